"""Surveys as robot lawn mowers drive them.

Every generator returns a :class:`~sfanav.sim.trajectories.Trajectory` of
frames ``spacing`` metres apart along the driven path (measured along the
path, turns included), in the area ``(width, height)`` centred on the
origin, ``margin`` metres inside its border:

* :func:`serpentine`: parallel lanes ``lane_spacing`` apart joined by
  U-turns (half circles of radius ``lane_spacing / 2``);
* :func:`perimeter_serpentine`: one lap along the border, then a serpentine
  one lane spacing inside it;
* :func:`spiral`: rectangular laps from the border inwards, each
  ``lane_spacing`` inside the last, with rounded corners;
* :func:`crossing`: a serpentine along x, then one along y (the lanes cross);
* :func:`random_survey`: a random (bounce) mower: straight lines, a new
  random direction at the border or an obstacle.

The robot faces its direction of travel: a frame's heading is the path's
tangent there (``heading="travel"``, the default); ``heading="random"``
gives every frame a uniformly random heading instead (panoramas taken at
random headings, as the earlier presets' test grids). The corners of the
geometric patterns are circular arcs (radius ``turn_radius``, at most half
the shorter of the two legs), so the heading changes smoothly along them.
With a ``world`` the geometric patterns are led around its obstacles
(:func:`~sfanav.sim.trajectories.detour`, which drops the ``lane`` and
``lap`` columns) and the random survey bounces off them.

:func:`survey` builds any of them by name (:data:`SURVEY_PATTERNS`).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from .._checks import as_pair, check_int, check_nonneg_float, check_positive_float
from . import trajectories as T
from .robot import wrap_angle

SURVEY_PATTERNS = ("serpentine", "perimeter-serpentine", "spiral", "crossing", "random")
"""The names :func:`survey` builds."""


HEADINGS = ("travel", "random")
"""Heading conventions: the direction of travel, or uniformly random per frame."""


def _inner(area: Any, margin: Any) -> tuple[float, float]:
    """Half sizes (hx, hy) of the area shrunk by ``margin``."""
    w, h = as_pair(area, "area")
    if not (w > 0 and h > 0):
        raise ValueError(f"area must be two positive sizes (width, height) in metres, got {area!r}")
    margin = check_nonneg_float(margin, "margin")
    hx, hy = w / 2 - margin, h / 2 - margin
    if hx <= 0 or hy <= 0:
        raise ValueError(f"margin {margin} m leaves no room in area {w} x {h} m")
    return hx, hy


def _levels(half: float, lane_spacing: float) -> np.ndarray:
    """Lane positions ``lane_spacing`` apart, centred in [-half, half]."""
    n = int(np.floor(2 * half / lane_spacing + 1e-9)) + 1
    if n < 2:
        raise ValueError(f"lane_spacing {lane_spacing} m leaves room for one lane only "
                         f"(the lanes span {2 * half:g} m inside the margin)")
    off = (2 * half - (n - 1) * lane_spacing) / 2
    return -half + off + lane_spacing * np.arange(n)


def _serpentine_vertices(hx: float, hy: float, lane_spacing: float, along: str = "x",
                         first: int = 0) -> tuple[list[tuple[float, float]], list[int]]:
    """Corners of a serpentine (start at the low end of the first lane) and
    the lane of each leg (``first`` + lane index on lanes, -1 on the
    connectors between lanes)."""
    if along == "x":
        levels = _levels(hy, lane_spacing)
        pts = []
        for k, lev in enumerate(levels):
            ends = (-hx, hx) if k % 2 == 0 else (hx, -hx)
            pts += [(ends[0], lev), (ends[1], lev)]
    else:
        levels = _levels(hx, lane_spacing)
        pts = []
        for k, lev in enumerate(levels):
            ends = (-hy, hy) if k % 2 == 0 else (hy, -hy)
            pts += [(lev, ends[0]), (lev, ends[1])]
    labels = [first + i // 2 if i % 2 == 0 else -1 for i in range(len(pts) - 1)]
    return pts, labels


def _fillet(vertices: Sequence[tuple[float, float]], labels: Sequence[int], radius: float,
            arc_step: float = np.radians(2.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A polyline with every corner replaced by a circular arc tangent to
    both legs (radius ``radius``, smaller where a leg is shorter than twice
    the arc's tangent length). Returns dense points (M, 2), their headings
    (M,) (the exact tangent, continuous) and the label of the leg or arc
    that each point starts (M,): a leg's label, -1 on arcs."""
    V = np.asarray(vertices, float)
    keep = np.ones(len(V), bool)
    keep[1:] = np.hypot(*np.diff(V, axis=0).T) > 1e-9
    V, lab = V[keep], [lb for lb, k in zip(labels, keep[1:]) if k]
    d = np.diff(V, axis=0)
    L = np.hypot(d[:, 0], d[:, 1])
    ang = np.arctan2(d[:, 1], d[:, 0])
    pts: list[np.ndarray] = [V[0]]
    head: list[float] = [float(ang[0])]
    labs: list[int] = [lab[0]]
    for i in range(1, len(V) - 1):
        turn = float(wrap_angle(ang[i] - ang[i - 1]))
        if abs(turn) < 1e-9:
            continue
        t = np.tan(abs(turn) / 2)
        cut = min(radius * t, L[i - 1] / 2, L[i] / 2)
        r = cut / t
        u = np.array([np.cos(ang[i - 1]), np.sin(ang[i - 1])])
        t1 = V[i] - cut * u
        pts.append(t1)
        head.append(head[-1])
        labs.append(-1)
        sgn = np.sign(turn)
        centre = t1 + sgn * r * np.array([-u[1], u[0]])
        k = max(2, int(np.ceil(abs(turn) / arc_step)))
        h0 = head[-1]
        for j in range(1, k + 1):
            th = float(ang[i - 1]) + turn * j / k
            pts.append(centre + sgn * r * np.array([np.sin(th), -np.cos(th)]))
            head.append(h0 + turn * j / k)
            labs.append(-1 if j < k else lab[i])
    pts.append(V[-1])
    head.append(head[-1])
    labs.append(lab[-1])
    return np.asarray(pts), np.asarray(head), np.asarray(labs, np.int64)


