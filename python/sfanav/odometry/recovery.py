"""Divergence handling of :class:`sfanav.OdometryEKF`: odometry steps that
the filter must not trust as they are (dropped frames, jumps), and the pose
a lost filter re-initialises at from the recent single-image estimates.

* :func:`step_anomalies`: per odometry step, how many nominal steps it spans
  (its noise variance is scaled by that many) and whether it is a jump
  (its displacement is treated as unknown).
* :func:`pose_from_window`: the robot's current pose from a few recent
  estimates and their odometry (a trimmed rigid fit), the re-initialisation
  point after a divergence.

The filter (:mod:`sfanav.odometry.ekf`) calls both; the measurements and the
rules are in ``docs/odometry.md`` ("Divergence and recovery").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_real_array
from .._sampling import evenly_spaced
from ..localization.error_metrics import align
from .dead_reckoning import wrap_angle

EVENT_KINDS = ("divergence", "innovation", "jump", "gap")
"""Kinds of :class:`FilterEvent`: ``divergence`` (a run of inconsistent
estimates: re-initialised), ``innovation`` (the windowed innovation test
failed: re-initialised), ``jump`` (an odometry step too long for the robot:
its displacement treated as unknown), ``gap`` (a step spanning several
nominal steps, e.g. dropped frames: its noise scaled)."""


@dataclass(frozen=True)
class FilterEvent:
    """One event of a filter run.

    Attributes
    ----------
    frame : int
        Index of the frame (row of the run) the event happened at; for
        ``jump`` and ``gap``, the frame the step leads to.
    kind : str
        One of :data:`EVENT_KINDS`.
    value : float
        ``divergence``/``innovation``: the distance in metres the state moved
        at the re-initialisation; ``jump``: the step's odometry distance in
        metres; ``gap``: the number of nominal steps the step spans.
    """

    frame: int
    kind: str
    value: float


def step_anomalies(steps: Any, stamps: Any = None, *, gap_factor: float | None = 3.0,
                   jump_factor: float | None = 8.0, nominal: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Scale and jump flag of each odometry step.

    Parameters
    ----------
    steps : array (N - 1, 2)
        Odometry increments ``(d [m], dtheta [rad])``
        (:func:`sfanav.odometry.increments`).
    stamps : array (N,) of float, optional
        Frame times in seconds (increasing). With them a step spans
        ``dt / median(dt)`` nominal steps; without them, ``|d| / median |d|``
        over the moving steps (a longer step than usual is read as dropped
        frames).
    gap_factor : float or None, default 3
        A step spanning more than this many nominal steps is a gap: its
        scale is that number (the filter multiplies the step's odometry
        noise variance by it), else 1. None: every scale is 1.
    jump_factor : float or None, default 8
        A step whose distance exceeds this many times the nominal distance
        of its duration (the median moving step, times its span in nominal
        steps when stamps are given) is a jump: no robot drives that far in
        that time (a kidnap, a teleport in the data). None: no jumps.
    nominal : float, optional
        The nominal step distance in metres (>= 0; 0: no jumps, and without
        stamps no gaps) instead of the median moving step of ``steps``: an
        online filter fixes it from the steps seen so far and checks each
        new step against it.

    Returns
    -------
    scale : ndarray (N - 1,)
        >= 1.
    jump : ndarray of bool (N - 1,)

    Raises ValueError on stamps of the wrong length, non-finite or not
    increasing, and on factors <= 1.

    Example
    -------
    >>> scale, jump = step_anomalies(np.array([[1.0, 0]] * 4 + [[5.0, 0], [30.0, 0]]))
    >>> scale.tolist(), jump.tolist()
    ([1.0, 1.0, 1.0, 1.0, 5.0, 30.0], [False, False, False, False, False, True])
    """
    U = np.asarray(steps, dtype=np.float64).reshape(-1, 2)
    n = len(U)
    for name, f in (("gap_factor", gap_factor), ("jump_factor", jump_factor)):
        if f is not None and not (np.isfinite(f) and f > 1):
            raise ValueError(f"{name} must be a number > 1 (nominal steps) or None, got {f!r}")
    scale, jump = np.ones(n), np.zeros(n, bool)
    if n == 0:
        return scale, jump
    d = np.abs(U[:, 0])
    if nominal is None:
        moving = d[d > 1e-9]
        nominal = float(np.median(moving)) if len(moving) else 0.0
    elif not (np.isfinite(nominal) and nominal >= 0):
        raise ValueError(f"nominal must be a distance >= 0 (metres), got {nominal!r}")
    nominal = float(nominal)
    if stamps is not None:
        t = as_real_array(stamps, "stamps").astype(np.float64).ravel()
        if len(t) != n + 1:
            raise ValueError(f"stamps must have one time per frame ({n + 1}), got {len(t)}")
        dt = np.diff(t)
        if not np.isfinite(t).all() or np.any(dt <= 0):
            raise ValueError("stamps must be finite and strictly increasing (seconds)")
        span = dt / float(np.median(dt))
    else:
        span = d / nominal if nominal > 0 else np.ones(n)
    if gap_factor is not None:
        scale = np.where(span > gap_factor, span, 1.0)
    if jump_factor is not None and nominal > 0:
        allowed = jump_factor * nominal * (np.maximum(span, 1.0) if stamps is not None else 1.0)
        jump = d > allowed
    return scale, jump


