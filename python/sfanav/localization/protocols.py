"""Evaluation protocols of a readout (thesis 3.5, 5.1), and which one produced
a number.

``"test-run"`` (:func:`evaluate_test_run`)
    Fit on the training run, measure on a separate test run (thesis 5.1.2,
    5.2-5.4). The honest figure.
``"random-splits"`` (:func:`evaluate_random_splits`)
    Random 50/50 splits of one run, repeated with a seeded generator
    (thesis 5.1.1). Optimistic on a continuous walk: neighbouring frames are
    near copies, so most test frames have a near-duplicate in the training
    half.

:func:`error_vs_n`: the error against the number of slow features used."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_matrix, check_int, check_nonneg_float, check_same_length
from ..sfa.node import expand
from .error_metrics import localization_metrics
from .extrapolation import quiet_extrapolation
from .quadratic import QuadraticRegression, fit_weights

TEST_RUN = "test-run"


RANDOM_SPLITS = "random-splits"


def _describe(protocol: str, n_repeats: int = 0, test_fraction: float = 0.5, seed: Any = None) -> str:
    if protocol == TEST_RUN:
        return "fit on the training run, error on a separate test run"
    pct = round(100 * test_fraction)
    return (
        f"random {100 - pct}/{pct} splits of one run, repeated {n_repeats} times (seed {seed}); "
        "optimistic on a continuous walk, where neighbouring frames are near copies"
    )


@dataclass
class RegressionResult:
    """The outcome of one evaluation protocol.

    Attributes
    ----------
    protocol : str
        ``"test-run"`` or ``"random-splits"``.
    description : str
        The protocol in words, with its caveat.
    n_outputs, ridge : int, float
        The regression's settings.
    metrics : dict
        Test metrics (:func:`sfanav.localization.localization_metrics`); for
        random splits the mean over the repeats. MAE % is relative to the
        coordinate range of the evaluated run (all of it, for splits).
    metrics_std : dict or None
        For random splits: standard deviation of each metric over the repeats.
    train_metrics : dict
        The same on the data the regression was fitted on (mean over repeats
        for splits).
    predictions : ndarray of shape (N, 2)
        Test-run estimates; for random splits each sample's estimate averaged
        over the repeats in which it was in the test half (NaN if never).
    n_repeats : int
        1 for a test run.
    """

    protocol: str
    description: str
    n_outputs: int
    ridge: float
    metrics: dict[str, float]
    train_metrics: dict[str, float]
    predictions: np.ndarray
    metrics_std: dict[str, float] | None = None
    n_repeats: int = 1

    def summary(self) -> str:
        m = self.metrics
        return (
            f"[{self.protocol}] n={self.n_outputs}: MED {m['med']:.3f} m, MAE x {m['mae_x']:.3f} m "
            f"({m['mae_x_pct']:.2f} %), y {m['mae_y']:.3f} m ({m['mae_y_pct']:.2f} %) -- {self.description}"
        )


def _check_run(features: Any, xy: Any, fname: str, xname: str) -> tuple[np.ndarray, np.ndarray]:
    F = as_matrix(features, fname)
    Y = as_matrix(xy, xname)
    check_same_length(F, Y, fname, xname)
    return F, Y


def evaluate_test_run(
    features_train: Any,
    xy_train: Any,
    features_test: Any,
    xy_test: Any,
    *,
    n_outputs: int = 8,
    ridge: float = 0.0,
    degree: int = 2,
) -> RegressionResult:
    """Protocol ``"test-run"``: fit on the training run, measure on a separate
    test run (thesis 5.1.2 onwards). Features (N, m), positions (N, 2) in metres."""
    Ftr, Ytr = _check_run(features_train, xy_train, "features_train", "xy_train")
    Fte, Yte = _check_run(features_test, xy_test, "features_test", "xy_test")
    reg = QuadraticRegression(n_outputs, ridge, degree).fit(Ftr, Ytr)
    pred = reg.predict(Fte)
    return RegressionResult(
        protocol=TEST_RUN,
        description=_describe(TEST_RUN),
        n_outputs=reg.n_outputs_,
        ridge=float(ridge),
        metrics=localization_metrics(pred, Yte),
        train_metrics=localization_metrics(reg.predict(Ftr), Ytr),
        predictions=pred,
    )


def _splits(n: int, n_repeats: int, test_fraction: float, random_state: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    if not 0 < test_fraction < 1:
        raise ValueError(f"test_fraction must be in (0, 1), got {test_fraction}")
    n_test = int(round(n * test_fraction))
    if n_test < 1 or n - n_test < 2:
        raise ValueError(f"{n} samples are too few for {test_fraction:.0%} test splits")
    rng = np.random.default_rng(random_state)
    out = []
    for _ in range(check_int(n_repeats, "n_repeats")):
        perm = rng.permutation(n)
        out.append((np.sort(perm[n_test:]), np.sort(perm[:n_test])))
    return out


def _mean_std(dicts: list[dict[str, float]]) -> tuple[dict[str, float], dict[str, float]]:
    keys = dicts[0].keys()
    mean = {k: float(np.mean([d[k] for d in dicts])) for k in keys}
    std = {k: float(np.std([d[k] for d in dicts])) for k in keys}
    return mean, std


def evaluate_random_splits(
    features: Any,
    xy: Any,
    *,
    n_outputs: int = 8,
    ridge: float = 0.0,
    degree: int = 2,
    n_repeats: int = 100,
    test_fraction: float = 0.5,
    random_state: int | np.random.Generator | None = 0,
) -> RegressionResult:
    """Protocol ``"random-splits"`` (thesis 5.1.1): random splits of one run
    (default 50/50), regression fitted on one part and measured on the other,
    repeated ``n_repeats`` times with a seeded generator; metrics are averaged
    over the repeats. MAE % is relative to the coordinate range of all of ``xy``.

    Optimistic on continuous walks (see the module docstring); prefer
    :func:`evaluate_test_run` when a separate test run exists.
    """
    F, Y = _check_run(features, xy, "features", "xy")
    rng_xy = Y.max(axis=0) - Y.min(axis=0)
    splits = _splits(len(F), n_repeats, test_fraction, random_state)
    test_m, train_m = [], []
    pred_sum = np.zeros_like(Y)
    pred_cnt = np.zeros(len(Y))
    reg = QuadraticRegression(n_outputs, ridge, degree)
    with quiet_extrapolation():  # resamples of one run: errors are reported, not positions
        for tr, te in splits:
            reg.fit(F[tr], Y[tr])
            p = reg.predict(F[te])
            pred_sum[te] += p
            pred_cnt[te] += 1
            test_m.append(localization_metrics(p, Y[te], coordinate_range=rng_xy))
            train_m.append(localization_metrics(reg.predict(F[tr]), Y[tr], coordinate_range=rng_xy))
    mean, std = _mean_std(test_m)
    train_mean, _ = _mean_std(train_m)
    with np.errstate(invalid="ignore", divide="ignore"):
        preds = pred_sum / pred_cnt[:, None]
    seed = random_state if isinstance(random_state, (int, np.integer)) else "given generator"
    return RegressionResult(
        protocol=RANDOM_SPLITS,
        description=_describe(RANDOM_SPLITS, len(splits), test_fraction, seed),
        n_outputs=reg.n_outputs_,
        ridge=float(ridge),
        metrics=mean,
        metrics_std=std,
        train_metrics=train_mean,
        predictions=preds,
        n_repeats=len(splits),
    )


@dataclass
class ErrorCurve:
    """Training and test error (MED, metres) against the number of slowest
    outputs used (thesis Fig. 5.3 and 5.6).

    Attributes
    ----------
    ns : ndarray of int
    train_error, test_error : ndarray of float
        MED for each n (mean over repeats for random splits).
    test_error_std : ndarray or None
        Standard deviation over repeats (random splits only).
    best_n : int
        The n with the smallest test error.
    protocol, description : str
        As in :class:`RegressionResult`.
    """

    ns: np.ndarray
    train_error: np.ndarray
    test_error: np.ndarray
    best_n: int
    protocol: str
    description: str
    test_error_std: np.ndarray | None = field(default=None)

    def plot(self, path: Any, *, title: str | None = None) -> Any:
        """Writes the curve as a PNG (see :func:`sfanav.localization.plot_error_vs_n`)."""
        from .plots import plot_error_vs_n

        return plot_error_vs_n(
            self.ns, self.train_error, self.test_error, path, best_n=self.best_n,
            protocol=self.protocol, title=title,
        )


def error_vs_n(
    features_train: Any,
    xy_train: Any,
    features_test: Any = None,
    xy_test: Any = None,
    ns: Iterable[int] = range(2, 13),
    *,
    ridge: float = 0.0,
    degree: int = 2,
    n_repeats: int = 100,
    test_fraction: float = 0.5,
    random_state: int | np.random.Generator | None = 0,
) -> ErrorCurve:
    """Training and test MED for regressions on the first n outputs, n in ``ns``.

    With ``features_test``/``xy_test``: protocol ``"test-run"``. Without them:
    protocol ``"random-splits"`` on ``features_train``/``xy_train`` (the same
    seeded splits for every n, so the curve compares like with like).

    Parameters
    ----------
    features_train : array (N, m)
        Slow features, slowest first; m >= max(ns).
    xy_train : array (N, 2)
        Positions in metres.
    features_test, xy_test : arrays, optional
        A separate test run.
    ns : iterable of int
        Numbers of outputs to try (thesis: 2..12).
    """
    ns_arr = np.array(sorted({check_int(int(n), "n") for n in ns}), dtype=int)
    if len(ns_arr) == 0:
        raise ValueError("ns is empty")
    Ftr, Ytr = _check_run(features_train, xy_train, "features_train", "xy_train")
    if ns_arr[-1] > Ftr.shape[1]:
        raise ValueError(f"ns goes up to {ns_arr[-1]}, but the features have only {Ftr.shape[1]} columns")
    if (features_test is None) != (xy_test is None):
        raise ValueError("give both features_test and xy_test, or neither (random splits)")
    degree = check_int(degree, "degree")
    ridge = check_nonneg_float(ridge, "ridge")
    train_err = np.empty(len(ns_arr))
    test_err = np.empty(len(ns_arr))
    test_std = None
    if features_test is not None:
        Fte, Yte = _check_run(features_test, xy_test, "features_test", "xy_test")
        if Fte.shape[1] < ns_arr[-1]:
            raise ValueError(f"ns goes up to {ns_arr[-1]}, but features_test has only {Fte.shape[1]} columns")
        for i, n in enumerate(ns_arr):
            Etr = expand(np.ascontiguousarray(Ftr[:, :n]), degree)
            Ete = expand(np.ascontiguousarray(Fte[:, :n]), degree)
            coef, icpt, _ = fit_weights(Etr, Ytr, ridge)
            train_err[i] = np.linalg.norm(Etr @ coef + icpt - Ytr, axis=1).mean()
            test_err[i] = np.linalg.norm(Ete @ coef + icpt - Yte, axis=1).mean()
        protocol, desc = TEST_RUN, _describe(TEST_RUN)
    else:
        splits = _splits(len(Ftr), n_repeats, test_fraction, random_state)
        test_std = np.empty(len(ns_arr))
        for i, n in enumerate(ns_arr):
            E = expand(np.ascontiguousarray(Ftr[:, :n]), degree)
            tr_e, te_e = [], []
            for tr, te in splits:
                coef, icpt, _ = fit_weights(E[tr], Ytr[tr], ridge)
                tr_e.append(np.linalg.norm(E[tr] @ coef + icpt - Ytr[tr], axis=1).mean())
                te_e.append(np.linalg.norm(E[te] @ coef + icpt - Ytr[te], axis=1).mean())
            train_err[i], test_err[i], test_std[i] = np.mean(tr_e), np.mean(te_e), np.std(te_e)
        seed = random_state if isinstance(random_state, (int, np.integer)) else "given generator"
        protocol, desc = RANDOM_SPLITS, _describe(RANDOM_SPLITS, len(splits), test_fraction, seed)
    return ErrorCurve(
        ns=ns_arr,
        train_error=train_err,
        test_error=test_err,
        best_n=int(ns_arr[int(np.argmin(test_err))]),
        protocol=protocol,
        description=desc,
        test_error_std=test_std,
    )
