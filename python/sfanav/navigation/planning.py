"""Planning baselines for navigation: A* on an occupancy grid
(:func:`astar`, :func:`shortest_path` for worlds; weighted for velocity
regions), and the optimal path and travel time across two velocity regions
(thesis 7.2.2: :func:`halfplane_optimal`, :func:`travel_time`)."""

from __future__ import annotations

import heapq
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .cost import as_vector2

# the 8-neighbourhood of a grid cell (row, column offsets)
N8 = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def astar(grid: Any, start: Sequence[int], goal: Sequence[int], weights: Any = None,
          *, connectivity: int = 8) -> tuple[list[tuple[int, int]], float]:
    """Shortest path on an occupancy grid with A*.

    Parameters
    ----------
    grid : bool array (rows, cols)
        True where a cell is free.
    start, goal : (row, col)
    weights : float array (rows, cols), optional
        Cost per unit length of each cell (>= 1 keeps the Euclidean
        heuristic admissible when the smallest weight is 1; in general the
        heuristic is scaled by the smallest weight). A move costs its length
        (1 or sqrt 2 cells) times the mean weight of the two cells.
    connectivity : 4 or 8

    Returns
    -------
    (path, cost): the cells from start to goal and the path cost in cells
    (times weights); ``([], inf)`` when the goal cannot be reached.
    """
    G = np.asarray(grid, bool)
    if G.ndim != 2:
        raise ValueError(f"grid must be 2-D, got shape {G.shape}")
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
    R, C = G.shape
    W = None
    if weights is not None:
        W = np.asarray(weights, float)
        if W.shape != G.shape or not np.isfinite(W).all() or (W <= 0).any():
            raise ValueError("weights must be positive finite numbers with the grid's shape")
    s, g = (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1]))
    for name, p in (("start", s), ("goal", g)):
        if not (0 <= p[0] < R and 0 <= p[1] < C):
            raise ValueError(f"{name} {p} is outside the grid {G.shape}")
        if not G[p]:
            return [], float("inf")
    hscale = float(W[G].min()) if W is not None else 1.0
    nbrs = N8 if connectivity == 8 else [(-1, 0), (0, -1), (0, 1), (1, 0)]
    steps = [(dr, dc, float(np.hypot(dr, dc))) for dr, dc in nbrs]

    def h(p: tuple[int, int]) -> float:
        return hscale * float(np.hypot(p[0] - g[0], p[1] - g[1]))

    best = {s: 0.0}
    parent: dict[tuple[int, int], tuple[int, int]] = {}
    heap = [(h(s), 0.0, s)]
    closed = set()
    while heap:
        f, cost, p = heapq.heappop(heap)
        if p in closed:
            continue
        if p == g:
            path = [p]
            while p in parent:
                p = parent[p]
                path.append(p)
            return path[::-1], cost
        closed.add(p)
        for dr, dc, L in steps:
            q = (p[0] + dr, p[1] + dc)
            if not (0 <= q[0] < R and 0 <= q[1] < C) or not G[q] or q in closed:
                continue
            if dr and dc and not (G[p[0] + dr, p[1]] and G[p[0], p[1] + dc]):
                continue  # no corner cutting
            step = L if W is None else L * 0.5 * (W[p] + W[q])
            nc = cost + step
            if nc < best.get(q, np.inf):
                best[q] = nc
                parent[q] = p
                heapq.heappush(heap, (nc + h(q), nc, q))
    return [], float("inf")


@dataclass
class GridMap:
    """A grid over the area: cell (row, col) has its centre at
    ``(x0 + col * res, y0 + row * res)``."""

    free: np.ndarray
    x0: float
    y0: float
    res: float

    def cell(self, xy: Any) -> tuple[int, int]:
        x, y = as_vector2(xy, "position")
        r = int(round((y - self.y0) / self.res))
        c = int(round((x - self.x0) / self.res))
        return min(max(r, 0), self.free.shape[0] - 1), min(max(c, 0), self.free.shape[1] - 1)

    def xy(self, cells: Sequence[tuple[int, int]]) -> np.ndarray:
        a = np.asarray(cells, float).reshape(-1, 2)
        return np.column_stack([self.x0 + a[:, 1] * self.res, self.y0 + a[:, 0] * self.res])

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        R, C = self.free.shape
        return np.meshgrid(self.x0 + np.arange(C) * self.res, self.y0 + np.arange(R) * self.res)