def pose_from_window(odometry: Any, estimates: Any, *, min_spread: float) -> tuple[np.ndarray, bool]:
    """The pose of the last frame of a window of frames from their odometry
    poses and single-image estimates.

    Parameters
    ----------
    odometry : array (n, 3)
        Odometry poses ``(x [m], y [m], theta [rad])`` of the window, in the
        odometry's own frame.
    estimates : array (n, 2)
        Their position estimates in metres (finite), in the map frame.
    min_spread : float
        Metres: when the window's odometry positions span at least this
        along x or y, a rigid fit of them to the estimates (refitted once
        without the estimates more than 3 times the median residual off,
        the residuals of the least-squares fit or, where lower in median,
        of the best fit through two frames: one outlier in four frames
        pulls a least-squares fit too far for the trimming to find it)
        gives the position and heading; else the heading is unknown.

    Returns
    -------
    pose : ndarray (3,)
        ``(x, y, theta)`` of the last frame; theta is NaN when unknown, and
        x, y are then the median of the estimates.
    heading_known : bool

    Example
    -------
    >>> odo = np.c_[np.arange(5.0), np.zeros(5), np.zeros(5)]
    >>> est = np.c_[10 + np.zeros(5), np.arange(5.0)]        # the map frame turned by 90 degrees
    >>> pose, ok = pose_from_window(odo, est, min_spread=1.0)
    >>> np.round(pose, 6).tolist(), ok
    ([10.0, 4.0, 1.570796], True)
    """
    P = np.asarray(odometry, dtype=np.float64)
    Z = np.asarray(estimates, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or Z.shape != (len(P), 2) or len(P) == 0:
        raise ValueError(f"odometry (n, 3) and estimates (n, 2) of the same n >= 1 are needed, got {P.shape} and {Z.shape}")
    if not (np.isfinite(P).all() and np.isfinite(Z).all()):
        raise ValueError("the window's odometry and estimates must be finite")
    if len(P) < 3 or float(np.ptp(P[:, :2], axis=0).max()) < min_spread:
        return np.array([*np.median(Z, axis=0), np.nan]), False
    al = align(P[:, :2], Z)
    res = np.hypot(*(al.apply(P[:, :2]) - Z).T)
    pair = _best_pair_residuals(P[:, :2], Z)
    if pair is not None and np.median(pair) < np.median(res):  # an outlier pulled the least-squares fit
        res = pair
    keep = res <= 3.0 * max(float(np.median(res)), 1e-9)
    if 3 <= keep.sum() < len(P) and float(np.ptp(P[keep, :2], axis=0).max()) >= min_spread:
        al = align(P[keep, :2], Z[keep])
    xy = al.apply(P[-1:, :2])[0]
    heading = float(wrap_angle(P[-1, 2] + np.arctan2(al.rotation[1, 0], al.rotation[0, 0])))
    return np.array([xy[0], xy[1], heading]), True


_MAX_PAIR_POINTS = 12
"""Points of a window the least-median fit draws its pairs from (evenly spaced)."""


def _best_pair_residuals(X: np.ndarray, Z: np.ndarray) -> np.ndarray | None:
    """Residuals (n,) of the least-median-of-squares rigid fit of points X
    (n, 2) to Z (n, 2) over the transforms that pairs of points fix (pairs
    closer than a tenth of the window's span skipped: their rotation is
    noise); None without such a pair. A least-squares fit of four frames
    spreads one outlier over all of them, so that trimming at 3 times the
    median residual keeps it; the pair fit of the others leaves it alone."""
    idx = evenly_spaced(len(X), _MAX_PAIR_POINTS)
    span = float(np.ptp(X, axis=0).max())
    best, best_med = None, np.inf
    for ai, a in enumerate(idx):
        for b in idx[ai + 1:]:
            dx, dz = X[b] - X[a], Z[b] - Z[a]
            if np.hypot(*dx) < 0.1 * span:
                continue
            ang = np.arctan2(dz[1], dz[0]) - np.arctan2(dx[1], dx[0])
            R = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
            r = np.hypot(*((X - 0.5 * (X[a] + X[b])) @ R.T + 0.5 * (Z[a] + Z[b]) - Z).T)
            if np.median(r) < best_med:
                best, best_med = r, float(np.median(r))
    return best

