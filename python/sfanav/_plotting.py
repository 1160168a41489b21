"""Shared figure helpers: every plot of sfanav is drawn with matplotlib's Agg
backend (no display needed) and written as a PNG by :func:`save_figure`."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def figure(width: float, height: float):
    from matplotlib.figure import Figure  # Agg canvas; no pyplot, no display

    return Figure(figsize=(width, height), layout="constrained")


def save_figure(fig: Any, path: Any, dpi: int) -> Path:
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"plots are written as PNG: give a path ending in .png, got {path}")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, format="png")
    return path
