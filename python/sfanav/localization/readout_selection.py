"""Choosing a readout by cross-validation on the training run only, in
contiguous blocks of the run (neighbouring frames are near copies: random
folds would leak them into the held-out part), or, when the training set is
several recordings (``groups``), one recording held out at a time (as a
robot will meet a light or season none of them showed). The test run never
influences the choice. :func:`select_readout` picks among candidate specs;
:func:`select_auto_readout` is the ``readout="auto"`` rule of
:class:`sfanav.Localizer`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from .._checks import as_matrix, check_same_length
from .._sampling import evenly_spaced
from .extrapolation import quiet_extrapolation
from .readouts import GPReadout, describe_spec, make_readout
from .signature_knn import SignatureKNNReadout
from .signature_readout import SignatureGPReadout


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


def group_folds(groups: Any, max_folds: int | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """(train, held-out) index pairs that hold out one group at a time.

    ``groups`` (N,): a label per sample (any values; e.g. the recording or
    condition each training image comes from). ``max_folds``: hold out at
    most that many groups, evenly spaced in the order of their first
    appearance (all when None). Raises ValueError for fewer than two groups.

    Example
    -------
    >>> [h.tolist() for _, h in group_folds(["a", "a", "b", "c", "b"])]
    [[0, 1], [2, 4], [3]]
    """
    g = np.asarray(groups)
    if g.ndim != 1:
        raise ValueError(f"groups must be one label per sample (1-D), got shape {g.shape}")
    _, first, inverse = np.unique(g, return_index=True, return_inverse=True)
    order = np.argsort(first)  # groups in the order they first appear
    if len(order) < 2:
        raise ValueError(f"leave-one-group-out needs at least 2 groups, got {len(order)}")
    if max_folds is not None:
        if int(max_folds) < 1:
            raise ValueError(f"max_folds must be at least 1, got {max_folds}")
        order = order[evenly_spaced(len(order), int(max_folds))]
    idx = np.arange(len(g))
    return [(idx[inverse != k], idx[inverse == k]) for k in order]


def _group_labels(groups: Any, n: int) -> np.ndarray | None:
    """``groups`` checked against ``n`` samples; None when absent or one group."""
    if groups is None:
        return None
    g = np.asarray(groups)
    if g.ndim != 1 or len(g) != n:
        raise ValueError(f"groups must hold one label per training sample ({n}), got shape {g.shape}")
    if g.dtype.kind == "f" and not np.all(np.isfinite(g)):
        raise ValueError("groups must not hold NaN or infinite labels")
    return g if len(np.unique(g)) >= 2 else None


def cross_val_predict(spec: dict[str, Any], features: Any, xy: Any, *, n_folds: int = 5,
                      block: int | None = 20) -> np.ndarray:
    """Held-out estimates (N, 2) of a training run: each frame's position
    predicted by the readout ``spec`` (as :func:`make_readout`, e.g. a
    fitted localizer's ``readout_spec_``) fitted on the other folds of
    :func:`block_folds` (blocks of ``block`` consecutive frames). What a
    test run inside the explored area would see, without the in-sample
    optimism of the fitted readout's own training estimates; used to choose
    the EKF noise on the training run.

    Raises ValueError for mismatched inputs or too few frames for the folds.
    """
    F = as_matrix(features, "features")
    Y = as_matrix(xy, "xy", n_cols=2)
    check_same_length(F, Y, "features", "xy")
    out = np.empty((len(F), 2))
    with quiet_extrapolation():  # a held-out block at the run's edge lies outside its folds' box by construction
        for train, held in block_folds(len(F), n_folds, block):
            out[held] = make_readout(spec).fit(F[train], Y[train]).predict(F[held])
    return out


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


# With several recordings (groups): recordings held out at most when the signature readouts are compared
# (each fold refits the GP readout's posterior), and the kNN sizes tried. docs/localization.md, "Several recordings".
AUTO_GROUP_FOLDS = 5


SIGNATURE_KNN_K = (1, 3)


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
            max_cv_samples: int | None, block: int | None = None, groups: np.ndarray | None = None) -> np.ndarray:
    if max_cv_samples is not None and len(F) > max_cv_samples:
        keep = evenly_spaced(len(F), int(max_cv_samples))
        F, Y = F[keep], Y[keep]
        groups = None if groups is None else groups[keep]
    folds = block_folds(len(F), n_folds, block) if groups is None else group_folds(groups, n_folds)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # many small solves: threads only thrash
        return _cv_scores(cands, folds, F, Y)


def select_auto_readout(features: Any, xy: Any, *, n_outputs: int | Sequence[int] | None = None,
                        n_folds: int = AUTO_FOLDS, block: int | None = AUTO_BLOCK,
                        tolerance: float = AUTO_TOLERANCE,
                        max_cv_samples: int | None = AUTO_MAX_CV_SAMPLES, gp: bool = True,
                        n_signature: int = 0, groups: Any = None, views: Any = None) -> ReadoutSelection:
    """The sfanav default readout (``"auto"``), chosen on the training run only.

    With ``n_signature > 0`` the last ``n_signature`` columns of ``features``
    are an appearance signature (the sfanav default's Fourier signature) and
    :func:`select_signature_readout` decides instead (``groups`` and
    ``views`` go to it). Without:

    1. A Gaussian-process readout (:class:`GPReadout`) on the most slowest
       outputs offered (12, or ``max(n_outputs)``), its ARD hyperparameters
       by maximum marginal likelihood on the whole run.
    2. Every candidate of :func:`auto_candidates` (Gaussian kernel ridge and
       kNN on 8 and 12 outputs, or ``n_outputs``; only those the features
       have) and the GP with its hyperparameters fixed are scored by blocked
       CV (mean held-out Euclidean error, m): the run cut into blocks of
       ``block`` consecutive images, block ``i`` held out in fold ``i mod
       n_folds`` (``block=None``: ``n_folds`` contiguous stretches); with
       ``groups`` (a label per sample, at least two distinct: the recording
       each sample comes from) one group held out per fold instead
       (:func:`group_folds`, at most ``n_folds`` of them).
    3. The GP is taken unless the best other candidate's CV error is lower by
       more than ``tolerance`` (relative); among the others kNN only if it
       beats kernel ridge by more than ``tolerance``.

    ``gp=False`` leaves the GP out (the earlier default: kernel ridge unless
    kNN is better by ``tolerance``). On the gardens and 5.1.1 runs, 5
    contiguous folds picked kNN where kernel ridge was better on the test
    run, and contiguous folds (whole strips of the area held out) chose too
    smooth kernels (docs/gardens.md). Runs too short for ``n_folds`` folds of
    ``block`` images use fewer folds (at least 2) and shorter blocks.
    Returns a :class:`ReadoutSelection` whose ``rule`` says why."""
    F = as_matrix(features, "features")
    Y = as_matrix(xy, "xy")
    check_same_length(F, Y, "features", "xy")
    if n_signature:
        return select_signature_readout(F, Y, n_signature, n_outputs=n_outputs, groups=groups, views=views,
                                        tolerance=tolerance)
    g = _group_labels(groups, len(F))
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
    scores = _scores(cands, F, Y, folds, max_cv_samples, blk, g)
    sel = ReadoutSelection({}, None, [dict(c) for c in cands], scores)
    k_spec, k_err = sel.best_of("kernel")
    n_spec, n_err = sel.best_of("knn")
    if np.isfinite(n_err) and (not np.isfinite(k_err) or n_err < (1.0 - tolerance) * k_err):
        spec, err, why = n_spec, n_err, f"kNN: CV {n_err:.3f} m < (1 - {tolerance:g}) x kernel ridge's {k_err:.3f} m"
    else:
        spec, err, why = k_spec, k_err, f"kernel ridge: CV {k_err:.3f} m (kNN {n_err:.3f} m not {tolerance:.0%} lower)"
    how = f"{folds}-fold blocked CV" + (f" (blocks of {blk} images)" if blk is not None else " (contiguous)")
    if g is not None:
        how = f"leave-one-group-out CV ({min(folds, len(np.unique(g)))} of {len(np.unique(g))} groups held out)"
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
                with quiet_extrapolation():
                    pred = make_readout(spec).fit(F[tr], Y[tr]).predict(F[te])
                errs.append(float(np.hypot(*(pred - Y[te]).T).mean()))
            except (ValueError, np.linalg.LinAlgError):
                errs.append(np.inf)
        scores[i] = float(np.mean(errs))
    return scores


def select_signature_readout(features: Any, xy: Any, n_signature: int, *,
                             n_outputs: int | Sequence[int] | None = None, groups: Any = None,
                             views: Any = None, tolerance: float = AUTO_TOLERANCE,
                             max_group_folds: int = AUTO_GROUP_FOLDS) -> ReadoutSelection:
    """The default readout of slow features plus an appearance signature.

    ``features`` (N, m + n_signature): the slow features, slowest first, then
    the signature. Two :class:`SignatureGPReadout` models are fitted by
    maximum marginal likelihood: the slow features (12, or ``max(n_outputs)``,
    at most m) together with the signature, and the signature alone. They
    are nested (the first has one length scale per slow feature more), so
    the combination is taken unless its log marginal likelihood exceeds the
    signature's by less than the Bayesian information criterion's price of
    those length scales, ``0.5 * m' * ln(n)`` (n: the samples the
    hyperparameters were fitted on). This choice needs no cross-validation.

    ``groups`` (N,): the recording each sample comes from. With two or more,
    the chosen GP (its kernel kept, the posterior refitted per fold) is
    compared by leave-one-group-out cross-validation (at most
    ``max_group_folds`` recordings held out, :func:`group_folds`) with the
    nearest training views by the signature alone
    (:class:`SignatureKNNReadout`, k in :data:`SIGNATURE_KNN_K`); the views
    are taken if their mean held-out error is lower by more than
    ``tolerance`` (relative). On the nine lights of 6.2.2 the views win
    (docs/localization.md, "Several recordings"). ``views``: indices of the
    samples the nearest-view readout stores (default all; the originals of a
    run fitted together with corrupted copies).

    Returns a :class:`ReadoutSelection` whose ``rule`` says why."""
    F = as_matrix(features, "features")
    Y = as_matrix(xy, "xy")
    check_same_length(F, Y, "features", "xy")
    q = int(n_signature)
    m = F.shape[1] - q
    if q < 1 or m < 0:
        raise ValueError(f"n_signature must be in [1, {F.shape[1]}], got {n_signature}")
    if n_outputs is None:
        n = min(12, m)
    else:
        n = int(n_outputs) if np.isscalar(n_outputs) else max(int(v) for v in n_outputs)  # type: ignore[arg-type]
        if not 0 <= n <= m:
            raise ValueError(f"n_outputs {n} out of range: the features have {m} slow-feature columns")
    if not 0.0 <= float(tolerance) < 1.0:
        raise ValueError(f"tolerance must be in [0, 1), got {tolerance}")
    g = _group_labels(groups, len(F))
    view_idx = None if views is None else _views(views, len(F))
    spec_alone = {"kind": "gp-signature", "n_outputs": 0, "n_signature": q}
    if n == 0:
        sel = ReadoutSelection(spec_alone, SignatureGPReadout(0, q).fit(F, Y),
                               rule="the signature alone (no slow features offered)")
    else:
        both, alone = SignatureGPReadout.fit_nested(F, Y, n, q)
        n_fit = min(len(F), both.max_fit)
        price = 0.5 * n * np.log(n_fit)
        gain = both.log_marginal_likelihood_ - alone.log_marginal_likelihood_
        cands = [{"kind": "gp-signature", "n_outputs": n, "n_signature": q}, spec_alone]
        scores = np.array([-both.log_marginal_likelihood_, -alone.log_marginal_likelihood_])
        if gain > price:
            sel = ReadoutSelection(cands[0], both, cands, scores,
                                   rule=(f"slow features and signature: log marginal likelihood {gain:.1f} above "
                                         f"the signature alone's, more than the BIC price {price:.1f} of {n} length "
                                         "scales"))
        else:
            sel = ReadoutSelection(spec_alone, alone, cands, scores,
                                   rule=(f"the signature alone: {n} slow features raise the log marginal likelihood "
                                         f"by {gain:.1f}, not more than their BIC price {price:.1f}"))
    if g is None:
        return sel
    return _by_recordings(sel, F, Y, q, g, view_idx, float(tolerance), max_group_folds)


def _views(views: Any, n: int) -> np.ndarray:
    v = np.asarray(views)
    if v.ndim != 1 or v.size == 0 or v.dtype.kind not in "iu" or v.min() < 0 or v.max() >= n:
        raise ValueError(f"views must be a non-empty 1-D array of indices into the {n} samples")
    return np.unique(v)


def _by_recordings(sel: ReadoutSelection, F: np.ndarray, Y: np.ndarray, q: int, groups: np.ndarray,
                   views: np.ndarray | None, tolerance: float, max_folds: int) -> ReadoutSelection:
    """``sel``'s GP against the nearest views by signature, one recording
    held out at a time: the views replace it when clearly better."""
    folds = group_folds(groups, max_folds)
    gp_spec, gp = dict(sel.spec), sel.readout
    knn_specs = [{"kind": "knn-signature", "n_outputs": 0, "n_signature": q, "k": k} for k in SIGNATURE_KNN_K]
    errs = np.zeros(1 + len(knn_specs))
    held_total = 0
    for tr, te in folds:
        fold_gp = SignatureGPReadout(gp.n_outputs, q, max_fit=gp.max_fit, max_train=gp.max_train)
        preds = [fold_gp.fit(F[tr], Y[tr], hyperparameters_from=gp).predict(F[te])]
        local = None if views is None else np.flatnonzero(np.isin(tr, views))
        if local is not None and local.size == 0:
            local = None
        for spec in knn_specs:
            preds.append(make_readout(spec).fit(F[tr], Y[tr], views=local).predict(F[te]))
        errs += [float(np.hypot(*(p - Y[te]).T).sum()) for p in preds]
        held_total += len(te)
    errs /= held_total
    best = 1 + int(np.argmin(errs[1:]))
    n_groups = len(np.unique(groups))
    how = f"leave-one-recording-out CV ({len(folds)} of {n_groups} recordings held out)"
    cands = [gp_spec] + knn_specs
    if errs[best] < (1.0 - tolerance) * errs[0]:
        spec = knn_specs[best - 1]
        readout = make_readout(spec).fit(F, Y, views=views)
        rule = (f"{how}: the nearest training views by the signature ({describe_spec(spec)}) {errs[best]:.3f} m, "
                f"more than {tolerance:.0%} below the GP's {errs[0]:.3f} m ({sel.rule})")
        return ReadoutSelection(spec, readout, cands, errs, rule=rule)
    rule = (f"{sel.rule}; {how}: GP {errs[0]:.3f} m, the nearest views by the signature "
            f"{errs[best]:.3f} m not {tolerance:.0%} lower")
    return ReadoutSelection(gp_spec, gp, cands, errs, rule=rule)
