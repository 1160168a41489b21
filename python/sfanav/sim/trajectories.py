"""Trajectories of the thesis's experiments.

Every generator returns a :class:`Trajectory`: robot poses (N, 3) = (x m,
y m, heading rad), timestamps (N,) in seconds and optional per-frame columns
(``extra``, e.g. the line-segment id). The free area is the rectangle of
``area = (width, height)`` metres centred on the origin; generators that take
a ``world`` also keep clear of its obstacles.

* :func:`grid`: grid-like exploration with crossings: lanes along x, then
  lanes along y, joined by turns on the spot or large-radius U-turns
  (thesis 5.1.2, 5.2, 6.2.1).
* :func:`grid_points`: a regular grid of positions walked in serpentine
  order (the simulator experiment of 5.1.1).
* :func:`random_lines`: straight lines at constant speed with a new random
  direction at the border or an obstacle (7.1.2); with ``speed`` a
  :class:`VelocityRegions`, the velocity-region variant (7.2.2).
* :func:`border_loop`: a closed border-wire loop (6.2.2).
* :func:`line_segments`: straight segments of random orientation and a
  minimum length, for unsupervised metric learning (5.3.1).
* :func:`random_walk`: a smooth random test walk.
* :func:`detour`: a trajectory (e.g. a grid) led around a world's obstacles
  (the realistic gardens, with objects inside the area).
* :func:`jitter`: a trajectory as a robot driving it again deviates from
  it (a border-wire mower's few centimetres and degrees).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from .robot import check_poses, wrap_angle


@dataclass
class Trajectory:
    """Robot poses over time.

    Attributes
    ----------
    poses : ndarray (N, 3)
        x (m), y (m), heading (rad).
    times : ndarray (N,)
        Seconds, non-decreasing.
    extra : dict of str to ndarray (N,)
        Per-frame extra columns (e.g. ``"segment"``).
    """

    poses: np.ndarray
    times: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.poses = check_poses(self.poses)
        self.times = np.asarray(self.times, float)
        if self.times.shape != (len(self.poses),):
            raise ValueError(f"times must have shape ({len(self.poses)},), got {self.times.shape}")
        if len(self.times) > 1 and np.any(np.diff(self.times) < 0):
            raise ValueError("trajectory times must be non-decreasing")
        for k, v in self.extra.items():
            v = np.asarray(v)
            if v.shape != (len(self.poses),):
                raise ValueError(f"extra column {k!r} must have shape ({len(self.poses)},), got {v.shape}")
            self.extra[k] = v

    def __len__(self) -> int:
        return len(self.poses)

    def __getitem__(self, idx: Any) -> "Trajectory":
        return Trajectory(self.poses[idx], self.times[idx], {k: v[idx] for k, v in self.extra.items()})

    @property
    def length(self) -> float:
        """Path length (m)."""
        return float(np.hypot(*np.diff(self.poses[:, :2], axis=0).T).sum()) if len(self) > 1 else 0.0


def _area(area: Any) -> tuple[float, float]:
    try:
        w, h = (float(a) for a in area)
    except (TypeError, ValueError):
        raise ValueError(f"area must be (width, height) in metres, got {area!r}") from None
    if not (w > 0 and h > 0):
        raise ValueError(f"area must be two positive sizes in metres, got {area!r}")
    return w, h


def _positive(v: Any, name: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not v > 0:
        raise ValueError(f"{name} must be a positive number, got {v!r}")
    return float(v)


def _count(v: Any, name: str, lo: int = 1) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
    return int(v)


class _Path:
    """Builds a trajectory from straight runs, arcs and turns on the spot,
    sampled every ``step`` metres or ``turn_step`` radians."""

    def __init__(self, pose: Sequence[float], step: float, speed: float, turn_step: float, turn_rate: float):
        self.pose = np.array(pose, float)
        self.step, self.speed = step, speed
        self.turn_step, self.turn_rate = turn_step, turn_rate
        self.poses = [self.pose.copy()]
        self.times = [0.0]
        self.labels = [-1]

    def _add(self, pose: np.ndarray, dt: float, label: int) -> None:
        self.pose = pose
        self.poses.append(pose.copy())
        self.times.append(self.times[-1] + dt)
        self.labels.append(label)

    def straight(self, length: float, label: int = -1) -> None:
        if length <= 1e-9:
            return
        n = max(1, int(np.ceil(length / self.step - 1e-9)))
        ds = length / n
        x, y, th = self.pose
        for i in range(1, n + 1):
            self._add(np.array([x + i * ds * np.cos(th), y + i * ds * np.sin(th), th]), ds / self.speed, label)

    def turn(self, angle: float, label: int = -1) -> None:
        angle = float(wrap_angle(angle))
        if abs(angle) <= 1e-9:
            return
        n = max(1, int(np.ceil(abs(angle) / self.turn_step)))
        x, y, th = self.pose
        for i in range(1, n + 1):
            self._add(np.array([x, y, th + angle * i / n]), abs(angle) / n / self.turn_rate, label)

    def face(self, heading: float, label: int = -1) -> None:
        self.turn(heading - self.pose[2], label)

    def arc(self, radius: float, angle: float, label: int = -1) -> None:
        """Arc of ``radius`` m turning by ``angle`` rad (positive: left)."""
        length = abs(angle) * radius
        n = max(1, int(np.ceil(length / self.step - 1e-9)))
        x, y, th = self.pose
        sgn = np.sign(angle)
        cx, cy = x - sgn * radius * np.sin(th), y + sgn * radius * np.cos(th)
        for i in range(1, n + 1):
            a = th + angle * i / n
            self._add(np.array([cx + sgn * radius * np.sin(a), cy - sgn * radius * np.cos(a), a]),
                      length / n / self.speed, label)

    def goto(self, x: float, y: float, label: int = -1) -> None:
        dx, dy = x - self.pose[0], y - self.pose[1]
        dist = float(np.hypot(dx, dy))
        if dist > 1e-9:
            self.face(np.arctan2(dy, dx), label)
            self.straight(dist, label)

    def result(self, label_name: str | None = None) -> Trajectory:
        P = np.array(self.poses)
        P[:, 2] = wrap_angle(P[:, 2])
        extra = {label_name: np.array(self.labels, np.int64)} if label_name else {}
        return Trajectory(P, np.array(self.times), extra)


def grid(area: Sequence[float], spacing: float = 1.0, step: float = 0.2, *, margin: float = 0.5,
         turn: str = "spot", crossings: bool = True, speed: float = 0.4, turn_rate: float = 0.8,
         turn_step: float = np.radians(10)) -> Trajectory:
    """Grid-like exploration: serpentine lanes along x, then (``crossings``)
    along y, so the lanes cross.

    Parameters
    ----------
    area : (width, height), m
    spacing : float
        Distance between lanes (m).
    step : float
        Distance between frames (m).
    margin : float
        Distance kept from the area border (m).
    turn : ``"spot"`` or ``"arc"``
        Between lanes: turn 90 degrees on the spot, drive ``spacing``, turn
        again (frames every ``turn_step`` rad); or a half circle of radius
        ``spacing / 2`` (a large-radius turn).
    speed, turn_rate : float
        m/s and rad/s, for the timestamps.
    """
    w, h = _area(area)
    spacing, step = _positive(spacing, "spacing"), _positive(step, "step")
    if turn not in ("spot", "arc"):
        raise ValueError(f"turn must be 'spot' or 'arc', got {turn!r}")
    hx, hy = w / 2 - margin, h / 2 - margin
    if hx <= 0 or hy <= 0:
        raise ValueError(f"margin {margin} m leaves no room in area {w} x {h} m")
    path = _Path((-hx, -hy, 0.0), step, _positive(speed, "speed"), _positive(turn_step, "turn_step"),
                 _positive(turn_rate, "turn_rate"))

    def lanes(along: int, lo: float, hi: float, count_lo: float, count_hi: float) -> None:
        n = max(1, int(np.floor((count_hi - count_lo) / spacing + 1e-9)) + 1)
        levels = np.linspace(count_lo, count_lo + (n - 1) * spacing, n)
        if path.pose[1 - along] > 0:
            levels = -levels
        for k, lev in enumerate(levels):
            cur = path.pose[along]
            target = hi if abs(cur - lo) < abs(cur - hi) else lo
            if k == 0:
                goal = np.array(path.pose[:2])
                goal[1 - along] = lev
                path.goto(*goal)
                heading = (0.0 if target > cur else np.pi) if along == 0 else (np.pi / 2 if target > cur else -np.pi / 2)
                path.face(heading)
            path.straight(abs(target - path.pose[along]))
            if k + 1 < n:
                nxt = levels[k + 1]
                side = np.sign(nxt - lev)
                hd = path.pose[2]
                # left turn if the next lane lies to the robot's left
                left_dir = np.array([-np.sin(hd), np.cos(hd)])
                to_next = np.zeros(2)
                to_next[1 - along] = side
                sgn = 1.0 if left_dir @ to_next > 0 else -1.0
                if turn == "arc":
                    path.arc(abs(nxt - lev) / 2, sgn * np.pi)
                else:
                    path.turn(sgn * np.pi / 2)
                    path.straight(abs(nxt - lev))
                    path.turn(sgn * np.pi / 2)

    # U-turn arcs bulge half a spacing beyond the lane ends: keep them inside the margin
    ex = spacing / 2 if turn == "arc" else 0.0
    if hx <= ex or hy <= ex:
        raise ValueError(f"spacing {spacing} m is too large for arc turns in area {w} x {h} m")
    lanes(0, -hx + ex, hx - ex, -hy, hy)
    if crossings:
        lanes(1, -hy + ex, hy - ex, -hx, hx)
    return path.result()


def grid_points(area: Sequence[float], nx: int, ny: int, *, margin: float = 0.0, dt: float = 1.0,
                offset: tuple[float, float] = (0.0, 0.0)) -> Trajectory:
    """A regular ``nx`` x ``ny`` grid of positions covering the area (minus
    ``margin``), visited row by row in serpentine order (thesis 5.1.1: images
    rendered on a grid and arranged into a continuous walk). Headings point
    along the walk; ``dt`` seconds per frame."""
    w, h = _area(area)
    nx, ny = _count(nx, "nx"), _count(ny, "ny")
    xs = np.linspace(-w / 2 + margin, w / 2 - margin, nx) + offset[0] if nx > 1 else np.array([offset[0]])
    ys = np.linspace(-h / 2 + margin, h / 2 - margin, ny) + offset[1] if ny > 1 else np.array([offset[1]])
    pts = []
    for j, y in enumerate(ys):
        row = xs if j % 2 == 0 else xs[::-1]
        pts.extend((x, y) for x in row)
    pts = np.array(pts)
    d = np.diff(pts, axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0]) if len(d) else np.zeros(0)
    heading = np.append(heading, heading[-1] if len(heading) else 0.0)
    poses = np.column_stack([pts, heading])
    return Trajectory(poses, np.arange(len(poses)) * _positive(dt, "dt"))


class VelocityRegions:
    """Speed factor of a position (thesis 7.2.2): the robot moves ``factor``
    times farther per step in the fast region than in the slow one."""

    def __init__(self, slow: Callable[[float, float], bool], factor: float = 3.0, description: str = ""):
        self.slow = slow
        self.factor = _positive(factor, "factor")
        self.description = description

    def __call__(self, x: float, y: float) -> float:
        return 1.0 if self.slow(x, y) else self.factor

    @classmethod
    def half_plane(cls, x0: float = 0.0, slow_side: str = "left", factor: float = 3.0) -> "VelocityRegions":
        """Slow for ``x < x0`` (``slow_side="left"``) or ``x > x0`` (``"right"``)."""
        if slow_side not in ("left", "right"):
            raise ValueError(f"slow_side must be 'left' or 'right', got {slow_side!r}")
        sgn = -1.0 if slow_side == "left" else 1.0
        return cls(lambda x, y: sgn * (x - x0) > 0, factor, f"slow where x {'<' if sgn < 0 else '>'} {x0} m")

    @classmethod
    def disc(cls, radius: float, center: tuple[float, float] = (0.0, 0.0), factor: float = 3.0) -> "VelocityRegions":
        """Slow inside a disc of ``radius`` m around ``center``."""
        r = _positive(radius, "radius")
        cx, cy = center
        return cls(lambda x, y: (x - cx) ** 2 + (y - cy) ** 2 < r * r, factor,
                   f"slow inside the disc of radius {r} m at ({cx}, {cy})")


def _free_fn(area: tuple[float, float], margin: float, world: Any) -> Callable[[float, float], bool]:
    w, h = area
    if world is not None:
        return lambda x, y: bool(world.free(x, y, margin))
    return lambda x, y: abs(x) <= w / 2 - margin and abs(y) <= h / 2 - margin


def _start(rng: np.random.Generator, area: tuple[float, float], free: Callable[[float, float], bool]) -> np.ndarray:
    w, h = area
    for _ in range(10000):
        x, y = rng.uniform(-w / 2, w / 2), rng.uniform(-h / 2, h / 2)
        if free(x, y):
            return np.array([x, y])
    raise ValueError("found no free start position: the margin or the obstacles leave no room")


def random_lines(area: Sequence[float], n_frames: int, step: float = 0.2, *, margin: float = 0.5,
                 world: Any = None, speed: VelocityRegions | None = None, dt: float = 1.0,
                 rng: np.random.Generator | int | None = None) -> Trajectory:
    """Straight lines at constant speed; at the border or an obstacle a new
    random direction is drawn (thesis 7.1.2: 5000 frames, 0.2 per step).

    Parameters
    ----------
    area : (width, height), m
    n_frames : int
    step : float
        Distance per frame (m); in the fast region of ``speed``, ``factor``
        times more.
    margin : float
        Clearance from the border and obstacles (m), e.g. half the robot size.
    world : World, optional
        Obstacles to bounce off.
    speed : VelocityRegions, optional
        Velocity regions (7.2.2); the trajectory gets an ``extra`` column
        ``"speed_factor"``.
    dt : float
        Seconds per frame.
    """
    a = _area(area)
    n = _count(n_frames, "n_frames")
    step = _positive(step, "step")
    rng = np.random.default_rng(rng)
    free = _free_fn(a, margin, world)
    p = _start(rng, a, free)
    alpha = rng.uniform(-np.pi, np.pi)
    poses = np.empty((n, 3))
    factors = np.ones(n)
    for k in range(n):
        f = speed(p[0], p[1]) if speed is not None else 1.0
        factors[k] = f
        s = step * f
        for _ in range(2000):
            q = p + s * np.array([np.cos(alpha), np.sin(alpha)])
            if free(q[0], q[1]) and (world is None or bool(world.free((p[0] + q[0]) / 2, (p[1] + q[1]) / 2, margin))):
                break
            alpha = rng.uniform(-np.pi, np.pi)
        else:
            raise ValueError(f"stuck at ({p[0]:.2f}, {p[1]:.2f}): no free direction for a step of {s} m")
        poses[k] = (p[0], p[1], alpha)
        p = q
    extra = {"speed_factor": factors} if speed is not None else {}
    return Trajectory(poses, np.arange(n) * _positive(dt, "dt"), extra)


def border_loop(area: Sequence[float], n_frames: int | None = None, step: float = 0.2, *, margin: float = 1.0,
                corner_radius: float = 2.0, wobble: float = 0.3, speed: float = 0.4,
                rng: np.random.Generator | int | None = None) -> Trajectory:
    """A closed loop along a border wire: a rounded rectangle ``margin`` m
    inside the area, bent by a smooth random wobble of about ``wobble`` m,
    driven counter-clockwise; the last frame is one step before the start.

    Parameters
    ----------
    n_frames : int, optional
        Number of frames around the loop (thesis 6.2.2: 279); overrides ``step``.
    step : float
        Distance between frames (m) when ``n_frames`` is not given.
    speed : float
        m/s, for the timestamps.
    """
    w, h = _area(area)
    rng = np.random.default_rng(rng)
    hx, hy = w / 2 - margin, h / 2 - margin
    if hx <= 0 or hy <= 0:
        raise ValueError(f"margin {margin} m leaves no room in area {w} x {h} m")
    rc = min(float(corner_radius), hx, hy)
    # dense rounded rectangle
    pts = []
    for cx, cy, a0 in ((hx - rc, -hy + rc, -np.pi / 2), (hx - rc, hy - rc, 0.0),
                       (-hx + rc, hy - rc, np.pi / 2), (-hx + rc, -hy + rc, np.pi)):
        a = a0 + np.linspace(0, np.pi / 2, 50, endpoint=False)
        pts.append(np.column_stack([cx + rc * np.cos(a), cy + rc * np.sin(a)]))
        # the straight side after this corner
        end = np.array([cx + rc * np.cos(a0 + np.pi / 2), cy + rc * np.sin(a0 + np.pi / 2)])
        pts.append(end[None, :])
    dense = np.concatenate(pts)
    dense = _resample_closed(dense, 2000)
    if wobble > 0:
        k = np.arange(2000) / 2000
        off = np.zeros(2000)
        for f in range(2, 7):
            off += rng.standard_normal() * np.sin(2 * np.pi * f * k + rng.uniform(0, 2 * np.pi)) / f
        off *= wobble / max(np.abs(off).max(), 1e-9)
        tang = np.roll(dense, -1, axis=0) - np.roll(dense, 1, axis=0)
        nrm = np.column_stack([tang[:, 1], -tang[:, 0]]) / np.hypot(*tang.T)[:, None]  # outward for CCW
        dense = dense + off[:, None] * nrm
        dense[:, 0] = np.clip(dense[:, 0], -w / 2 + 0.1, w / 2 - 0.1)
        dense[:, 1] = np.clip(dense[:, 1], -h / 2 + 0.1, h / 2 - 0.1)
    seg = np.hypot(*np.diff(np.vstack([dense, dense[:1]]), axis=0).T)
    total = float(seg.sum())
    n = _count(n_frames, "n_frames", 3) if n_frames is not None else max(3, int(round(total / _positive(step, "step"))))
    pts = _resample_closed(dense, n)
    nxt = np.roll(pts, -1, axis=0) - np.roll(pts, 1, axis=0)
    heading = np.arctan2(nxt[:, 1], nxt[:, 0])
    times = np.arange(n) * (total / n) / _positive(speed, "speed")
    return Trajectory(np.column_stack([pts, heading]), times)


def _resample_closed(pts: np.ndarray, n: int) -> np.ndarray:
    closed = np.vstack([pts, pts[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    q = np.arange(n) * s[-1] / n
    return np.column_stack([np.interp(q, s, closed[:, 0]), np.interp(q, s, closed[:, 1])])


def line_segments(area: Sequence[float], n_lines: int = 10, min_length: float = 8.0, step: float = 0.2, *,
                  margin: float = 0.5, world: Any = None, transit: bool = True, speed: float = 0.4,
                  turn_rate: float = 0.8, turn_step: float = np.radians(10), through: bool = False,
                  rng: np.random.Generator | int | None = None) -> Trajectory:
    """Straight line segments of random orientation (thesis 5.3.1: 10 lines,
    at least 8 m long, sampled every 0.2 m).

    Start and end points lie in the area (and clear of obstacles) at least
    ``min_length`` apart: two random free points, or, with ``through``, the
    whole chord of the area (inside the margin) through a random free point
    in a random direction (longer lines: about 16 m on average in a 16x18 m
    area, which gives the thesis's ~860 points for 10 lines; two random
    points give about 11.5 m). The ``extra`` column ``"segment"`` gives each
    frame's segment (0 .. n_lines - 1) or -1 for the transit between
    segments (turn on the spot, drive to the next start, turn), which is
    left out when ``transit`` is False.
    """
    w, h = _area(area)
    n_lines = _count(n_lines, "n_lines")
    min_length = _positive(min_length, "min_length")
    rng = np.random.default_rng(rng)
    free = _free_fn((w, h), margin, world)
    if min_length > np.hypot(w - 2 * margin, h - 2 * margin):
        raise ValueError(f"min_length {min_length} m does not fit in area {w} x {h} m (margin {margin} m)")
    segs = []
    for _ in range(n_lines):
        for _ in range(10000):
            if through:
                a, b = _chord(rng, (w, h), margin, free)
            else:
                a, b = _start(rng, (w, h), free), _start(rng, (w, h), free)
            L = float(np.hypot(*(b - a)))
            if L >= min_length:
                ts = np.linspace(0, 1, max(2, int(L / 0.1)))
                if all(free(*(a + t * (b - a))) for t in ts):
                    segs.append((a, b))
                    break
        else:
            raise ValueError("found no segment of the minimum length clear of obstacles")
    a0, b0 = segs[0]
    path = _Path((a0[0], a0[1], float(np.arctan2(*(b0 - a0)[::-1]))), _positive(step, "step"),
                 _positive(speed, "speed"), _positive(turn_step, "turn_step"), _positive(turn_rate, "turn_rate"))
    path.labels[0] = 0
    for i, (a, b) in enumerate(segs):
        if i > 0:
            path.goto(a[0], a[1], -1)
            path.face(float(np.arctan2(b[1] - a[1], b[0] - a[0])), -1)
            path.labels[-1] = i  # the segment's first frame is its start point
        path.straight(float(np.hypot(*(b - a))), i)
    traj = path.result("segment")
    if not transit:
        traj = traj[traj.extra["segment"] >= 0]
    return traj


def _chord(rng: np.random.Generator, area: tuple[float, float], margin: float,
           free: Callable[[float, float], bool]) -> tuple[np.ndarray, np.ndarray]:
    """The chord of the area shrunk by ``margin`` through a random free point
    in a random direction (ends in driving order)."""
    w, h = area
    p = _start(rng, area, free)
    a = rng.uniform(0, 2 * np.pi)
    u = np.array([np.cos(a), np.sin(a)])
    half = (w / 2 - margin - 1e-6, h / 2 - margin - 1e-6)  # just inside, against rounding
    ts = [t for i in range(2) if abs(u[i]) > 1e-12 for t in ((half[i] - p[i]) / u[i], (-half[i] - p[i]) / u[i])]
    t_hi = min([t for t in ts if t >= 0], default=0.0)
    t_lo = max([t for t in ts if t <= 0], default=0.0)
    return p + t_lo * u, p + t_hi * u


def random_walk(area: Sequence[float], n_frames: int, step: float = 0.2, *, turn_sigma: float = 0.15,
                margin: float = 0.5, world: Any = None, dt: float = 0.5,
                rng: np.random.Generator | int | None = None) -> Trajectory:
    """A smooth random test walk: constant step, heading a random walk with
    ``turn_sigma`` rad per frame; at the border or an obstacle it turns
    away (new heading drawn around the reverse direction)."""
    a = _area(area)
    n = _count(n_frames, "n_frames")
    step = _positive(step, "step")
    rng = np.random.default_rng(rng)
    free = _free_fn(a, margin, world)
    p = _start(rng, a, free)
    th = rng.uniform(-np.pi, np.pi)
    poses = np.empty((n, 3))
    for k in range(n):
        th_new = th + turn_sigma * rng.standard_normal()
        for tries in range(2000):
            q = p + step * np.array([np.cos(th_new), np.sin(th_new)])
            if free(q[0], q[1]):
                break
            th_new = th + np.pi + rng.normal(0, 0.6 + tries * 0.01)
        else:
            raise ValueError(f"random walk stuck at ({p[0]:.2f}, {p[1]:.2f})")
        th = float(wrap_angle(th_new))
        poses[k] = (p[0], p[1], th)  # the heading it drives off with
        p = q
    return Trajectory(poses, np.arange(n) * _positive(dt, "dt"))


def detour(traj: Trajectory, world: Any, *, margin: float = 0.45, speed: float = 0.4,
           turn_rate: float = 0.8) -> Trajectory:
    """Leads a trajectory around a world's obstacles.

    Every stretch of consecutive poses within ``margin`` m of an obstacle is
    replaced by a detour: straight out to a circle around that obstacle
    (its parts' bounding circle plus ``margin``), along the circle on the
    side that stays in the area and clear of other obstacles, and back in,
    sampled at the trajectory's median step; headings follow the motion.
    A stretch no detour clears is dropped (the trajectory jumps). Times are
    recomputed from ``speed`` (m/s) and ``turn_rate`` (rad/s); extra
    columns are dropped. A trajectory that touches no obstacle comes back
    unchanged."""
    from .primitives import BLOCK_HEIGHT

    P = traj.poses
    blocked = np.asarray(world.collides(P[:, 0], P[:, 1], margin), bool)
    if not blocked.any():
        return traj
    steps = np.hypot(*np.diff(P[:, :2], axis=0).T)
    step = float(np.median(steps[steps > 1e-9])) if np.any(steps > 1e-9) else 0.2
    obstacles = world.obstacles
    w, h = world.area

    def clear(pts: np.ndarray) -> bool:
        return bool(np.all(world.free(pts[:, 0], pts[:, 1], margin * 0.9)))

    out: list[np.ndarray] = []
    i, n = 0, len(P)
    while i < n:
        if not blocked[i]:
            out.append(P[i, :2])
            i += 1
            continue
        j = i
        while j < n and blocked[j]:
            j += 1
        if i == 0 or j == n:
            i = j
            continue
        a, b = P[i - 1, :2], P[j, :2]
        mid = P[(i + j) // 2, :2]
        o = min(obstacles, key=lambda ob: min(float(np.hypot(mid[0] - p.x, mid[1] - p.y)) - p.bound_radius
                                              for p in ob.parts))
        c = np.array([o.x, o.y])
        R = max(float(np.hypot(p.x - o.x, p.y - o.y)) + p.bound_radius for p in o.parts
                if p.z0 < BLOCK_HEIGHT) + margin + 0.05
        a0 = np.arctan2(*(a - c)[::-1])
        a1 = np.arctan2(*(b - c)[::-1])
        best = None
        for sgn in (1.0, -1.0):
            span = float(wrap_angle(sgn * (a1 - a0))) % (2 * np.pi)
            k = max(2, int(np.ceil(span * R / step)))
            ang = a0 + sgn * span * np.linspace(0, 1, k + 1)
            arc = c + R * np.stack([np.cos(ang), np.sin(ang)], axis=1)
            pts = np.concatenate([_line(a, arc[0], step), arc, _line(arc[-1], b, step)])
            if clear(pts) and (best is None or len(pts) < len(best)):
                best = pts
        if best is not None:
            out.extend(best)
        i = j
    pts = np.asarray(out)
    keep = np.ones(len(pts), bool)
    keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-9
    # repeated positions (turns on the spot) are dropped: headings follow the motion
    pts = pts[keep]
    d = np.diff(pts, axis=0)
    head = np.arctan2(d[:, 1], d[:, 0])
    head = np.append(head, head[-1] if len(head) else 0.0)
    poses = np.column_stack([pts, head])
    dist = np.hypot(*np.diff(pts, axis=0).T)
    dth = np.abs(wrap_angle(np.diff(head)))
    times = np.concatenate([[0.0], np.cumsum(np.maximum(dist / speed, dth / turn_rate))])
    return Trajectory(poses, times)


def _line(a: np.ndarray, b: np.ndarray, step: float) -> np.ndarray:
    k = int(np.ceil(float(np.hypot(*(b - a))) / step))
    if k <= 1:
        return np.empty((0, 2))
    return a + (b - a) * np.linspace(0, 1, k + 1)[1:-1, None]


def jitter(traj: Trajectory, lateral: float = 0.05, heading_deg: float = 2.0, *, length: float = 2.0,
           rng: np.random.Generator | int | None = None) -> Trajectory:
    """The trajectory as a robot driving it again would: every pose moved
    sideways by a smooth random offset and turned by a smooth random heading
    error, independently drawn.

    Both are Gaussian-smoothed white noise along the path length with a
    correlation length of about ``length`` metres, scaled so that their
    largest magnitude over the run is exactly ``lateral`` metres and
    ``heading_deg`` degrees. Sideways is the pose's left (heading + 90 deg).
    Times and extra columns are kept; poses stay where they are when the
    path has no length (offsets are then constant).

    Parameters
    ----------
    traj : Trajectory
    lateral : float
        Largest sideways offset (m), >= 0.
    heading_deg : float
        Largest heading error (degrees), >= 0.
    length : float
        Correlation length along the path (m), > 0.
    rng : numpy Generator or int seed

    Returns
    -------
    Trajectory of the same length.

    Raises
    ------
    ValueError
        A negative or non-finite ``lateral`` or ``heading_deg``, a
        non-positive ``length``.

    Examples
    --------
    >>> loop = border_loop((15, 15), 279, rng=0)
    >>> again = jitter(loop, 0.05, 2.0, rng=1)
    >>> bool(np.hypot(*(again.poses[:, :2] - loop.poses[:, :2]).T).max() <= 0.05 + 1e-12)
    True
    """
    for name, v in (("lateral", lateral), ("heading_deg", heading_deg)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not (
                np.isfinite(v) and v >= 0):
            raise ValueError(f"jitter {name} must be a finite number >= 0, got {v!r}")
    length = _positive(length, "jitter length")
    rng = np.random.default_rng(rng)
    P = traj.poses
    if not len(P):
        return traj[:]
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(P[:, :2], axis=0).T))])
    off = float(lateral) * _smooth_noise(s, length, rng)
    dth = np.radians(float(heading_deg)) * _smooth_noise(s, length, rng)
    out = P.copy()
    out[:, 0] -= off * np.sin(P[:, 2])
    out[:, 1] += off * np.cos(P[:, 2])
    out[:, 2] = P[:, 2] + dth  # the input's heading convention (wrapped or continuous) is kept
    return Trajectory(out, traj.times.copy(), {k: v.copy() for k, v in traj.extra.items()})


def _smooth_noise(s: np.ndarray, length: float, rng: np.random.Generator) -> np.ndarray:
    """Smooth random values at path positions ``s`` (m, non-decreasing from
    0): white noise on knots every ``length / 4`` m, smoothed by a Gaussian
    of ``length`` m, interpolated; scaled to a largest magnitude of 1."""
    knot = length / 4
    pad = 12  # three standard deviations of the kernel, in knots
    m = int(np.ceil(s[-1] / knot)) + 2
    kernel = np.exp(-0.5 * (np.arange(-pad, pad + 1) / 4.0) ** 2)
    smooth = np.convolve(rng.standard_normal(m + 2 * pad), kernel, mode="valid")
    v = np.interp(s / knot, np.arange(m), smooth)
    peak = float(np.abs(v).max())
    return v / peak if peak > 0 else v
