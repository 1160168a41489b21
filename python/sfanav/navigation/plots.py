"""Navigation figures: the cost surface over the area (thesis fig. 7.7) and
trajectories of trials (figs. 7.3, 7.6, 7.9, 7.10). Each writes a PNG and
returns its path."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .cost import SlowFeatureCost, as_vector2
from .navigator import NavigationResult


def _draw_world(ax: Any, world: Any, area: Sequence[float] | None) -> None:
    from matplotlib.patches import Circle, Polygon, Rectangle

    if area is not None:
        w, h = area
        ax.add_patch(Rectangle((-w / 2, -h / 2), w, h, fill=False, ec="0.3", lw=1.0))
    if world is None:
        return
    for o in getattr(world, "obstacles", []):
        for p in o.parts:
            if p.shape != "box":
                ax.add_patch(Circle((p.x, p.y), p.radius, fc="0.15", ec="0.15"))
                continue
            c, s = np.cos(p.yaw), np.sin(p.yaw)
            hl, hw = p.length / 2, p.width / 2
            corners = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
            xy = np.column_stack([p.x + c * corners[:, 0] - s * corners[:, 1],
                                  p.y + s * corners[:, 0] + c * corners[:, 1]])
            ax.add_patch(Polygon(xy, closed=True, fc="0.15", ec="0.15"))


def plot_cost_surface(
    xs: Any,
    ys: Any,
    features: Any,
    target_features: Any,
    path: Any,
    *,
    ns: Sequence[int] = (2,),
    weights: Any = None,
    target: Any = None,
    n_firing: int | None = None,
    world: Any = None,
    cmap: str = "viridis",
    title: str | None = None,
    dpi: int = 110,
) -> Path:
    """Spatial firing maps and cost surfaces (thesis fig. 7.7).

    ``features`` (len(ys), len(xs), m): SFA outputs on a grid of positions
    ``xs`` x ``ys`` (m); NaN rows mark places that cannot be visited. Rows:
    the firing maps of outputs ``1..n_firing`` (default ``max(ns)``; 0 for
    none), the cost to ``target_features`` for each ``n`` in ``ns``
    with the raw outputs, and (when ``weights`` is given) with the weighted
    outputs. ``target`` (x, y) is marked with a white cross."""
    from .._plotting import figure, save_figure

    X = np.asarray(xs, float)
    Y = np.asarray(ys, float)
    F = np.asarray(features, float)
    if F.ndim != 3 or F.shape[:2] != (len(Y), len(X)):
        raise ValueError(f"features must have shape (len(ys), len(xs), m) = ({len(Y)}, {len(X)}, m), got {F.shape}")
    ns = [int(n) for n in ns]
    m = F.shape[2]
    if not ns or min(ns) < 1 or max(ns) > m:
        raise ValueError(f"ns must be in 1..{m}, got {ns}")
    nf = max(ns) if n_firing is None else int(n_firing)
    if not 0 <= nf <= m:
        raise ValueError(f"n_firing must be in 0..{m}, got {n_firing}")
    rowsets: list[list[tuple[str, np.ndarray]]] = []
    if nf:
        rowsets.append([(f"s{j + 1}", F[:, :, j]) for j in range(nf)])
    rowsets.append([(f"C, n={n}", SlowFeatureCost(target_features, n)(F)) for n in ns])
    if weights is not None:
        rowsets.append([(f"C 1/beta, n={n}", SlowFeatureCost(target_features, n, weights)(F)) for n in ns])
    ncol = max(len(r) for r in rowsets)
    aspect = (Y[-1] - Y[0]) / max(X[-1] - X[0], 1e-9) if len(X) > 1 and len(Y) > 1 else 1.0
    fig = figure(1.9 * ncol + 0.4, (1.9 * aspect + 0.35) * len(rowsets) + (0.4 if title else 0))
    axes = fig.subplots(len(rowsets), ncol, squeeze=False)
    for r, rs in enumerate(rowsets):
        for c in range(ncol):
            ax = axes[r, c]
            if c >= len(rs):
                ax.set_axis_off()
                continue
            name, V = rs[c]
            ax.pcolormesh(X, Y, np.ma.masked_invalid(V), cmap=cmap, shading="nearest")
            _draw_world(ax, world, None)
            if target is not None and name.startswith("C"):
                tx, ty = as_vector2(target, "target")
                ax.plot([tx], [ty], "x", color="white", ms=7, mew=2)
            ax.set_title(name, fontsize="small")
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
    if title:
        fig.suptitle(title)
    return save_figure(fig, path, dpi)


def plot_trajectories(
    results: Sequence[NavigationResult],
    path: Any,
    *,
    world: Any = None,
    area: Sequence[float] | None = None,
    background: tuple[Any, Any, Any] | None = None,
    optimal: Sequence[Any] | None = None,
    regions: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    titles: Sequence[str] | None = None,
    title: str | None = None,
    cols: int = 4,
    dpi: int = 110,
) -> Path:
    """Navigation trajectories (thesis figs. 7.3, 7.6, 7.9c, 7.10c): one
    panel per run, start as a black cross, target as a white circle, the
    driven path in red (success) or orange (failure), the optimal path
    (when ``optimal`` gives one per run) dashed blue, or white over a
    ``background``; obstacles in black.
    ``background`` = (xs, ys, values) is drawn under the paths (e.g. a cost
    surface); ``regions(X, Y)`` shades slow-velocity regions."""
    from .._plotting import figure, save_figure

    n = len(results)
    if n == 0:
        raise ValueError("no results to plot")
    cols = max(1, min(int(cols), n))
    rows = (n + cols - 1) // cols
    if area is None and world is not None:
        area = world.area
    aspect = area[1] / area[0] if area is not None else 1.0
    fig = figure(2.6 * cols + 0.2, 2.6 * aspect * rows + 0.3 + (0.4 if title else 0))
    axes = fig.subplots(rows, cols, squeeze=False)
    for i in range(rows * cols):
        ax = axes[i // cols, i % cols]
        if i >= n:
            ax.set_axis_off()
            continue
        r = results[i]
        if background is not None:
            bx, by, bv = background
            ax.pcolormesh(np.asarray(bx), np.asarray(by), np.ma.masked_invalid(np.asarray(bv, float)),
                          cmap="viridis", shading="nearest")
        elif regions is not None and area is not None:
            gx = np.linspace(-area[0] / 2, area[0] / 2, 181)
            gy = np.linspace(-area[1] / 2, area[1] / 2, 221)
            GX, GY = np.meshgrid(gx, gy)
            ax.pcolormesh(gx, gy, np.asarray(regions(GX, GY), float), cmap="Greys", vmin=0, vmax=3,
                          shading="nearest")
        _draw_world(ax, world, area)
        if optimal is not None and optimal[i] is not None and len(optimal[i]):
            op = np.asarray(optimal[i], float)
            if background is not None:  # the thesis's white line on the colour map
                ax.plot(op[:, 0], op[:, 1], "-", color="white", lw=1.6, zorder=2)
            else:
                ax.plot(op[:, 0], op[:, 1], "--", color="tab:blue", lw=1.2, zorder=2)
        P = r.path
        ax.plot(P[:, 0], P[:, 1], "-", color="tab:red" if r.success else "tab:orange", lw=1.3, zorder=3)
        ax.plot(P[:, 0], P[:, 1], ".", color="tab:red" if r.success else "tab:orange", ms=2, zorder=3)
        ax.plot([r.start[0]], [r.start[1]], "x", color="black", ms=8, mew=2, zorder=4)
        ax.plot([r.target[0]], [r.target[1]], "o", mfc="white", mec="black", ms=7, zorder=4)
        if area is not None:
            ax.set_xlim(-area[0] / 2, area[0] / 2)
            ax.set_ylim(-area[1] / 2, area[1] / 2)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        label = titles[i] if titles is not None else ("reached" if r.success else r.reason)
        ax.set_title(label, fontsize="small")
    if title:
        fig.suptitle(title)
    return save_figure(fig, path, dpi)
