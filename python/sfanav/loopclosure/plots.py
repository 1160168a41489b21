"""Plots of loop closures on the trajectory (thesis Fig. 6.9, 6.15a)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .._checks import as_matrix
from .._plotting import figure, save_figure
from .closures import LoopClosures


def plot_closures(positions: Any, closures: LoopClosures, path: Any, *, title: str | None = None,
                  dpi: int = 120) -> Path:
    """The run's trajectory (positions (N, 2) m) with a segment from each
    closure's past to its current position and a dot at the current one,
    coloured by score. Returns the PNG's path."""
    P = as_matrix(positions, "positions", n_cols=2)
    fig = figure(6, 6)
    ax = fig.add_subplot()
    ax.plot(P[:, 0], P[:, 1], color="0.75", lw=0.8, label="trajectory")
    if len(closures):
        import matplotlib as mpl

        cmap = mpl.colormaps["viridis"]
        for p, c, s in zip(closures.past, closures.current, closures.score):
            ax.plot(*P[[p, c]].T, color=cmap(float(s)), lw=1.2)
        sc = ax.scatter(*P[closures.current].T, c=closures.score, cmap=cmap, vmin=0, vmax=1, s=14, zorder=3,
                        label=f"{len(closures)} loop closures")
        fig.colorbar(sc, ax=ax, shrink=0.7, label="score")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or f"{len(closures)} loop closures")
    return save_figure(fig, path, dpi)


def plot_precision_recall(curves: dict[str, tuple[np.ndarray, np.ndarray]], path: Any, *,
                          title: str = "loop closures: precision vs recall", dpi: int = 120) -> Path:
    """Precision-recall curves ``{label: (recall, precision)}``."""
    fig = figure(5, 4)
    ax = fig.add_subplot()
    for label, (r, p) in curves.items():
        ax.plot(r, p, label=label)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.legend()
    ax.set_title(title)
    return save_figure(fig, path, dpi)
