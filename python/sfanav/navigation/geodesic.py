""":class:`GeodesicField`: shortest-path distances through the space an
exploration run covered (a grid of cells near its path), so that a robot can
go round obstacles it never bumped into."""

from __future__ import annotations

from typing import Any

import numpy as np

from .cost import SlowFeatureCost, as_vector2


def run_positions(positions: Any) -> np.ndarray:
    P = np.asarray(positions, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or len(P) < 2:
        raise ValueError(f"positions must be (N >= 2, 2) metres, got shape {P.shape}")
    if not np.isfinite(P).all():
        raise ValueError("positions contain NaN or inf")
    return P


def thin_run(P: np.ndarray, thin: float) -> tuple[np.ndarray, np.ndarray]:
    """One node per occupied cell of ``thin`` metres (the first frame in it):
    (node positions (n, 2), each frame's node (N,))."""
    ij = np.floor((P - P.min(axis=0)) / thin).astype(np.int64)
    _, first, node = np.unique(ij, axis=0, return_index=True, return_inverse=True)
    return P[first], node.ravel()


class GeodesicField:
    """Shortest-path distances through the space an exploration run covered
    (beyond the thesis; docs/navigation.md).

    The thesis expects slow features to "flow" around obstacles because the
    robot's temporal distance between the two sides of an obstacle is
    large (7.1). This makes that distance explicit. The run's positions
    (N, 2) in metres (ground truth in the simulator, or the metric map a
    robot learned from odometry, :mod:`sfanav.odometry.metric_learning`) mark the space known
    to be free: the cells of a grid of ``thin`` metres within ``radius / 2``
    of the run's path (its positions and, with ``temporal``, the straight
    pieces between consecutive ones up to ``5 * radius`` long: the robot
    drove there), so gaps of up to ``radius`` between the run's lines are
    bridged. Distances are
    shortest paths between free cells, 16-connected (straight, diagonal and
    knight moves, the cells a move passes over free too, so paths in open
    ground are nearly straight; docs/navigation.md compares this with a
    graph of the run's frames). An obstacle
    the robot kept clear of by at least its radius on each side (more than
    ``radius / 2``) leaves blocked cells along it, so paths go round it. A
    place's cost to a target is the smallest, over the place's
    ``neighbours`` nearest free cells, of that cell's distance plus the
    straight offset to it (and the target's own offset to its cell); places
    the run's free space does not connect to the target cost the largest
    finite distance plus their straight distance.

    ``GeodesicField(run_xy).cost`` is a ``cost=`` for :class:`Navigator`
    on :class:`MetricFeatures` (``n_outputs=2``)."""

    _MOVES = ((0, 1, ()), (1, 0, ()), (1, 1, ((0, 1), (1, 0))), (1, -1, ((0, -1), (1, 0))),
              (1, 2, ((0, 1), (1, 1))), (2, 1, ((1, 0), (1, 1))), (2, -1, ((1, 0), (1, -1))),
              (1, -2, ((0, -1), (1, -1))))

    def __init__(self, positions: Any, *, radius: float = 0.5, thin: float = 0.1, temporal: bool = True,
                 neighbours: int = 8) -> None:
        from scipy.sparse import coo_matrix
        from scipy.spatial import cKDTree

        P = run_positions(positions)
        for name, v in (("radius", radius), ("thin", thin)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of metres, got {v}")
        if isinstance(neighbours, bool) or int(neighbours) != neighbours or int(neighbours) < 1:
            raise ValueError(f"neighbours must be a positive integer, got {neighbours!r}")
        self.radius, self.thin = float(radius), float(thin)
        if self.radius < 1.5 * self.thin:
            raise ValueError(f"radius ({radius} m) must be at least 1.5 x the cell size thin ({thin} m), "
                             "or the run's own cells may not count as covered")
        self.neighbours = int(neighbours)
        self.centres, _ = thin_run(P, self.thin)  # the run's places (for visible())
        self.tree = cKDTree(self.centres)
        path = P
        if temporal:
            seg = np.diff(P, axis=0)
            step = np.hypot(*seg.T)
            keep = step <= 5.0 * self.radius  # longer jumps join separate runs, not a drive
            seg, start = seg[keep], P[:-1][keep]
            k = np.maximum(1, np.ceil(step[keep] / (0.5 * self.thin)).astype(int))
            idx = np.repeat(np.arange(len(seg)), k)
            frac = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k, k)
            path = np.vstack([start[idx] + frac[:, None] * seg[idx], P])
        lo = P.min(axis=0) - self.radius
        shape = (np.ceil((P.max(axis=0) + self.radius - lo) / self.thin).astype(int) + 1)[::-1]  # (ny, nx)
        if int(shape[0]) * int(shape[1]) > 4_000_000:
            raise ValueError(f"a grid of {shape[1]} x {shape[0]} cells of {self.thin} m is too large: "
                             "the run spans too far for this cell size")
        ny, nx = int(shape[0]), int(shape[1])
        gy, gx = np.mgrid[0:ny, 0:nx]
        cell_xy = np.column_stack([lo[0] + gx.ravel() * self.thin, lo[1] + gy.ravel() * self.thin])
        near = cKDTree(path).query(cell_xy, distance_upper_bound=self.radius / 2)[0]
        free = np.isfinite(near).reshape(ny, nx)
        index = np.full((ny, nx), -1, dtype=np.int64)
        index[free] = np.arange(int(free.sum()))
        self.cells = cell_xy[free.ravel()]
        self._cell_tree = cKDTree(self.cells)
        rows, cols, lens = [], [], []
        for di, dj, over in self._MOVES:
            i0, i1 = max(0, -di), ny - max(0, di)
            j0, j1 = max(0, -dj), nx - max(0, dj)
            ok = free[i0:i1, j0:j1] & free[i0 + di : i1 + di, j0 + dj : j1 + dj]
            for oi, oj in over:
                ok &= free[i0 + oi : i1 + oi, j0 + oj : j1 + oj]
            a = index[i0:i1, j0:j1][ok]
            b = index[i0 + di : i1 + di, j0 + dj : j1 + dj][ok]
            rows.append(a)
            cols.append(b)
            lens.append(np.full(len(a), self.thin * float(np.hypot(di, dj))))
        r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(lens)
        n = len(self.cells)
        self.graph = coo_matrix((np.r_[w, w], (np.r_[r, c], np.r_[c, r])), shape=(n, n)).tocsr()
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def n_nodes(self) -> int:
        """Free cells (the graph's nodes)."""
        return len(self.cells)

    def _source(self, target: Any) -> tuple[int, np.ndarray]:
        t = as_vector2(target, "target")
        k = int(self._cell_tree.query(t)[1])
        if k not in self._cache:
            from scipy.sparse.csgraph import dijkstra

            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[k] = dijkstra(self.graph, directed=False, indices=k, return_predecessors=True)
        return k, t

    def distances_from(self, target: Any) -> np.ndarray:
        """Shortest-path distance (m) from the target to every free cell
        (:attr:`cells`)."""
        k, t = self._source(target)
        D = self._cache[k][0].copy()
        finite = np.isfinite(D)
        D[~finite] = (D[finite].max() if finite.any() else 0.0) + np.hypot(*(self.cells[~finite] - t).T)
        return D + float(np.hypot(*(self.cells[k] - t)))

    def evaluate(self, D: np.ndarray, xy: Any) -> np.ndarray:
        """Geodesic distances of places ``xy`` (..., 2) given the cell
        distances ``D`` (from :meth:`distances_from`): the minimum over the
        ``neighbours`` nearest free cells of cell distance plus offset."""
        xy = np.asarray(xy, dtype=float)
        flat = xy.reshape(-1, 2)
        k = min(self.neighbours, self.n_nodes)
        d, i = self._cell_tree.query(flat, k=k)
        d, i = np.asarray(d).reshape(len(flat), k), np.asarray(i).reshape(len(flat), k)
        return (D[i] + d).min(axis=1).reshape(xy.shape[:-1])

    def visible(self, a: Any, b: Any, clearance: float | None = None) -> bool:
        """Whether the straight segment from ``a`` to ``b`` stays within
        ``clearance`` metres (default ``0.6 * radius``) of the run's
        positions everywhere (sampled every 0.1 m): known free space."""
        a, b = as_vector2(a, "a"), as_vector2(b, "b")
        c = 0.6 * self.radius if clearance is None else float(clearance)
        n = max(2, int(np.ceil(np.hypot(*(b - a)) / 0.1)) + 1)
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        return bool((self.tree.query(pts)[0] <= c).all())

    def crosses_wall(self, a: Any, b: Any, target: Any, jump: float = 3.0) -> bool:
        """Whether the straight segment from ``a`` to ``b`` passes between
        places the run connects only the long way round: the geodesic
        distance to ``target``, sampled every 0.1 m along the segment,
        jumps by more than ``jump`` metres between neighbouring samples (a
        wall the run never crossed). Unlike :meth:`visible`, gaps in the
        run's coverage of open ground do not count."""
        a, b = as_vector2(a, "a"), as_vector2(b, "b")
        if not (np.isfinite(jump) and jump > 0):
            raise ValueError(f"jump must be a positive number of metres, got {jump}")
        n = max(2, int(np.ceil(np.hypot(*(b - a)) / 0.1)) + 1)
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        g = self.evaluate(self.distances_from(target), pts)
        return bool(np.abs(np.diff(g)).max() > jump)

    def waypoint(self, xy: Any, target: Any, lookahead: float = 3.0, *, jump: float | None = None) -> np.ndarray:
        """Where to head from ``xy`` (2,) towards ``target``: the farthest
        point of the shortest path within ``lookahead`` metres (path length)
        that ``xy`` sees in a straight line through known free space
        (:meth:`visible`; with ``jump``: no :meth:`crosses_wall` on the way;
        the path's first cell if none); the target itself when it is that
        near, visible, or unreachable."""
        x = as_vector2(xy, "xy")
        k, t = self._source(target)
        pred = self._cache[k][1]
        i = int(self._cell_tree.query(x)[1])
        travelled, cur = 0.0, x
        path: list[np.ndarray] = []
        for _ in range(self.n_nodes):
            j = int(pred[i])
            if j < 0:  # the target's cell (or unreachable)
                path.append(t)
                break
            nxt = self.cells[j]
            travelled += float(np.hypot(*(nxt - cur)))
            if travelled > lookahead:
                break
            path.append(nxt)
            cur, i = nxt, j
        if not path:
            return self.cells[int(pred[i])].copy() if pred[i] >= 0 else t
        for q in reversed(path):
            if self.visible(x, q) if jump is None else not self.crosses_wall(x, q, t, jump):
                return np.array(q, float)
        return np.array(path[0], float)

    def __call__(self, xy: Any, target: Any) -> np.ndarray:
        """Geodesic distance (m) of places ``xy`` (..., 2) to ``target``."""
        return _GeodesicCost(self, target)(xy)

    def cost(self, target_features: Any, n_outputs: int = 2, weights: Any = None) -> "SlowFeatureCost":
        """The cost of a run to a target (its estimated position, from
        :class:`MetricFeatures`); the signature of :class:`Navigator`'s ``cost``."""
        if int(n_outputs) != 2:
            raise ValueError(f"a geodesic cost works on metric positions: n_outputs must be 2, got {n_outputs}")
        if weights is not None:
            raise ValueError("a geodesic cost takes no per-output weights")
        return _GeodesicCost(self, np.asarray(target_features, float).ravel()[:2])


class _GeodesicCost(SlowFeatureCost):
    def __init__(self, field: GeodesicField, target: Any) -> None:
        super().__init__(target, 2)
        self.field = field
        self._D = field.distances_from(self.target)

    def __call__(self, features: Any) -> np.ndarray:
        f = np.asarray(features, dtype=float)
        if f.shape[-1] < 2:
            raise ValueError(f"features have {f.shape[-1]} outputs, the geodesic cost needs x, y")
        return self.field.evaluate(self._D, f[..., :2])
