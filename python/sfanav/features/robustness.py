"""Long-term robustness prediction of local visual features (thesis 6.1.2).

1. :func:`stability_labels`: features of one place seen in several seasons
   are *stable* if matched (ratio test, and the matched keypoint within a
   pixel threshold) in every other season, *unstable* if matched in none.
2. :func:`balanced` picks as many unstable as stable samples.
3. :class:`RobustnessPredictor` learns an RBF support vector machine on the
   77-dimensional texture and colour vectors
   (:func:`~sfanav.features.descriptor.robustness_vectors`), standardised,
   C and gamma by grid search with 5-fold cross-validation.
4. :meth:`RobustnessPredictor.select` keeps ``k`` keypoints of an image
   out of the ``4 k`` of largest detector response (:func:`select_ranked`):
   by default the ``k`` most robust (``method="robust"``), or those of the
   smallest sum of their rank by response and their rank by predicted
   robustness (``method="rank-sum"``). Apply it to the map's images *and*
   to the live images matched against the map: both sides then keep the
   same kind of keypoint. The thesis filtered only the map, with a pool
   of ``1.5 k`` (``candidates=1.5``).

The predictor is saved as JSON (no pickle): format name, version, the
scaler, the support vectors, dual coefficients, intercept and gamma, with a
SHA-256 checksum of the content; :meth:`RobustnessPredictor.load` refuses a
wrong format or version and a corrupted file.

>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> X = np.vstack([rng.normal(0, 1, (40, 77)), rng.normal(2, 1, (40, 77))])
>>> y = np.repeat([0, 1], 40)
>>> p = RobustnessPredictor.fit(X, y, detector="fast-brief", grid={"C": [1.0], "gamma": [0.01]}, cv=2)
>>> bool((p.decision_function(X[40:]) > 0).mean() > 0.9)
True
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .descriptor import DIM, PATCH, robustness_vectors
from .detectors import Features, detect, match, pixel_distance

FORMAT = "sfanav-robustness-predictor"
VERSION = 1
STABLE, UNSTABLE, NEITHER = 1, 0, -1
#: how :func:`select_ranked` picks keypoints (see there); the first is the default
METHODS = ("robust", "rank-sum")
#: default candidate pool of :func:`select_ranked`, in multiples of the number kept
CANDIDATES = 4.0
#: default grid of the support vector machine (gamma in units of 1 / (77 * variance) as scikit-learn's "scale")
GRID = {"C": [0.3, 1.0, 3.0, 10.0, 30.0], "gamma": [0.003, 0.01, 0.03, 0.1]}


def stability_labels(seasons: Sequence[Features], *, threshold: float = 10.0, ratio: float = 0.75) -> list[np.ndarray]:
    """Stable / unstable labels of the features of one place in several seasons.

    A feature of season ``s`` is matched in season ``t`` if its nearest
    descriptor in ``t`` passes the distance ratio test and lies at most
    ``threshold`` pixels from it (the viewpoint is the same).

    Parameters
    ----------
    seasons : sequence of Features
        The same place in two or more seasons.
    threshold : float
        Pixels.
    ratio : float in (0, 1]
        Distance ratio of the nearest to the second nearest descriptor.

    Returns
    -------
    list of ndarray (n_s,) int
        Per season: ``STABLE`` (1) matched in all other seasons,
        ``UNSTABLE`` (0) in none, ``NEITHER`` (-1) in some.

    Raises
    ------
    ValueError
        Fewer than two seasons, a threshold <= 0, a ratio outside (0, 1].
    TypeError
        An entry that is not a :class:`Features`.
    """
    from .._checks import check_positive_float

    if len(seasons) < 2:
        raise ValueError(f"stability needs the place in at least two seasons, got {len(seasons)}")
    for s in seasons:
        if not isinstance(s, Features):
            raise TypeError(f"seasons must hold Features, got {type(s).__name__}")
    threshold = check_positive_float(threshold, "threshold")
    if not 0 < float(ratio) <= 1:
        raise ValueError(f"ratio must be in (0, 1], got {ratio!r}")
    out = []
    for a, fa in enumerate(seasons):
        count = np.zeros(len(fa), int)
        for b, fb in enumerate(seasons):
            if a == b:
                continue
            pairs = match(fa, fb, cross_check=False, ratio=ratio)
            ok = pixel_distance(fa.xy[pairs[:, 0]], fb.xy[pairs[:, 1]], fa.width) <= threshold
            count[pairs[ok, 0]] += 1
        lab = np.full(len(fa), NEITHER)
        lab[count == len(seasons) - 1] = STABLE
        lab[count == 0] = UNSTABLE
        out.append(lab)
    return out


def balanced(labels: Any, rng: np.random.Generator | int | None = 0) -> np.ndarray:
    """Indices of all samples of the rarer class among ``STABLE`` and
    ``UNSTABLE`` and an equal random draw of the other (``NEITHER`` left out),
    sorted."""
    lab = np.asarray(labels)
    rng = np.random.default_rng(rng)
    s, u = np.flatnonzero(lab == STABLE), np.flatnonzero(lab == UNSTABLE)
    k = min(len(s), len(u))
    return np.sort(np.concatenate([rng.choice(s, k, replace=False), rng.choice(u, k, replace=False)]))


def training_samples(places: Any, detector: str = "fast-brief", *, n: int = 1000, threshold: float = 10.0,
                     ratio: float = 0.75) -> tuple[np.ndarray, np.ndarray]:
    """Labelled robustness vectors of places seen in several seasons.

    Parameters
    ----------
    places : iterable of sequences of ndarray (H, W, 3)
        Per place, its RGB panoramas in two or more seasons (same pose).
    detector : str
        One of :data:`~sfanav.features.detectors.DETECTORS`.
    n : int
        Features per image (largest response).
    threshold, ratio
        As :func:`stability_labels`.

    Returns
    -------
    X : ndarray (m, 77)
        Vectors of the stable and unstable features (not yet balanced).
    y : ndarray (m,) int
        1 stable, 0 unstable.

    Raises
    ------
    ValueError
        A place with fewer than two images, bad images or parameters.
    """
    X, y = [np.zeros((0, DIM))], [np.zeros(0, int)]
    for imgs in places:
        feats = [detect(im, detector, n) for im in imgs]
        for im, ft, lab in zip(imgs, feats, stability_labels(feats, threshold=threshold, ratio=ratio)):
            keep = lab >= 0
            X.append(robustness_vectors(im, ft.xy[keep]))
            y.append(lab[keep])
    return np.vstack(X), np.concatenate(y)


def select_ranked(scores: Any, k: int, *, candidates: float = CANDIDATES, method: str = METHODS[0]) -> np.ndarray:
    """Which ``k`` of a detector's keypoints to keep, given their predicted
    robustness.

    The keypoints are those of an image sorted by decreasing detector
    response (as :func:`~sfanav.features.detectors.detect` returns them);
    the candidates are the ``ceil(candidates * k)`` strongest. ``method``:

    * ``"robust"`` (default): the ``k`` candidates of largest score (the
      thesis's rule, which used ``candidates=1.5``).
    * ``"rank-sum"``: the ``k`` candidates of smallest sum of their rank by
      response and their rank by score (ties: the stronger response).
      Strong keypoints predicted unstable give way to slightly weaker ones
      predicted stable.

    The defaults (the most robust of ``4 k``) are meant for selecting the
    keypoints of the map *and* of the images matched against it. To filter
    the map only and match it with the live images' strongest keypoints,
    ``method="rank-sum", candidates=1.5`` is the better choice: a keypoint
    taken from deep in a large pool rarely finds its counterpart among
    another image's strongest. Measurements: docs/experiments.md, 6.1.2.

    Parameters
    ----------
    scores : array (n,)
        Predicted robustness of the keypoints, in response order (larger:
        more robust; e.g. :meth:`RobustnessPredictor.score_keypoints`).
    k : int
        Keypoints to keep (>= 1); all if there are fewer.
    candidates : float
        Pool size in multiples of ``k`` (> 0; values below 1 count as 1).
    method : str
        One of :data:`METHODS`.

    Returns
    -------
    ndarray (min(k, n),) int
        Indices into ``scores``, best first.

    Raises
    ------
    ValueError
        ``k`` < 1, ``candidates`` <= 0, an unknown method, scores not a
        finite 1-d array.

    Examples
    --------
    >>> select_ranked([0.1, -2.0, 1.5, 0.3], 2, candidates=2.0)
    array([2, 3])
    >>> select_ranked([0.1, -2.0, 1.5, 0.3], 2, candidates=2.0, method="rank-sum")
    array([0, 2])
    """
    from .._checks import check_int, check_positive_float

    k = check_int(k, "k", minimum=1)
    c = check_positive_float(candidates, "candidates")
    if method not in METHODS:
        raise ValueError(f"unknown selection method {method!r}; available: {', '.join(METHODS)}")
    s = np.asarray(scores, dtype=float)
    if s.ndim != 1 or not np.all(np.isfinite(s)):
        raise ValueError(f"scores must be a finite 1-d array, got shape {s.shape}")
    pool = s[: max(k, int(np.ceil(c * k)))]
    by_score = np.argsort(-pool, kind="stable")
    if method == "robust":
        return by_score[:k]
    rank = np.empty(len(pool))
    rank[by_score] = np.arange(len(pool))
    return np.argsort(np.arange(len(pool)) + rank, kind="stable")[:k]


@dataclass
class RobustnessPredictor:
    """An RBF support vector machine that scores keypoints' long-term
    robustness (larger: more likely stable).

    Attributes
    ----------
    detector : str
        The detector the predictor was trained for.
    mean, scale : ndarray (77,)
        Standardisation of the vectors.
    support_vectors : ndarray (m, 77)
        In standardised units.
    dual_coef : ndarray (m,)
    intercept : float
    gamma : float
        RBF kernel ``exp(-gamma * |u - v|^2)``.
    patch : int
        Patch edge (pixels) of the vectors.
    info : dict
        Training notes (C, cross-validated accuracy, sample counts).
    """

    detector: str
    mean: np.ndarray
    scale: np.ndarray
    support_vectors: np.ndarray
    dual_coef: np.ndarray
    intercept: float
    gamma: float
    patch: int = PATCH
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def fit(cls, X: Any, y: Any, *, detector: str, grid: dict[str, Sequence[float]] | None = None, cv: int = 5,
            seed: int = 0, patch: int = PATCH) -> "RobustnessPredictor":
        """Grid search (``grid``: lists of ``C`` and ``gamma``) with ``cv``-fold
        cross-validation of a standardised RBF SVM on vectors ``X`` (n, 77)
        and labels ``y`` (n,) in {0 unstable, 1 stable}.

        Raises
        ------
        ValueError
            Not 77 columns, labels other than 0/1 or only one class, fewer
            than ``cv`` samples per class.
        """
        from sklearn.model_selection import GridSearchCV, StratifiedKFold
        from sklearn.preprocessing import StandardScaler
        from sklearn.svm import SVC

        from .._checks import as_float_2d, check_int, check_same_length

        X = as_float_2d(X, "robustness vectors")
        if X.shape[1] != DIM:
            raise ValueError(f"robustness vectors must have {DIM} columns, got {X.shape[1]}")
        y = np.asarray(y)
        check_same_length(X, y, "robustness vectors", "labels")
        if not set(np.unique(y).tolist()) == {0, 1}:
            raise ValueError(f"labels must hold both 0 (unstable) and 1 (stable), got {np.unique(y).tolist()}")
        cv = check_int(cv, "cv", minimum=2)
        if np.bincount(y.astype(int)).min() < cv:
            raise ValueError(f"{cv}-fold cross-validation needs at least {cv} samples per class")
        scaler = StandardScaler().fit(X)
        scale = np.where(scaler.scale_ > 0, scaler.scale_, 1.0)
        Z = (X - scaler.mean_) / scale
        g = dict(grid or GRID)
        search = GridSearchCV(SVC(kernel="rbf"), {"C": list(g["C"]), "gamma": list(g["gamma"])},
                              cv=StratifiedKFold(cv, shuffle=True, random_state=seed), n_jobs=1)
        search.fit(Z, y.astype(int))
        svm = search.best_estimator_
        return cls(detector, scaler.mean_.copy(), scale, svm.support_vectors_.copy(), svm.dual_coef_[0].copy(),
                   float(svm.intercept_[0]), float(svm._gamma), int(patch),
                   {"C": float(search.best_params_["C"]), "cv_accuracy": float(search.best_score_),
                    "cv_folds": cv, "n_samples": int(len(y)), "n_stable": int((y == 1).sum())})

    def decision_function(self, X: Any) -> np.ndarray:
        """Signed SVM scores (n,) of vectors ``X`` (n, 77); > 0: stable."""
        from .._checks import as_float_2d

        X = as_float_2d(X, "robustness vectors", min_samples=0) if np.size(X) else np.zeros((0, DIM))
        if X.shape[1] != DIM:
            raise ValueError(f"robustness vectors must have {DIM} columns, got {X.shape[1]}")
        Z = (X - self.mean) / self.scale
        out = np.empty(len(Z))
        for s in range(0, len(Z), 512):
            z = Z[s:s + 512]
            d2 = (z * z).sum(1)[:, None] + (self.support_vectors ** 2).sum(1)[None, :] - 2 * z @ self.support_vectors.T
            out[s:s + 512] = np.exp(-self.gamma * np.maximum(d2, 0)) @ self.dual_coef + self.intercept
        return out

    def score_keypoints(self, image: Any, features: Features) -> np.ndarray:
        """Scores (n,) of the keypoints of ``features`` in RGB ``image``."""
        return self.decision_function(robustness_vectors(image, features.xy, patch=self.patch))

    def select(self, image: Any, k: int, *, candidates: float = CANDIDATES, method: str = METHODS[0],
               features: Features | None = None) -> Features:
        """``k`` keypoints of RGB ``image`` to keep in a long-term map: of the
        ``ceil(candidates * k)`` of largest response (detected with the
        predictor's detector unless ``features`` are given), those
        :func:`select_ranked` picks by ``method`` (default ``"robust"``: the
        most robust; ``"rank-sum"``: rank by response plus rank by predicted
        robustness). Select the live images' keypoints the same way as the
        map's (see :func:`select_ranked`). ValueError as
        :func:`select_ranked`."""
        from .._checks import check_int, check_positive_float

        k = check_int(k, "k", minimum=1)
        m = max(k, int(np.ceil(check_positive_float(candidates, "candidates") * k)))
        pool = detect(image, self.detector, m) if features is None else features.strongest(m)
        s = self.score_keypoints(image, pool)
        return pool.subset(select_ranked(s, k, candidates=candidates, method=method))

    # ------------------------------------------------------------ file

    def _payload(self) -> dict[str, Any]:
        return {"detector": self.detector, "patch": self.patch, "dim": DIM, "mean": self.mean.tolist(),
                "scale": self.scale.tolist(), "support_vectors": self.support_vectors.tolist(),
                "dual_coef": self.dual_coef.tolist(), "intercept": self.intercept, "gamma": self.gamma,
                "info": self.info}

    def save(self, path: str | os.PathLike, *, overwrite: bool = True) -> Path:
        """Writes the predictor as JSON, atomically; returns the path."""
        from .._files import write_text_atomic

        payload = self._payload()
        doc = {"format": FORMAT, "version": VERSION, "sha256": _digest(payload), "predictor": payload}
        return write_text_atomic(path, json.dumps(doc), overwrite=overwrite)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "RobustnessPredictor":
        """Reads a predictor of :meth:`save`.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            Not JSON, another format or version, a checksum mismatch
            (corrupted), fields of wrong shape or non-finite.
        """
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"robustness predictor {p} does not exist")
        try:
            doc = json.loads(p.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{p} is not a robustness predictor (not JSON: {exc})") from None
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise ValueError(f"{p} is not a robustness predictor (format {doc.get('format') if isinstance(doc, dict) else None!r})")
        if doc.get("version") != VERSION:
            raise ValueError(f"{p} is robustness predictor version {doc.get('version')!r}; this sfanav reads {VERSION}")
        pay = doc.get("predictor")
        if not isinstance(pay, dict) or doc.get("sha256") != _digest(pay):
            raise ValueError(f"{p} is corrupted: its checksum does not match its content")
        try:
            sv = np.asarray(pay["support_vectors"], float).reshape(-1, DIM)
            dc = np.asarray(pay["dual_coef"], float).ravel()
            mean = np.asarray(pay["mean"], float).ravel()
            scale = np.asarray(pay["scale"], float).ravel()
            out = cls(str(pay["detector"]), mean, scale, sv, dc, float(pay["intercept"]), float(pay["gamma"]),
                      int(pay["patch"]), dict(pay.get("info") or {}))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{p} has a malformed robustness predictor: {exc}") from None
        if mean.shape != (DIM,) or scale.shape != (DIM,) or len(dc) != len(sv) or len(sv) == 0:
            raise ValueError(f"{p} has a malformed robustness predictor: inconsistent array shapes")
        if not all(np.all(np.isfinite(a)) for a in (sv, dc, mean, scale, [out.intercept, out.gamma])) or out.gamma <= 0:
            raise ValueError(f"{p} has a malformed robustness predictor: non-finite values or gamma <= 0")
        return out


def _digest(payload: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()