def _sample(pts: np.ndarray, head: np.ndarray, labs: np.ndarray, spacing: float,
            speed: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses every ``spacing`` m along a dense path (headings interpolated
    along the path), their times at ``speed`` and labels."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    q = np.arange(0.0, s[-1] + 1e-9, spacing)
    x, y, th = np.interp(q, s, pts[:, 0]), np.interp(q, s, pts[:, 1]), np.interp(q, s, head)
    idx = np.clip(np.searchsorted(s, q, side="right") - 1, 0, len(s) - 1)
    return np.column_stack([x, y, wrap_angle(th)]), q / speed, labs[idx]


def _finish(vertices: list[tuple[float, float]], labels: list[int], column: str, *, spacing: Any,
            turn_radius: float, speed: Any, heading: str, world: Any, margin: float,
            rng: np.random.Generator | int | None) -> T.Trajectory:
    spacing = check_positive_float(spacing, "spacing")
    speed = check_positive_float(speed, "speed")
    pts, head, labs = _fillet(vertices, labels, turn_radius)
    poses, times, lab = _sample(pts, head, labs, spacing, speed)
    traj = T.Trajectory(poses, times, {column: lab})
    if world is not None:
        traj = T.detour(traj, world, margin=max(margin, 0.05), speed=speed)
    return _headings(traj, heading, rng)


def _check_heading(heading: Any) -> str:
    if heading not in HEADINGS:
        raise ValueError(f"heading must be one of {', '.join(map(repr, HEADINGS))}, got {heading!r}")
    return heading


def _headings(traj: T.Trajectory, heading: str, rng: np.random.Generator | int | None) -> T.Trajectory:
    if heading == "travel":
        return traj
    P = traj.poses.copy()
    P[:, 2] = np.random.default_rng(rng).uniform(-np.pi, np.pi, len(P))
    return T.Trajectory(P, traj.times, dict(traj.extra))


def _radius(turn_radius: Any, lane_spacing: float) -> float:
    return lane_spacing / 2 if turn_radius is None else check_positive_float(turn_radius, "turn_radius")


def serpentine(area: Sequence[float], lane_spacing: float = 1.2, spacing: float = 1.2, *, along: str = "x",
               margin: float = 0.5, turn_radius: float | None = None, heading: str = "travel",
               speed: float = 0.4, world: Any = None, rng: np.random.Generator | int | None = None) -> T.Trajectory:
    """Parallel lanes ``lane_spacing`` apart joined by U-turns.

    Parameters
    ----------
    area : (width, height), m
    lane_spacing : float
        Distance between neighbouring lanes (m); the lanes are centred in
        the area inside the margin, the outermost ones at most
        ``lane_spacing`` from it.
    spacing : float
        Distance between frames along the path (m).
    along : ``"x"`` or ``"y"``
        Direction of the lanes; the first lane starts at the low corner.
    margin : float
        Distance kept from the border (m).
    turn_radius : float, optional
        Radius of the turns (m), default ``lane_spacing / 2``: half-circle
        U-turns; never more than that.
    heading : ``"travel"`` or ``"random"``
    speed : float
        m/s, for the timestamps.
    world : World, optional
        Obstacles to drive around.
    rng : numpy Generator or int seed
        Only for ``heading="random"``.

    Returns
    -------
    Trajectory with the extra column ``lane`` (0 .. lanes - 1 on the lanes,
    -1 in the turns).

    Raises
    ------
    ValueError
        A non-positive size or spacing, a margin that leaves no room, room
        for one lane only, an unknown ``along`` or ``heading``.

    Examples
    --------
    >>> tr = serpentine((30, 30), lane_spacing=29 / 23, spacing=1.2)
    >>> int(tr.extra["lane"].max()) + 1
    24
    """
    hx, hy = _inner(area, margin)
    lane_spacing = check_positive_float(lane_spacing, "lane_spacing")
    if along not in ("x", "y"):
        raise ValueError(f"along must be 'x' or 'y', got {along!r}")
    v, lab = _serpentine_vertices(hx, hy, lane_spacing, along)
    return _finish(v, lab, "lane", spacing=spacing, turn_radius=_radius(turn_radius, lane_spacing), speed=speed,
                   heading=_check_heading(heading), world=world, margin=float(margin), rng=rng)


def perimeter_serpentine(area: Sequence[float], lane_spacing: float = 1.2, spacing: float = 1.2, *,
                         margin: float = 0.5, turn_radius: float | None = None, heading: str = "travel",
                         speed: float = 0.4, world: Any = None,
                         rng: np.random.Generator | int | None = None) -> T.Trajectory:
    """One lap along the border (``margin`` inside it, counter-clockwise
    from the low corner), then a serpentine along x one ``lane_spacing``
    inside the lap, as most robot mowers mow a lawn's edge first.

    Parameters and errors as :func:`serpentine`; the area must leave room
    for two lanes inside the lap.

    Returns
    -------
    Trajectory with the extra column ``lane`` (the serpentine's lanes 0 ..;
    -1 on the lap and in the turns): the lap is every frame before the
    first of lane 0.

    Examples
    --------
    >>> tr = perimeter_serpentine((10, 10), 1.0, 0.5)
    >>> bool(abs(tr.poses[0, 1] + 4.5) < 1e-9)   # the lap starts on the border lane
    True
    """
    hx, hy = _inner(area, margin)
    lane_spacing = check_positive_float(lane_spacing, "lane_spacing")
    ix, iy = hx - lane_spacing, hy - lane_spacing
    if ix <= 0 or iy <= 0:
        raise ValueError(f"lane_spacing {lane_spacing} m leaves no room for lanes inside the perimeter lap")
    inner, lab = _serpentine_vertices(ix, iy, lane_spacing, "x")
    lap = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy), (-hx, inner[0][1])]
    # the lap's last leg turns into the first lane (its start moves out to the lap)
    v = lap + inner[1:]
    labels = [-1] * 4 + lab
    return _finish(v, labels, "lane", spacing=spacing, turn_radius=_radius(turn_radius, lane_spacing),
                   speed=speed, heading=_check_heading(heading), world=world, margin=float(margin), rng=rng)


