"""Figures of the odometry stage: the learned lines of metric learning on the
map, and an EKF-fused track beside the SFA estimates and odometry. Each
function writes a PNG and returns its path."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import as_matrix, as_real_array, check_is_fitted, check_same_length
from .metric_learning import MetricLearner


def plot_fusion(
    xy_true: Any,
    sfa: Any,
    odometry: Any,
    fused: Any,
    path: Any,
    *,
    labels: Sequence[str] = ("SFA", "odometry", "EKF"),
    title: str | None = None,
    dpi: int = 120,
) -> Path:
    """Thesis fig. 5.24: three panels, each estimate (SFA, odometry, EKF)
    against the ground truth, with its MED in the panel title.

    Parameters
    ----------
    xy_true : array (N, 2)
        Ground truth, metres.
    sfa, odometry, fused : arrays (N, 2) or (N, 3)
        Estimated positions (poses' headings are ignored), metres, all in the
        ground truth's frame; NaN rows of ``sfa`` are skipped.
    path : str or Path
        Output PNG.
    """
    from .._plotting import figure, save_figure

    T = as_matrix(xy_true, "xy_true", n_cols=2)
    ests = []
    for name, e in zip(("sfa", "odometry", "fused"), (sfa, odometry, fused)):
        a = as_real_array(e, name).astype(np.float64, copy=False)
        if a.ndim != 2 or a.shape[1] not in (2, 3) or len(a) != len(T):
            raise ValueError(f"{name} must have shape ({len(T)}, 2) or ({len(T)}, 3), got {a.shape}")
        ests.append(a[:, :2])
    fig = figure(12.0, 4.3 + (0.3 if title else 0))
    axes = fig.subplots(1, 3, sharex=True, sharey=True)
    styles = [".", "-", "-"]
    for ax, E, lab, st in zip(axes, ests, labels, styles):
        ok = np.isfinite(E).all(axis=1)
        err = np.linalg.norm(E[ok] - T[ok], axis=1).mean() if ok.any() else np.nan
        ax.plot(T[:, 0], T[:, 1], "-", color="0.55", lw=1.2, label="ground truth")
        if st == ".":
            ax.plot(E[ok, 0], E[ok, 1], ".", color="tab:red", ms=2.5, label=lab)
        else:
            ax.plot(E[ok, 0], E[ok, 1], "-", color="tab:red", lw=1.0, label=lab)
        ax.set_aspect("equal", adjustable="box")
        ax.set_title(f"{lab}: MED {err:.3f} m")
        ax.set_xlabel("x [m]")
        ax.legend(loc="best", fontsize="small")
    axes[0].set_ylabel("y [m]")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path, dpi)






def plot_metric_lines(
    learner: MetricLearner,
    features: Any,
    path: Any,
    *,
    iterations: Sequence[int] | None = None,
    title: str | None = None,
    dpi: int = 120,
) -> Path:
    """The optimisation as in thesis fig. 5.19: one panel per recorded
    iteration; per line, in its own colour, the line-model estimates
    ``o_n + d u(alpha_n)`` dotted and the feature estimates ``W^T s`` solid.

    Parameters
    ----------
    learner : MetricLearner
        Fitted, with ``snapshot_iterations`` e.g. (0, 500, 1000).
    features : array (N, m)
        The features it was fitted on.
    path : str or Path
        Output PNG.
    iterations : sequence of int, optional
        Snapshots to show; default all recorded (the last is the result).
    """
    from .._plotting import figure, save_figure

    check_is_fitted(learner, "weights_")
    F = as_matrix(features, "features")
    check_same_length(F, learner.lines_.labels, "features", "the fitted lines")
    its = sorted(learner.snapshots_) if iterations is None else [int(i) for i in iterations]
    missing = [i for i in its if i not in learner.snapshots_]
    if missing:
        raise ValueError(f"no snapshot at iteration(s) {missing}; recorded: {sorted(learner.snapshots_)}")
    lab = learner.lines_.labels
    L = learner.lines_.n_lines
    fig = figure(4.0 * len(its), 4.2 + (0.3 if title else 0))
    axes = fig.subplots(1, len(its), squeeze=False)[0]
    from matplotlib import colormaps

    cmap = colormaps["tab20" if L > 10 else "tab10"]
    for ax, it in zip(axes, its):
        lp = learner.line_points(it)
        fp = learner.transform_snapshot(F, it)
        for n in range(L):
            sel = lab == n
            col = cmap(n % cmap.N)
            ax.plot(lp[sel, 0], lp[sel, 1], ":", color=col, lw=1.5)
            ax.plot(fp[sel, 0], fp[sel, 1], "-", color=col, lw=0.8)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"iteration {it}")
        ax.set_xlabel("x [m]")
    axes[0].set_ylabel("y [m]")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path, dpi)
