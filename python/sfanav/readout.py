"""Readouts: from slow features to metric positions, beyond the thesis's
quadratic regression (issue 7).

The thesis reads position out of the ``n`` slowest SFA outputs with a
quadratic regression fitted by least squares (thesis 3.5;
:class:`sfanav.regression.QuadraticRegression`). Where the slowest outputs
are not smooth functions of position (gardens with objects inside the area:
blobs and rings around nearby objects), a global polynomial cannot follow
them, although the features still tell places apart. Local readouts can:

* :class:`KNNReadout`: k nearest training samples in the (standardised)
  feature space, their positions averaged with inverse-distance weights.
* :class:`KernelRidgeReadout`: kernel ridge regression with a Gaussian (RBF)
  kernel on the standardised features (Saunders, Gammerman and Vovk 1998;
  Schoelkopf and Smola 2002, ch. 4), a smooth interpolant of the training
  run's positions.
* ``QuadraticRegression(ridge=...)``: the thesis's readout with an L2
  penalty.

:func:`select_readout` chooses among candidates by cross-validation **on the
training run only**, in contiguous blocks of the run (neighbouring frames of
a run are near copies; random folds would leak them into the held-out part,
the same optimism as the thesis's random splits). The test run never
influences the choice.

All readouts have ``fit(features, xy)`` and ``predict(features)``, with
features (N, m >= n_outputs) whose first ``n_outputs`` columns are used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

try:  # loaded here, before any threadpool_limits: a BLAS library loaded inside one escapes the limit
    from scipy.linalg import cho_factor, cho_solve
except ImportError:  # pragma: no cover - scipy is a dependency
    cho_factor = cho_solve = None

from ._checks import as_matrix, check_same_length
from .regression import QuadraticRegression
from .sfa import NotFittedError

__all__ = [
    "GPReadout",
    "KNNReadout",
    "KernelRidgeReadout",
    "ReadoutSelection",
    "AUTO_BLOCK",
    "AUTO_FOLDS",
    "AUTO_TOLERANCE",
    "auto_candidates",
    "block_folds",
    "default_candidates",
    "make_readout",
    "readout_from_state",
    "readout_state",
    "select_auto_readout",
    "select_readout",
]


def _cols(F: Any, n: int | None, name: str = "features") -> np.ndarray:
    X = as_matrix(F, name)
    if n is not None:
        if X.shape[1] < n:
            raise ValueError(f"{name} have {X.shape[1]} columns, fewer than n_outputs={n}")
        X = X[:, :n]
    return X


class _Standardised:
    n_outputs: int | None

    def _fit_scale(self, X: np.ndarray) -> np.ndarray:
        self.mean_ = X.mean(axis=0)
        sd = X.std(axis=0)
        self.scale_ = np.where(sd > 0, sd, 1.0)
        return (X - self.mean_) / self.scale_

    def _scaled(self, F: Any) -> np.ndarray:
        if not hasattr(self, "mean_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted; call fit first")
        return (_cols(F, self.n_outputs) - self.mean_) / self.scale_


class _KernelMachine(_Standardised):
    """A fitted kernel expansion ``k(q, X) @ dual + y_mean`` on standardised
    features: the shared prediction and model-file state of
    :class:`KernelRidgeReadout` and :class:`GPReadout`."""

    X_: np.ndarray
    dual_: np.ndarray
    y_mean_: np.ndarray

    def _kernel(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:  # pragma: no cover - overridden
        raise NotImplementedError

    def _query(self, Q: np.ndarray) -> np.ndarray:
        """Standardised queries in the coordinates of ``X_``."""
        return Q

    def predict(self, features: Any, chunk: int = 2048) -> np.ndarray:
        if not hasattr(self, "dual_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted; call fit first")
        Q = self._query(self._scaled(features))
        out = np.empty((len(Q), self.dual_.shape[1]))
        for s in range(0, len(Q), chunk):
            out[s : s + chunk] = self._kernel(Q[s : s + chunk], self.X_) @ self.dual_ + self.y_mean_
        return out

    def _arrays(self) -> dict[str, Any]:
        if not hasattr(self, "dual_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted; call fit first")
        return {"mean": self.mean_, "scale": self.scale_, "X": self.X_, "dual": self.dual_, "y_mean": self.y_mean_}

    def _load_arrays(self, state: dict[str, Any]) -> None:
        self.mean_, self.scale_ = np.asarray(state["mean"], float), np.asarray(state["scale"], float)
        self.X_, self.dual_ = np.asarray(state["X"], float), np.asarray(state["dual"], float)
        self.y_mean_ = np.asarray(state["y_mean"], float)
        if (self.X_.ndim != 2 or self.dual_.ndim != 2 or len(self.X_) != len(self.dual_)
                or self.mean_.shape != (self.X_.shape[1],) or self.y_mean_.shape != (self.dual_.shape[1],)):
            raise ValueError(f"invalid {type(self).__name__} state: inconsistent array shapes")


class KNNReadout(_Standardised):
    """k-nearest-neighbour readout: the mean position of the ``k`` training
    samples nearest in the standardised feature space, weighted by inverse
    distance (``weights="distance"``) or equally (``"uniform"``).

    Memory grows with the training run (one feature vector and position per
    sample: ``n_outputs + 2`` numbers), unlike the regressions."""

    def __init__(self, n_outputs: int | None = 8, k: int = 5, weights: str = "distance") -> None:
        if weights not in ("distance", "uniform"):
            raise ValueError(f"weights must be 'distance' or 'uniform', got {weights!r}")
        if int(k) < 1:
            raise ValueError(f"k must be at least 1, got {k}")
        self.n_outputs, self.k, self.weights = n_outputs, int(k), weights

    def __repr__(self) -> str:
        return f"KNNReadout(n_outputs={self.n_outputs}, k={self.k}, weights={self.weights!r})"

    def fit(self, features: Any, xy: Any) -> "KNNReadout":
        X = _cols(features, self.n_outputs)
        Y = as_matrix(xy, "xy")
        check_same_length(X, Y, "features", "xy")
        self.X_ = self._fit_scale(X)
        self.y_ = Y
        return self

    def predict(self, features: Any, chunk: int = 2048) -> np.ndarray:
        Q = self._scaled(features)
        k = min(self.k, len(self.X_))
        out = np.empty((len(Q), self.y_.shape[1]))
        sq = (self.X_**2).sum(axis=1)
        for s in range(0, len(Q), chunk):
            q = Q[s : s + chunk]
            d2 = np.maximum((q**2).sum(axis=1)[:, None] + sq[None, :] - 2.0 * q @ self.X_.T, 0.0)
            idx = np.argpartition(d2, k - 1, axis=1)[:, :k] if k < len(self.X_) else np.tile(np.arange(k), (len(q), 1))
            dk = np.sqrt(np.take_along_axis(d2, idx, axis=1))
            if self.weights == "distance":
                w = 1.0 / np.maximum(dk, 1e-9)
            else:
                w = np.ones_like(dk)
            w /= w.sum(axis=1, keepdims=True)
            out[s : s + chunk] = np.einsum("qk,qkd->qd", w, self.y_[idx])
        return out

    def _get_state(self) -> dict[str, Any]:
        if not hasattr(self, "X_"):
            raise NotFittedError("this KNNReadout is not fitted; call fit first")
        return {"params": {"n_outputs": self.n_outputs, "k": self.k, "weights": self.weights},
                "mean": self.mean_, "scale": self.scale_, "X": self.X_, "y": self.y_}

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> "KNNReadout":
        r = cls(**state["params"])
        r.mean_, r.scale_ = np.asarray(state["mean"], float), np.asarray(state["scale"], float)
        r.X_, r.y_ = np.asarray(state["X"], float), np.asarray(state["y"], float)
        if r.X_.ndim != 2 or r.y_.ndim != 2 or len(r.X_) != len(r.y_) or r.mean_.shape != (r.X_.shape[1],):
            raise ValueError("invalid KNNReadout state: inconsistent array shapes")
        return r


class KernelRidgeReadout(_KernelMachine):
    """Kernel ridge regression with the Gaussian kernel ``exp(-gamma |a -
    b|^2 / n)`` on the standardised features (``gamma`` relative to the
    number of features ``n``), ridge ``alpha``; the intercept is the
    training mean. Training runs longer than ``max_train`` samples are
    subsampled evenly (the solve is cubic in the number of samples)."""

    def __init__(self, n_outputs: int | None = 8, gamma: float = 1.0, alpha: float = 1e-2,
                 max_train: int = 3000) -> None:
        if not gamma > 0 or not alpha > 0:
            raise ValueError(f"gamma and alpha must be positive, got {gamma}, {alpha}")
        self.n_outputs, self.gamma, self.alpha, self.max_train = n_outputs, float(gamma), float(alpha), int(max_train)

    def __repr__(self) -> str:
        return f"KernelRidgeReadout(n_outputs={self.n_outputs}, gamma={self.gamma:g}, alpha={self.alpha:g})"

    def _kernel(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        d2 = (A**2).sum(axis=1)[:, None] + (B**2).sum(axis=1)[None, :] - 2.0 * A @ B.T
        return np.exp(-self.gamma / A.shape[1] * np.maximum(d2, 0.0))

    def fit(self, features: Any, xy: Any) -> "KernelRidgeReadout":
        X = _cols(features, self.n_outputs)
        Y = as_matrix(xy, "xy")
        check_same_length(X, Y, "features", "xy")
        if len(X) > self.max_train:
            keep = np.unique(np.linspace(0, len(X) - 1, self.max_train).round().astype(int))
            X, Y = X[keep], Y[keep]
        Xs = self._fit_scale(X)
        self.X_ = Xs
        self.y_mean_ = Y.mean(axis=0)
        K = self._kernel(Xs, Xs)
        K[np.diag_indices_from(K)] += self.alpha
        try:  # K + alpha I is symmetric positive definite: Cholesky, ~2x faster than LU
            if cho_factor is None:
                raise ImportError
            self.dual_ = cho_solve(cho_factor(K, overwrite_a=True, check_finite=False), Y - self.y_mean_,
                                   check_finite=False)
        except (ImportError, np.linalg.LinAlgError):
            K = self._kernel(Xs, Xs)
            K[np.diag_indices_from(K)] += self.alpha
            self.dual_ = np.linalg.solve(K, Y - self.y_mean_)
        return self

    def _get_state(self) -> dict[str, Any]:
        return {"params": {"n_outputs": self.n_outputs, "gamma": self.gamma, "alpha": self.alpha,
                           "max_train": self.max_train}, **self._arrays()}

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> "KernelRidgeReadout":
        r = cls(**state["params"])
        r._load_arrays(state)
        return r


def readout_state(spec: dict[str, Any], readout: Any) -> dict[str, Any]:
    """A fitted readout as a model-file state: ``{"spec": spec, "state": ...}``
    (arrays inside; no pickle). Read back with :func:`readout_from_state`."""
    return {"spec": dict(spec), "state": readout._get_state()}


def readout_from_state(state: dict[str, Any]) -> Any:
    """The fitted readout a :func:`readout_state` describes."""
    try:
        kind = state["spec"]["kind"]
        cls = {"quadratic": QuadraticRegression, "knn": KNNReadout, "kernel": KernelRidgeReadout,
               "gp": GPReadout}[kind]
        return cls._from_state(state["state"])
    except (KeyError, TypeError) as exc:
        raise ValueError(f"invalid readout state: {exc}") from None


def make_readout(spec: dict[str, Any]) -> Any:
    """A readout from a spec: ``{"kind": "quadratic", "n_outputs", "ridge"}``,
    ``{"kind": "knn", "n_outputs", "k", "weights"}`` or ``{"kind": "kernel",
    "n_outputs", "gamma", "alpha"}`` or ``{"kind": "gp", "n_outputs"}`` (plus
    ``length_scale`` and ``noise`` to fix its hyperparameters)."""
    s = dict(spec)
    kind = s.pop("kind", None)
    if kind == "quadratic":
        return QuadraticRegression(n_outputs=s.pop("n_outputs", 8), ridge=s.pop("ridge", 0.0), degree=s.pop("degree", 2))
    if kind == "knn":
        return KNNReadout(**s)
    if kind == "kernel":
        return KernelRidgeReadout(**s)
    if kind == "gp":
        return GPReadout(**s)
    raise ValueError(f"unknown readout kind {kind!r}; use 'quadratic', 'knn', 'kernel' or 'gp'")


_KEY_ORDER = ("n_outputs", "k", "weights", "gamma", "alpha", "ridge", "degree", "noise", "length_scale",
              "max_train")


def describe_spec(spec: dict[str, Any]) -> str:
    """A spec in words, e.g. ``kernel(n_outputs=12, gamma=0.5, alpha=0.001)``."""
    s = dict(spec)
    kind = s.pop("kind")
    keys = sorted(s, key=lambda k: (_KEY_ORDER.index(k) if k in _KEY_ORDER else len(_KEY_ORDER), k))
    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:g}"
        if isinstance(v, (list, tuple, np.ndarray)):
            return "[" + " ".join(f"{float(x):.2g}" for x in v) + "]"
        return str(v)

    return kind + "(" + ", ".join(f"{k}={fmt(s[k])}" for k in keys) + ")"


def default_candidates(kinds: Sequence[str] = ("quadratic", "knn", "kernel"),
                       n_outputs: Sequence[int] = (8, 12)) -> list[dict[str, Any]]:
    """The grid :func:`select_readout` searches by default: ridge quadratic
    regression (ridge 0 .. 1 on the centred expansion), kNN (k 1 .. 20,
    inverse-distance weights) and Gaussian kernel ridge (gamma 0.5 .. 4,
    alpha 1e-3 .. 1e-1), each on ``n_outputs`` slowest outputs."""
    out: list[dict[str, Any]] = []
    for n in n_outputs:
        if "quadratic" in kinds:
            out += [{"kind": "quadratic", "n_outputs": n, "ridge": r} for r in (0.0, 1e-2, 1e-1, 1.0, 10.0)]
        if "knn" in kinds:
            out += [{"kind": "knn", "n_outputs": n, "k": k, "weights": "distance"} for k in (1, 3, 5, 10, 20)]
        if "kernel" in kinds:
            out += [{"kind": "kernel", "n_outputs": n, "gamma": g, "alpha": a}
                    for g in (0.5, 1.0, 2.0, 4.0) for a in (1e-3, 1e-2, 1e-1)]
    return out


def block_folds(n: int, n_folds: int = 5, block: int | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """(train, held-out) index pairs of a run of ``n`` samples.

    ``block=None``: ``n_folds`` contiguous blocks (each held-out part a
    ``1/n_folds`` stretch of the run). ``block=b``: the run cut into blocks
    of ``b`` consecutive samples, block ``i`` held out in fold ``i mod
    n_folds`` (short held-out stretches spread over the run, as a test run
    inside the explored area is; consecutive near-duplicate frames still
    stay on one side)."""
    if n < 2 * n_folds:
        raise ValueError(f"{n} samples are too few for {n_folds} folds")
    idx = np.arange(n)
    if block is None:
        edges = np.linspace(0, n, n_folds + 1).round().astype(int)
        return [(np.concatenate([idx[: edges[i]], idx[edges[i + 1] :]]), idx[edges[i] : edges[i + 1]])
                for i in range(n_folds)]
    if int(block) < 1:
        raise ValueError(f"block must be at least 1, got {block}")
    fold = (idx // int(block)) % n_folds
    if len(np.unique(fold)) < n_folds:
        raise ValueError(f"{n} samples in blocks of {block} are too few for {n_folds} folds")
    return [(idx[fold != k], idx[fold == k]) for k in range(n_folds)]


class GPReadout(_KernelMachine):
    """Gaussian-process regression (the posterior mean) with an ARD squared
    exponential kernel ``exp(-sum_i (a_i - b_i)^2 / (2 l_i^2))`` on the
    standardised features plus white noise (Rasmussen and Williams 2006,
    ch. 2 and 5): one length scale ``l_i`` per slow feature, so features
    that do not code position get long scales and drop out.

    The hyperparameters (length scales, signal and noise variance; shared by
    x and y, each standardised) maximise the log marginal likelihood of the
    training run (type-II maximum likelihood, scikit-learn's optimiser) on at
    most ``max_fit`` evenly spaced samples; no cross-validation is needed.
    Given ``length_scale`` and ``noise`` (noise / signal variance) they are
    fixed instead. The posterior mean uses at most ``max_train`` evenly
    spaced samples (the solve is cubic in their number).

    Fitted attributes: ``length_scale_`` (n_outputs,), ``noise_`` (noise /
    signal variance), ``log_marginal_likelihood_`` (None if fixed)."""

    def __init__(self, n_outputs: int | None = 12, length_scale: Sequence[float] | None = None,
                 noise: float | None = None, max_fit: int = 1000, max_train: int = 3000) -> None:
        if (length_scale is None) != (noise is None):
            raise ValueError("give both length_scale and noise (fixed hyperparameters) or neither (learned)")
        if length_scale is not None:
            ls = np.asarray(length_scale, float)
            if ls.ndim != 1 or not np.all(np.isfinite(ls)) or np.any(ls <= 0):
                raise ValueError(f"length_scale must be positive finite numbers, got {length_scale!r}")
            if not (np.isfinite(noise) and noise > 0):  # type: ignore[arg-type]
                raise ValueError(f"noise must be positive, got {noise}")
        if int(max_fit) < 2 or int(max_train) < 2:
            raise ValueError(f"max_fit and max_train must be at least 2, got {max_fit}, {max_train}")
        self.n_outputs = n_outputs
        self.length_scale = None if length_scale is None else [float(v) for v in length_scale]
        self.noise = None if noise is None else float(noise)
        self.max_fit, self.max_train = int(max_fit), int(max_train)

    def __repr__(self) -> str:
        return f"GPReadout(n_outputs={self.n_outputs})"

    @staticmethod
    def _even(n: int, m: int) -> np.ndarray:
        return np.unique(np.linspace(0, n - 1, min(n, m)).round().astype(int))

    def _learn(self, Xs: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, float, float]:
        import warnings

        from sklearn.exceptions import ConvergenceWarning
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

        d = Xs.shape[1]
        kernel = (ConstantKernel(1.0, (1e-3, 1e3)) * RBF(np.ones(d), (1e-2, 1e3))
                  + WhiteKernel(1e-2, (1e-8, 1e1)))
        keep = self._even(len(Xs), self.max_fit)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)  # a length scale at its bound: feature unused
            gp = GaussianProcessRegressor(kernel, normalize_y=True, random_state=0).fit(Xs[keep], Y[keep])
        k = gp.kernel_
        signal, ls, noise = float(k.k1.k1.constant_value), np.atleast_1d(k.k1.k2.length_scale).astype(float), \
            float(k.k2.noise_level)
        return ls, noise / signal, float(gp.log_marginal_likelihood_value_)

    def _kernel(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        d2 = (A**2).sum(axis=1)[:, None] + (B**2).sum(axis=1)[None, :] - 2.0 * A @ B.T
        return np.exp(-0.5 * np.maximum(d2, 0.0))

    def fit(self, features: Any, xy: Any) -> "GPReadout":
        X = _cols(features, self.n_outputs)
        Y = as_matrix(xy, "xy")
        check_same_length(X, Y, "features", "xy")
        if len(X) < 3:
            raise ValueError(f"a GP readout needs at least 3 training samples, got {len(X)}")
        Xs = self._fit_scale(X)
        if self.length_scale is None:
            ls, noise, lml = self._learn(Xs, Y)
        else:
            ls, noise, lml = np.asarray(self.length_scale, float), float(self.noise), None  # type: ignore[arg-type]
            if len(ls) != X.shape[1]:
                raise ValueError(f"length_scale has {len(ls)} entries for {X.shape[1]} features")
        self.length_scale_, self.noise_, self.log_marginal_likelihood_ = ls, noise, lml
        keep = self._even(len(Xs), self.max_train)
        A, Yk = Xs[keep] / ls, Y[keep]
        self.y_mean_ = Yk.mean(axis=0)
        K = self._kernel(A, A)
        K[np.diag_indices_from(K)] += max(noise, 1e-10)
        try:
            self.dual_ = cho_solve(cho_factor(K, overwrite_a=True, check_finite=False), Yk - self.y_mean_,
                                   check_finite=False)
        except np.linalg.LinAlgError:
            K = self._kernel(A, A)
            K[np.diag_indices_from(K)] += max(noise, 1e-10)
            self.dual_ = np.linalg.lstsq(K, Yk - self.y_mean_, rcond=None)[0]
        self.X_ = A
        return self

    def _query(self, Q: np.ndarray) -> np.ndarray:
        return Q / self.length_scale_

    def fixed_spec(self) -> dict[str, Any]:
        """The spec of this readout with its learned hyperparameters fixed
        (refitting it only solves for the posterior mean)."""
        if not hasattr(self, "length_scale_"):
            raise NotFittedError("this GPReadout is not fitted; call fit first")
        return {"kind": "gp", "n_outputs": self.n_outputs, "length_scale": [float(v) for v in self.length_scale_],
                "noise": float(self.noise_)}

    def _get_state(self) -> dict[str, Any]:
        arrays = self._arrays()
        return {"params": {"n_outputs": self.n_outputs, "max_fit": self.max_fit, "max_train": self.max_train},
                **arrays, "length_scale": self.length_scale_, "noise": float(self.noise_)}

    @classmethod
    def _from_state(cls, state: dict[str, Any]) -> "GPReadout":
        r = cls(**state["params"])
        r._load_arrays(state)
        r.length_scale_, r.noise_ = np.asarray(state["length_scale"], float), float(state["noise"])
        r.log_marginal_likelihood_ = None
        if r.length_scale_.shape != r.mean_.shape or not np.all(r.length_scale_ > 0):
            raise ValueError("invalid GPReadout state: inconsistent array shapes")
        return r


# The sfanav default readout ("auto"): a Gaussian process with ARD length
# scales (marginal likelihood) unless Gaussian kernel ridge or kNN, chosen by
# blocked CV on the training run (AUTO_FOLDS folds of interleaved blocks of
# AUTO_BLOCK consecutive images), has a CV error lower by more than
# AUTO_TOLERANCE (relative); kNN over kernel ridge by the same margin.
# Measured in docs/gardens.md ("Choosing the readout").
AUTO_FOLDS = 10
AUTO_BLOCK = 10  # consecutive training images per CV block
AUTO_TOLERANCE = 0.1
AUTO_MAX_CV_SAMPLES = 1500


def auto_candidates(n_outputs: Sequence[int] = (8, 12)) -> list[dict[str, Any]]:
    """The grid of the default (``"auto"``) readout: Gaussian kernel ridge
    (gamma 0.25 .. 2, alpha 1e-3 .. 1e-2; docs/gardens.md) and kNN (k 1 ..
    10, inverse-distance weights), each on ``n_outputs`` slowest outputs."""
    out: list[dict[str, Any]] = []
    for n in n_outputs:
        out += [{"kind": "kernel", "n_outputs": int(n), "gamma": g, "alpha": a}
                for g in (0.25, 0.5, 1.0, 2.0) for a in (1e-3, 1e-2)]
        out += [{"kind": "knn", "n_outputs": int(n), "k": k, "weights": "distance"} for k in (1, 3, 5, 10)]
    return out


@dataclass
class ReadoutSelection:
    """What :func:`select_readout` found: the best ``spec``, its readout fitted
    on the whole training run (``readout``), and each candidate's mean
    held-out Euclidean error in metres (``scores``, same order as
    ``candidates``)."""

    spec: dict[str, Any]
    readout: Any
    candidates: list[dict[str, Any]] = field(default_factory=list)
    scores: np.ndarray = field(default_factory=lambda: np.empty(0))
    rule: str = "lowest CV error"

    def describe(self) -> str:
        return describe_spec(self.spec)

    def best_of(self, kind: str) -> tuple[dict[str, Any], float]:
        """The candidate of one ``kind`` with the lowest CV error, and that error (m)."""
        idx = [i for i, c in enumerate(self.candidates) if c["kind"] == kind]
        if not idx:
            raise ValueError(f"no {kind!r} candidates in this selection")
        i = min(idx, key=lambda j: float(self.scores[j]))
        return dict(self.candidates[i]), float(self.scores[i])


def select_readout(features: Any, xy: Any, candidates: Sequence[dict[str, Any]] | None = None, *,
                   n_folds: int = 5, max_cv_samples: int | None = None,
                   block: int | None = None) -> ReadoutSelection:
    """Chooses a readout by blocked cross-validation on one (training) run.

    Each candidate is fitted on ``n_folds - 1`` contiguous blocks of the run
    and scored by the mean Euclidean error on the held-out block; the one
    with the lowest mean is refitted on the whole run. ``features`` (N, m)
    and ``xy`` (N, 2) in the run's order. ``max_cv_samples``: runs longer
    than that are subsampled evenly for the CV (not for the final fit).
    ``block``: folds of interleaved blocks of that many samples instead of
    contiguous stretches (:func:`block_folds`)."""
    F = as_matrix(features, "features")
    Y = as_matrix(xy, "xy")
    check_same_length(F, Y, "features", "xy")
    cands = list(candidates) if candidates is not None else default_candidates(n_outputs=tuple(
        n for n in (8, 12) if n <= F.shape[1]) or (F.shape[1],))
    if not cands:
        raise ValueError("no readout candidates")
    scores = _scores(cands, F, Y, n_folds, max_cv_samples, block)
    best = int(np.argmin(scores))
    spec = dict(cands[best])
    return ReadoutSelection(spec, make_readout(spec).fit(F, Y), [dict(c) for c in cands], scores)


def _scores(cands: list[dict[str, Any]], F: np.ndarray, Y: np.ndarray, n_folds: int,
            max_cv_samples: int | None, block: int | None = None) -> np.ndarray:
    if max_cv_samples is not None and len(F) > max_cv_samples:
        keep = np.unique(np.linspace(0, len(F) - 1, int(max_cv_samples)).round().astype(int))
        F, Y = F[keep], Y[keep]
    folds = block_folds(len(F), n_folds, block)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # many small solves: threads only thrash
        return _cv_scores(cands, folds, F, Y)


def select_auto_readout(features: Any, xy: Any, *, n_outputs: int | Sequence[int] | None = None,
                        n_folds: int = AUTO_FOLDS, block: int | None = AUTO_BLOCK,
                        tolerance: float = AUTO_TOLERANCE,
                        max_cv_samples: int | None = AUTO_MAX_CV_SAMPLES, gp: bool = True) -> ReadoutSelection:
    """The sfanav default readout (``"auto"``), chosen on the training run only.

    1. A Gaussian-process readout (:class:`GPReadout`) on the most slowest
       outputs offered (12, or ``max(n_outputs)``), its ARD hyperparameters
       by maximum marginal likelihood on the whole run.
    2. Every candidate of :func:`auto_candidates` (Gaussian kernel ridge and
       kNN on 8 and 12 outputs, or ``n_outputs``; only those the features
       have) and the GP with its hyperparameters fixed are scored by blocked
       CV (mean held-out Euclidean error, m): the run cut into blocks of
       ``block`` consecutive images, block ``i`` held out in fold ``i mod
       n_folds`` (``block=None``: ``n_folds`` contiguous stretches).
    3. The GP is taken unless the best other candidate's CV error is lower by
       more than ``tolerance`` (relative); among the others kNN only if it
       beats kernel ridge by more than ``tolerance``.

    ``gp=False`` leaves the GP out (the issue-7 default: kernel ridge unless
    kNN is better by ``tolerance``). On the gardens and 5.1.1 runs, 5
    contiguous folds picked kNN where kernel ridge was better on the test
    run, and contiguous folds (whole strips of the area held out) chose too
    smooth kernels (docs/gardens.md). Runs too short for ``n_folds`` folds of
    ``block`` images use fewer folds (at least 2) and shorter blocks.
    Returns a :class:`ReadoutSelection` whose ``rule`` says why."""
    F = as_matrix(features, "features")
    Y = as_matrix(xy, "xy")
    check_same_length(F, Y, "features", "xy")
    if not 0.0 <= float(tolerance) < 1.0:
        raise ValueError(f"tolerance must be in [0, 1), got {tolerance}")
    if n_outputs is None:
        ns = tuple(n for n in (8, 12) if n <= F.shape[1]) or (F.shape[1],)
    else:
        ns = (int(n_outputs),) if np.isscalar(n_outputs) else tuple(int(n) for n in n_outputs)  # type: ignore[arg-type]
        bad = [n for n in ns if not 1 <= n <= F.shape[1]]
        if bad:
            raise ValueError(f"n_outputs {bad} out of range: the features have {F.shape[1]} columns")
    folds = min(int(n_folds), len(F) // 2)
    if folds < 2:
        raise ValueError(f"{len(F)} training samples are too few to choose a readout by cross-validation")
    n_cv = min(len(F), max_cv_samples or len(F))
    blk = None if block is None else max(1, min(int(block), n_cv // folds))
    cands = auto_candidates(ns)
    gp_fit = None
    if gp:
        gp_fit = GPReadout(n_outputs=max(ns)).fit(F, Y)
        cands.append(gp_fit.fixed_spec())
    scores = _scores(cands, F, Y, folds, max_cv_samples, blk)
    sel = ReadoutSelection({}, None, [dict(c) for c in cands], scores)
    k_spec, k_err = sel.best_of("kernel")
    n_spec, n_err = sel.best_of("knn")
    if np.isfinite(n_err) and (not np.isfinite(k_err) or n_err < (1.0 - tolerance) * k_err):
        spec, err, why = n_spec, n_err, f"kNN: CV {n_err:.3f} m < (1 - {tolerance:g}) x kernel ridge's {k_err:.3f} m"
    else:
        spec, err, why = k_spec, k_err, f"kernel ridge: CV {k_err:.3f} m (kNN {n_err:.3f} m not {tolerance:.0%} lower)"
    how = f"{folds}-fold blocked CV" + (f" (blocks of {blk} images)" if blk is not None else " (contiguous)")
    if gp_fit is not None:
        g_err = float(scores[-1])
        if not (np.isfinite(err) and err < (1.0 - tolerance) * g_err):
            sel.spec = {"kind": "gp", "n_outputs": max(ns)}
            sel.rule = (f"{how}; GP (ARD, marginal likelihood): CV {g_err:.3f} m (best other "
                        f"{describe_spec(spec)} {err:.3f} m not {tolerance:.0%} lower)")
            sel.readout = gp_fit
            return sel
        why = f"{why}; beats the GP's CV {g_err:.3f} m by more than {tolerance:.0%}"
    sel.spec, sel.rule = spec, f"{how}; {why}"
    sel.readout = make_readout(spec).fit(F, Y)
    return sel


def _cv_scores(cands: list[dict[str, Any]], folds: list[tuple[np.ndarray, np.ndarray]], F: np.ndarray,
               Y: np.ndarray) -> np.ndarray:
    scores = np.empty(len(cands))
    for i, spec in enumerate(cands):
        errs = []
        for tr, te in folds:
            try:
                pred = make_readout(spec).fit(F[tr], Y[tr]).predict(F[te])
                errs.append(float(np.hypot(*(pred - Y[te]).T).mean()))
            except (ValueError, np.linalg.LinAlgError):
                errs.append(np.inf)
        scores[i] = float(np.mean(errs))
    return scores