def spiral(area: Sequence[float], lane_spacing: float = 1.2, spacing: float = 1.2, *, margin: float = 0.5,
           turn_radius: float | None = None, heading: str = "travel", speed: float = 0.4, world: Any = None,
           rng: np.random.Generator | int | None = None) -> T.Trajectory:
    """Rectangular laps from the border inwards, counter-clockwise from the
    low corner, each ``lane_spacing`` inside the last, until the middle.

    Parameters and errors as :func:`serpentine`.

    Returns
    -------
    Trajectory with the extra column ``lap`` (0 on the outermost lap; a
    lap's last leg leads one lane inwards to the next).

    Examples
    --------
    >>> tr = spiral((10, 10), 1.0, 0.5)
    >>> bool(np.abs(tr.poses[-1, :2]).max() < 1.5)   # ends in the middle
    True
    """
    hx, hy = _inner(area, margin)
    ls = check_positive_float(lane_spacing, "lane_spacing")
    if 2 * min(hx, hy) < 2 * ls:
        raise ValueError(f"lane_spacing {ls} m leaves room for one lap only")
    v: list[tuple[float, float]] = [(-hx, -hy)]
    lab: list[int] = []
    k = 0
    while True:
        x0, x1, y0, y1 = -hx + k * ls, hx - k * ls, -hy + k * ls, hy - k * ls
        if x1 - x0 < ls / 2 or y1 - y0 < ls / 2:
            break
        legs = [(x1, y0), (x1, y1), (x0, y1), (x0, y0 + ls)]
        for p in legs:
            v.append(p)
            lab.append(k)
        if (y1 - (y0 + ls)) < ls / 2:
            break
        k += 1
    return _finish(v, lab, "lap", spacing=spacing, turn_radius=_radius(turn_radius, ls), speed=speed,
                   heading=_check_heading(heading), world=world, margin=float(margin), rng=rng)