def occupancy_grid(area: Sequence[float], free: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
                   *, resolution: float = 0.1, margin: float = 0.35) -> GridMap:
    """Occupancy grid of ``resolution`` m over the area (thesis: 0.1): a cell
    is free when its centre is ``margin`` m inside the border and
    ``free(x, y)`` holds there (pass ``lambda x, y: world.free(x, y, r)`` to
    inflate obstacles by the robot radius ``r``)."""
    w, h = (float(a) for a in area)
    res = float(resolution)
    if not res > 0:
        raise ValueError(f"resolution must be positive, got {resolution}")
    nx, ny = int(np.floor(w / res)) + 1, int(np.floor(h / res)) + 1
    x0, y0 = -(nx - 1) * res / 2, -(ny - 1) * res / 2
    m = GridMap(np.zeros((ny, nx), bool), x0, y0, res)
    X, Y = m.centres()
    ok = (np.abs(X) <= w / 2 - margin + 1e-9) & (np.abs(Y) <= h / 2 - margin + 1e-9)
    if free is not None:
        ok &= np.asarray(free(X, Y), bool)
    m.free = ok
    return m


def path_length(path: Any) -> float:
    """Length of a polyline (k, 2) (m)."""
    P = np.asarray(path, float).reshape(-1, 2)
    return float(np.hypot(*np.diff(P, axis=0).T).sum()) if len(P) > 1 else 0.0


def _line_free(m: GridMap, a: np.ndarray, b: np.ndarray) -> bool:
    L = float(np.hypot(*(b - a)))
    k = max(2, int(np.ceil(L / (m.res * 0.5))) + 1)
    for t in np.linspace(0.0, 1.0, k):
        if not m.free[m.cell(a + t * (b - a))]:
            return False
    return True


def shortest_path(
    grid: GridMap,
    start: Any,
    goal: Any,
    *,
    weights: Any = None,
    smooth: bool = False,
    connectivity: int = 8,
) -> tuple[np.ndarray, float]:
    """A* between two positions on a :class:`GridMap` (:func:`occupancy_grid`).

    Returns (path (k, 2) in m, length or weighted cost in m). With
    ``smooth`` the grid path is shortened by line-of-sight (string pulling;
    unweighted grids only), which removes the 8-neighbourhood's detours of
    up to 8 % on oblique segments."""
    s, g = as_vector2(start, "start"), as_vector2(goal, "goal")
    cells, cost = astar(grid.free, grid.cell(s), grid.cell(g), weights, connectivity=connectivity)
    if not cells:
        return np.zeros((0, 2)), float("inf")
    P = grid.xy(cells)
    P[0], P[-1] = s, g
    if smooth and weights is None:
        out = [P[0]]
        i = 0
        while i < len(P) - 1:
            j = len(P) - 1
            while j > i + 1 and not _line_free(grid, P[i], P[j]):
                j -= 1
            out.append(P[j])
            i = j
        P = np.array(out)
        return P, path_length(P)
    # cost in cells -> metres; the ends are snapped to cell centres, add the offsets
    return P, float(cost * grid.res)


def halfplane_optimal(start: Any, target: Any, *, x0: float = 0.0, speed_left: float = 1.0,
                      speed_right: float = 3.0) -> tuple[np.ndarray, float]:
    """The time-optimal path between two half-planes of different speed
    (thesis 7.2.2, fig. 7.9): two straight pieces meeting at the transition
    point ``(x0, y)`` that minimises the travel time (Snell's law); found by
    a ternary search on the convex travel time. With start and target on the
    same side the straight line is optimal. Returns (path (k, 2), time)."""
    s, t = as_vector2(start, "start"), as_vector2(target, "target")
    vl, vr = float(speed_left), float(speed_right)

    def v(p: np.ndarray) -> float:
        return vl if p[0] < x0 else vr

    if (s[0] - x0) * (t[0] - x0) >= 0:
        return np.array([s, t]), float(np.hypot(*(t - s))) / v(s if s[0] != x0 else t)

    def T(y: float) -> float:
        m = np.array([x0, y])
        return float(np.hypot(*(m - s))) / v(s) + float(np.hypot(*(t - m))) / v(t)

    lo, hi = min(s[1], t[1]), max(s[1], t[1])
    for _ in range(200):
        a, b = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        if T(a) < T(b):
            hi = b
        else:
            lo = a
    y = 0.5 * (lo + hi)
    return np.array([s, [x0, y], t]), T(y)


def travel_time(path: Any, speed: Callable[[float, float], float], *, piece: float = 0.02) -> float:
    """Travel time along a polyline (k, 2) with the speed field
    ``speed(x, y)`` (e.g. :class:`sfanav.sim.VelocityRegions`), integrated
    in pieces of ``piece`` m (midpoint rule)."""
    P = np.asarray(path, float).reshape(-1, 2)
    total = 0.0
    for a, b in zip(P[:-1], P[1:]):
        L = float(np.hypot(*(b - a)))
        if L <= 0:
            continue
        k = max(1, int(np.ceil(L / piece)))
        for i in range(k):
            m = a + (i + 0.5) / k * (b - a)
            total += (L / k) / float(speed(float(m[0]), float(m[1])))
    return total
