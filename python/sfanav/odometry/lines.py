"""Straight-line segments of a run (thesis 5.3.1): :class:`Lines` (labels,
distances along each line, relative angles between lines, transits between
them) from known labels or from odometry, and :func:`segment_lines` that
finds them in an odometry track."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_real_array, check_finite, check_int, check_nonneg_float
from .dead_reckoning import as_poses, increments, wrap_angle


@dataclass
class Lines:
    """Straight line segments of a trajectory (thesis 5.3.1).

    Attributes
    ----------
    labels : ndarray of int, shape (N,)
        Line index of each sample, -1 for samples on no line (turns, stops,
        segments too short).
    distances : ndarray of float, shape (N,)
        Signed distance in metres along its line from the line's first
        sample (the thesis's ``d_{n,m}``; 0 at the first sample, growing in the
        driving direction); NaN for samples on no line.
    relative_angles : ndarray of float, shape (n_lines - 1,), or None
        Measured heading change from line n to line n+1 in radians, wrapped
        to (-pi, pi] (the thesis's angle between l_n and l_{n+1}); None if
        unknown (e.g. lines driven independently in a simulator).
    headings : ndarray of float, shape (n_lines,), or None
        Odometry heading of each line in radians (circular mean over the
        line): an initial guess for the line orientations.
    origins : ndarray of float, shape (n_lines, 2), or None
        Odometry position of each line's first sample in metres: an initial
        guess for the line origins.
    transit_lengths : ndarray of float, shape (n_lines - 1,), or None
        Odometry path length in metres driven between the last sample of
        line n and the first sample of line n+1 (the transit; 0 for a turn on
        the spot). With ``transit_turns`` it sets the odometry's noise on the
        relative pose of consecutive lines (:func:`sfanav.odometry.odometry_variances`).
    transit_turns : ndarray of float, shape (n_lines - 1,), or None
        Total absolute heading change in radians over the same transit.
    """

    labels: np.ndarray
    distances: np.ndarray
    relative_angles: np.ndarray | None = None
    headings: np.ndarray | None = None
    origins: np.ndarray | None = None
    transit_lengths: np.ndarray | None = None
    transit_turns: np.ndarray | None = None

    def __post_init__(self) -> None:
        lab = np.asarray(self.labels)
        if lab.ndim != 1 or lab.dtype.kind not in "iu":
            raise TypeError(f"labels must be a 1-D integer array, got dtype {lab.dtype} and shape {lab.shape}")
        self.labels = lab.astype(np.int64)
        self.distances = np.asarray(self.distances, dtype=np.float64)
        if self.distances.shape != self.labels.shape:
            raise ValueError(
                f"distances must have one value per sample ({len(self.labels)}), got shape {self.distances.shape}"
            )
        n = self.n_lines
        on = self.labels >= 0
        if np.any(self.labels < -1):
            raise ValueError("labels must be line indices >= 0, or -1 for samples on no line")
        if n and len(np.unique(self.labels[on])) != n:
            missing = sorted(set(range(n)) - set(np.unique(self.labels[on]).tolist()))
            raise ValueError(f"line labels must be 0..{n - 1} without gaps; line(s) {missing} have no samples")
        if not np.isfinite(self.distances[on]).all():
            raise ValueError("distances contain NaN or infinity on samples that belong to a line")
        for name, shape in (("relative_angles", (max(n - 1, 0),)), ("headings", (n,)), ("origins", (n, 2)),
                            ("transit_lengths", (max(n - 1, 0),)), ("transit_turns", (max(n - 1, 0),))):
            v = getattr(self, name)
            if v is not None:
                v = np.asarray(v, dtype=np.float64)
                if v.shape != shape:
                    raise ValueError(f"{name} must have shape {shape} for {n} lines, got {v.shape}")
                check_finite(v, name)
                if name.startswith("transit") and np.any(v < 0):
                    raise ValueError(f"{name} must be >= 0 (path length in metres, absolute turn in radians)")
                setattr(self, name, v)

    @property
    def n_lines(self) -> int:
        """Number of lines."""
        return int(self.labels.max()) + 1 if len(self.labels) and self.labels.max() >= 0 else 0

    @property
    def mask(self) -> np.ndarray:
        """Boolean (N,): samples that belong to a line."""
        return self.labels >= 0

    @property
    def n_points(self) -> int:
        """Number of samples on lines."""
        return int(self.mask.sum())

    def sizes(self) -> np.ndarray:
        """Number of samples of each line, shape (n_lines,)."""
        return np.bincount(self.labels[self.mask], minlength=self.n_lines)

    def path_lengths(self) -> np.ndarray:
        """Odometry path length driven on each line in metres (sum of the
        absolute steps of its distances), shape (n_lines,)."""
        out = np.zeros(self.n_lines)
        for n in range(self.n_lines):
            out[n] = float(np.abs(np.diff(self.distances[self.labels == n])).sum())
        return out

    def transits(self) -> np.ndarray:
        """Odometry displacement from the origin of line n to the origin of
        line n+1, in the frame of line n's odometry heading (x along the
        line, y to its left), metres, shape (n_lines - 1, 2). Needs
        ``origins`` and ``headings``."""
        if self.origins is None or self.headings is None:
            raise ValueError("the transits between lines need the odometry origins and headings of the lines")
        dxy = np.diff(self.origins, axis=0)
        c, s = np.cos(self.headings[:-1]), np.sin(self.headings[:-1])
        return np.c_[c * dxy[:, 0] + s * dxy[:, 1], -s * dxy[:, 0] + c * dxy[:, 1]]

    def lengths(self) -> np.ndarray:
        """Length of each line in metres (max - min distance), shape (n_lines,)."""
        out = np.zeros(self.n_lines)
        for n in range(self.n_lines):
            d = self.distances[self.labels == n]
            out[n] = d.max() - d.min()
        return out

    def __repr__(self) -> str:
        ang = "measured" if self.relative_angles is not None else "none"
        return (
            f"<sfanav.odometry.Lines {self.n_lines} lines, {self.n_points} of {len(self.labels)} samples, "
            f"relative angles: {ang}>"
        )


def lines_from_labels(labels: Any, distances: Any, relative_angles: Any = None, *, headings: Any = None,
                      origins: Any = None, transit_lengths: Any = None, transit_turns: Any = None) -> Lines:
    """Lines known in advance (e.g. a simulator that drives given straight
    lines, thesis 5.3.1): labels (N,) with line indices 0..L-1 (-1: no line)
    and distances (N,) in metres along each line. Optional measured relative
    angles (L - 1,) in radians, odometry headings (L,) and origins (L, 2),
    transit path lengths (L - 1,) in metres and absolute turns (L - 1,) in
    radians (see :class:`Lines`)."""
    lab = as_real_array(labels, "labels")
    if lab.dtype.kind == "f":
        if not np.all(np.isfinite(lab)) or not np.all(lab == np.round(lab)):
            raise TypeError("labels must be integers")
        lab = lab.astype(np.int64)
    dist = as_real_array(distances, "distances").astype(np.float64)
    return Lines(lab, dist, relative_angles, headings, origins, transit_lengths, transit_turns)


def _describe(P: np.ndarray, U: np.ndarray, spans: list[tuple[int, int]], labels: np.ndarray,
              distances: np.ndarray) -> Lines:
    """Lines of the sample spans [a, b] (inclusive, in time order) of odometry
    poses P with increments U: headings, origins, relative angles, transits."""
    headings = np.array([_circular_mean(P[a : b + 1, 2]) for a, b in spans])
    origins = np.array([P[a, :2] for a, _ in spans]).reshape(len(spans), 2)
    n = len(spans)
    rel = wrap_angle(np.diff(headings)) if n > 1 else np.empty(0)
    t_len = np.array([float(np.abs(U[b0:a1, 0]).sum()) for (_, b0), (a1, _) in zip(spans[:-1], spans[1:])])
    t_turn = np.array([float(np.abs(U[b0:a1, 1]).sum()) for (_, b0), (a1, _) in zip(spans[:-1], spans[1:])])
    return Lines(labels, distances, np.atleast_1d(rel), headings, origins, t_len, t_turn)


def lines_from_odometry(labels: Any, odometry: Any) -> Lines:
    """Lines known in advance (labels (N,), 0..L-1 in driving order, each
    line's samples contiguous, -1 elsewhere) measured by odometry poses
    (N, 3): distances along each line (signed cumulative odometry distance),
    headings, origins, relative angles and transits, as
    :func:`segment_lines` gives them."""
    lab = as_real_array(labels, "labels")
    if lab.dtype.kind == "f":
        if not np.all(np.isfinite(lab)) or not np.all(lab == np.round(lab)):
            raise TypeError("labels must be integers")
    lab = lab.astype(np.int64).ravel()
    P = as_poses(odometry)
    if len(P) != len(lab):
        raise ValueError(f"labels has {len(lab)} samples but odometry has {len(P)}; they must match")
    U = increments(P)
    dist = np.full(len(lab), np.nan)
    spans = []
    n_lines = int(lab.max()) + 1 if lab.size and lab.max() >= 0 else 0
    for n in range(n_lines):
        idx = np.flatnonzero(lab == n)
        if len(idx) == 0:
            raise ValueError(f"line labels must be 0..{n_lines - 1} without gaps; line {n} has no samples")
        if np.any(np.diff(idx) != 1):
            raise ValueError(f"line {n} is not contiguous in time")
        if spans and idx[0] <= spans[-1][1]:
            raise ValueError(f"line {n} starts before line {n - 1} ends: lines must be numbered in driving order")
        dist[idx] = np.concatenate([[0.0], np.cumsum(U[idx[:-1], 0])])
        spans.append((int(idx[0]), int(idx[-1])))
    if not spans:
        raise ValueError("no line: every sample is labelled -1")
    return _describe(P, U, spans, lab, dist)


def _circular_mean(a: np.ndarray) -> float:
    return float(np.arctan2(np.sin(a).mean(), np.cos(a).mean()))


def segment_lines(
    odometry: Any,
    *,
    dt: Any = 1.0,
    min_speed: float | None = None,
    max_turn_rate: float | None = None,
    min_points: int = 10,
    min_length: float = 0.5,
) -> Lines:
    """Splits a trajectory into straight line segments from odometry
    (thesis 5.3.1, real-world experiment: "split into line segments based on
    the translational and angular velocity measurements from odometry").

    A step (frame k to k+1) is *straight* if its speed ``|d| / dt`` is at
    least ``min_speed`` and its turn rate ``|dtheta| / dt`` at most
    ``max_turn_rate``. A line is a maximal run of consecutive straight steps
    (its samples are the frames they join); runs with fewer than
    ``min_points`` samples or shorter than ``min_length`` are dropped.

    Parameters
    ----------
    odometry : array of shape (N, 3)
        Odometry poses ``(x, y, theta)``: metres, metres, radians.
    dt : float or array of shape (N - 1,), default 1.0
        Time of each step in seconds (default: speeds per frame).
    min_speed : float or None
        Metres per second. None: a quarter of the median speed of the steps
        that move at all (scale-free; stops and turns on the spot fall below).
    max_turn_rate : float or None
        Radians per second. None: the larger of 0.2 rad per metre driven at
        the median speed (arcs tighter than a 5 m radius are not straight)
        and 4 times the median turn rate of the steps at or above
        ``min_speed`` (the heading noise of straight driving).
    min_points : int, default 10
        Fewest samples of a line.
    min_length : float, default 0.5
        Shortest line in metres.

    Returns
    -------
    Lines
        With ``distances`` from the odometry's distance measurements (signed
        cumulative arc length from the line's first sample), ``relative_angles``
        from the odometry heading change between consecutive lines (circular
        means over each line), ``headings`` and ``origins`` for initialisation.

    Raises
    ------
    ValueError
        If no line is found (with the thresholds used, so they can be
        adjusted), or the inputs are malformed.
    """
    P = as_poses(odometry)
    U = increments(P)
    dts = np.broadcast_to(np.asarray(dt, dtype=np.float64), (len(U),))
    if not np.all(np.isfinite(dts)) or np.any(dts <= 0):
        raise ValueError("dt must be positive and finite (seconds per step)")
    speed = np.abs(U[:, 0]) / dts
    rate = np.abs(U[:, 1]) / dts
    moving = speed[speed > 0]
    if len(moving) == 0:
        raise ValueError("no line found: the odometry never moves")
    med = float(np.median(moving))
    v_min = 0.25 * med if min_speed is None else check_nonneg_float(min_speed, "min_speed")
    if max_turn_rate is None:
        # 0.2 rad per metre at the median speed, or 4x the median turn rate of the moving steps
        # (the heading noise of straight driving), whichever is larger
        w_max = max(0.2 * med, 4.0 * float(np.median(rate[speed >= v_min])))
    else:
        w_max = check_nonneg_float(max_turn_rate, "max_turn_rate")
    min_points = check_int(min_points, "min_points", minimum=2)
    min_length = check_nonneg_float(min_length, "min_length")
    straight = (speed >= v_min) & (rate <= w_max)
    labels = np.full(len(P), -1, dtype=np.int64)
    distances = np.full(len(P), np.nan)
    # runs of straight steps [a, b) -> samples a..b
    edges = np.diff(np.concatenate([[0], straight.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    n = 0
    spans = []
    for a, b in zip(starts, ends):
        d = np.concatenate([[0.0], np.cumsum(U[a:b, 0])])
        if b - a + 1 < min_points or d.max() - d.min() < min_length:
            continue
        labels[a : b + 1] = n
        distances[a : b + 1] = d
        spans.append((int(a), int(b)))
        n += 1
    if n == 0:
        raise ValueError(
            f"no line found in {len(P)} odometry samples: no run of at least {min_points} samples and "
            f"{min_length} m with speed >= {v_min:.4g} m/s and turn rate <= {w_max:.4g} rad/s "
            f"(dt = {float(dts[0]):.4g} s); adjust min_speed, max_turn_rate, min_points or min_length"
        )
    # heading change between consecutive lines (odometry integrates it across the turn); wrapped,
    # so only its value modulo 2 pi matters; transits: path length and turn between the lines
    return _describe(P, U, spans, labels, distances)