def crossing(area: Sequence[float], lane_spacing: float = 1.2, spacing: float = 1.2, *, margin: float = 0.5,
             turn_radius: float | None = None, heading: str = "travel", speed: float = 0.4, world: Any = None,
             rng: np.random.Generator | int | None = None) -> T.Trajectory:
    """A crossing grid: a serpentine along x, then from its end one along y,
    so every lane of the second pass crosses every lane of the first. The
    lanes end on the outermost lanes of the other pass (where the lanes
    are centred with room to spare, they are that much shorter).

    Parameters and errors as :func:`serpentine`.

    Returns
    -------
    Trajectory with the extra column ``lane``: the x lanes 0 .. nx - 1, the
    y lanes nx .. nx + ny - 1, -1 in the turns.

    Examples
    --------
    >>> tr = crossing((10, 10), 2.0, 0.5)
    >>> int(tr.extra["lane"].max()) + 1   # 5 lanes along x, 5 along y
    10
    """
    hx, hy = _inner(area, margin)
    ls = check_positive_float(lane_spacing, "lane_spacing")
    # every lane ends on the outermost lane of the other pass: the passes join at a corner
    ax, ay = float(np.abs(_levels(hx, ls)).max()), float(np.abs(_levels(hy, ls)).max())
    vx, lx = _serpentine_vertices(ax, ay, ls, "x")
    vy, ly = _serpentine_vertices(ax, ay, ls, "y", first=max(lx) + 1)
    ex, ey = vx[-1]
    # mirrored so that the y pass starts on the side where the x pass ended and runs away from its last lane
    sx, sy = (1.0 if ex < 0 else -1.0), (1.0 if ey < 0 else -1.0)
    vy = [(sx * x, sy * y) for x, y in vy]
    if np.hypot(vy[0][0] - ex, vy[0][1] - ey) > 1e-9:
        v, lab = vx + vy, lx + [-1] + ly
    else:
        v, lab = vx + vy[1:], lx + ly
    return _finish(v, lab, "lane", spacing=spacing, turn_radius=_radius(turn_radius, ls), speed=speed,
                   heading=_check_heading(heading), world=world, margin=float(margin), rng=rng)


