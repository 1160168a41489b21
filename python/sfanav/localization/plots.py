"""Figures of localization results: firing maps of the slow features over
the area (thesis fig. 5.3), estimated against true trajectories, and error
against the number of outputs used. Each function writes a PNG and returns
its path."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import as_matrix, as_real_array, check_same_length
from .._plotting import figure, save_figure
from ..sfa.diagnostics import as_rotated_outputs, orientation_angles


def plot_firing_maps(
    outputs: Any,
    xy: Any,
    path: Any,
    *,
    which: Sequence[int] = (0, 1, 2, 3),
    orientations: Sequence[float] = (0, 90, 180, 270),
    angles: Any = None,
    bins: int | None = None,
    cmap: str = "viridis",
    title: str | None = None,
    dpi: int = 120,
) -> Path:
    """Spatial firing maps (thesis Fig. 3.3c, 5.2a, 5.5a): each output's value
    colour-coded over position, one column per orientation.

    Parameters
    ----------
    outputs : array (N, K, n) or (N, n)
        Outputs under ``K`` simulated rotations (``Network.transform(images,
        rotations=True)``), or at one orientation only.
    xy : array (N, 2)
        Positions, metres.
    path : str or Path
        Output PNG.
    which : sequence of int
        Output indices to plot (0 = slowest); rows of the figure.
    orientations : sequence of float
        Relative orientations in degrees (columns); each picks the nearest
        rotation. Ignored for (N, n) outputs.
    angles : array (K,), optional
        Degrees of each rotation (see :func:`orientation_angles`); default evenly spaced.
    bins : int, optional
        Average into a ``bins x bins`` grid (for dense walks); default: one
        square marker per sample.
    """
    a = as_real_array(outputs, "outputs").astype(np.float64, copy=False)
    if a.ndim == 2:
        a = a[:, None, :]
        orientations, angles = (0.0,), np.zeros(1)
    a = as_rotated_outputs(a)
    P = as_matrix(xy, "xy", n_cols=2)
    check_same_length(a, P, "outputs", "xy")
    K, n = a.shape[1], a.shape[2]
    which = [int(j) for j in which]
    if not which or min(which) < 0 or max(which) >= n:
        raise ValueError(f"which must list output indices in 0..{n - 1}, got {which}")
    ang = orientation_angles(K) if angles is None else np.asarray(angles, dtype=float)
    if ang.shape != (K,):
        raise ValueError(f"angles must have shape ({K},), got {ang.shape}")
    cols = []
    for o in orientations:
        diff = np.abs((ang - float(o) + 180.0) % 360.0 - 180.0)
        cols.append(int(np.argmin(diff)))
    fig = figure(2.4 * len(cols) + 0.8, 2.2 * len(which) + (0.4 if title else 0))
    axes = fig.subplots(len(which), len(cols), squeeze=False, sharex=True, sharey=True)
    x0, x1, y0, y1 = P[:, 0].min(), P[:, 0].max(), P[:, 1].min(), P[:, 1].max()
    pad = 0.02 * max(x1 - x0, y1 - y0)
    x0, x1, y0, y1 = x0 - pad, x1 + pad, y0 - pad, y1 + pad
    marker = float(np.clip((150.0 / np.sqrt(len(P))) ** 2, 2.0, 200.0))  # points^2: tiles a ~2 inch panel
    for r, j in enumerate(which):
        vals = a[:, cols, j]
        vmin, vmax = float(vals.min()), float(vals.max())
        im = None
        for c, k in enumerate(cols):
            ax = axes[r, c]
            v = a[:, k, j]
            if bins:
                sums, xe, ye = np.histogram2d(P[:, 0], P[:, 1], bins=bins, weights=v)
                cnt, _, _ = np.histogram2d(P[:, 0], P[:, 1], bins=[xe, ye])
                with np.errstate(invalid="ignore"):
                    grid = np.where(cnt > 0, sums / np.maximum(cnt, 1), np.nan)
                im = ax.pcolormesh(xe, ye, grid.T, cmap=cmap, vmin=vmin, vmax=vmax)
            else:
                im = ax.scatter(P[:, 0], P[:, 1], c=v, s=marker, marker="s", cmap=cmap, vmin=vmin, vmax=vmax, linewidths=0)
            ax.set_aspect("equal")
            if x1 > x0:
                ax.set_xlim(x0, x1)
            if y1 > y0:
                ax.set_ylim(y0, y1)
            if r == 0:
                ax.set_title(f"{ang[k]:.0f}\N{DEGREE SIGN}")
            if c == 0:
                ax.set_ylabel(f"s{j + 1}  y [m]")
            if r == len(which) - 1:
                ax.set_xlabel("x [m]")
        fig.colorbar(im, ax=list(axes[r]), shrink=0.9)
    if title:
        fig.suptitle(title)
    return save_figure(fig, path, dpi)


def plot_trajectory(
    xy_true: Any,
    xy_pred: Any,
    path: Any,
    *,
    title: str | None = None,
    connect: bool = True,
    error_lines: bool = False,
    dpi: int = 120,
) -> Path:
    """Ground truth and estimated positions (thesis Fig. 5.2b, 5.5b), equal
    axes in metres. ``connect`` draws the ground truth as a line (a walk);
    ``error_lines`` joins each estimate to its true position."""
    T = as_matrix(xy_true, "xy_true", n_cols=2)
    E = as_real_array(xy_pred, "xy_pred").astype(np.float64, copy=False)
    if E.shape != T.shape:
        raise ValueError(f"xy_pred must have the shape of xy_true {T.shape}, got {E.shape}")
    ok = np.isfinite(E).all(axis=1)  # random-split predictions may hold NaN rows
    fig = figure(5.5, 5.0)
    ax = fig.subplots()
    if error_lines:
        from matplotlib.collections import LineCollection

        segs = np.stack([T[ok], E[ok]], axis=1)
        ax.add_collection(LineCollection(segs, colors="0.7", linewidths=0.5))
    if connect:
        ax.plot(T[:, 0], T[:, 1], "-", color="tab:blue", lw=1.0, label="ground truth")
    else:
        ax.plot(T[:, 0], T[:, 1], ".", color="tab:blue", ms=3, label="ground truth")
    ax.plot(E[ok, 0], E[ok, 1], ".", color="tab:red", ms=3, label="estimate")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best", fontsize="small")
    if title:
        ax.set_title(title)
    return save_figure(fig, path, dpi)


def plot_error_vs_n(
    ns: Any,
    train_error: Any,
    test_error: Any,
    path: Any,
    *,
    best_n: int | None = None,
    protocol: str | None = None,
    title: str | None = None,
    unit: str = "m",
    dpi: int = 120,
) -> Path:
    """Training and test error against the number of slow outputs used
    (thesis Fig. 5.3, 5.6). ``train_error`` may be None."""
    ns_a = np.asarray(ns, dtype=float).ravel()
    te = np.asarray(test_error, dtype=float).ravel()
    if te.shape != ns_a.shape:
        raise ValueError(f"test_error must have one value per n ({len(ns_a)}), got {te.shape}")
    fig = figure(5.0, 3.5)
    ax = fig.subplots()
    if train_error is not None:
        tr = np.asarray(train_error, dtype=float).ravel()
        if tr.shape != ns_a.shape:
            raise ValueError(f"train_error must have one value per n ({len(ns_a)}), got {tr.shape}")
        ax.plot(ns_a, tr, "o-", label="training error")
    ax.plot(ns_a, te, "s-", label="test error")
    if best_n is not None:
        ax.axvline(best_n, color="0.5", ls="--", lw=0.8, label=f"best n = {best_n}")
    ax.set_xlabel("number of slow outputs n")
    ax.set_ylabel(f"MED [{unit}]")
    ax.set_xticks(ns_a)
    ax.legend(fontsize="small")
    ax.set_title(title or (f"error vs n ({protocol})" if protocol else "error vs n"))
    return save_figure(fig, path, dpi)