def random_survey(area: Sequence[float], n_frames: int, spacing: float = 1.2, *, margin: float = 0.5,
                  heading: str = "travel", speed: float = 0.4, world: Any = None,
                  rng: np.random.Generator | int | None = None) -> T.Trajectory:
    """A random (bounce) mower: straight lines at ``spacing`` m per frame; at
    the border or an obstacle (``margin`` m clearance) a new random
    direction (:func:`~sfanav.sim.trajectories.random_lines`). A frame's
    heading is the direction it drives off in.

    Parameters
    ----------
    area : (width, height), m
    n_frames : int
    spacing, margin, heading, speed, world, rng
        As :func:`serpentine`; ``rng`` draws the start, the directions (and
        the random headings).

    Raises
    ------
    ValueError
        Bad sizes or counts, an unknown ``heading``, no free start or way on.

    Examples
    --------
    >>> tr = random_survey((10, 10), 50, rng=0)
    >>> bool((np.abs(tr.poses[:, :2]) <= 4.5).all())
    True
    """
    _inner(area, margin)
    heading = _check_heading(heading)
    spacing = check_positive_float(spacing, "spacing")
    speed = check_positive_float(speed, "speed")
    n = check_int(n_frames, "n_frames")
    rng = np.random.default_rng(rng)
    traj = T.random_lines(area, n, spacing, margin=float(margin), world=world, dt=spacing / speed, rng=rng)
    return _headings(traj, heading, rng)


def survey(pattern: str, area: Sequence[float], lane_spacing: float = 1.2, spacing: float = 1.2, *,
           n_frames: int | None = None, margin: float = 0.5, heading: str = "travel", speed: float = 0.4,
           world: Any = None, rng: np.random.Generator | int | None = None) -> T.Trajectory:
    """The survey ``pattern`` (one of :data:`SURVEY_PATTERNS`) of ``area``.

    ``n_frames`` is the random survey's length (default: as many frames as
    the serpentine of ``lane_spacing`` would have) and ignored by the
    others; ``lane_spacing`` is ignored by the random survey. See the
    pattern's function for the rest.

    Raises
    ------
    ValueError
        An unknown pattern, or what the pattern's function raises.

    Examples
    --------
    >>> tr = survey("spiral", (10, 10), 1.0, 0.5)
    >>> "lap" in tr.extra
    True
    """
    if pattern not in SURVEY_PATTERNS:
        raise ValueError(f"unknown survey pattern {pattern!r}; available: {', '.join(SURVEY_PATTERNS)}")
    kw = dict(margin=margin, heading=heading, speed=speed, world=world, rng=rng)
    if pattern == "random":
        if n_frames is None:
            n_frames = len(serpentine(area, lane_spacing, spacing, margin=margin))
        return random_survey(area, n_frames, spacing, **kw)
    fn = {"serpentine": serpentine, "perimeter-serpentine": perimeter_serpentine, "spiral": spiral,
          "crossing": crossing}[pattern]
    return fn(area, lane_spacing, spacing, **kw)
