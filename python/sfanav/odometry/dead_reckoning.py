"""Poses and odometry increments: wrapping angles, per-step (distance, heading
change) increments of an odometry track and dead reckoning back from them.
Poses are (N, 3) arrays of x, y in metres and heading in radians."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import as_matrix, as_real_array, check_finite


def wrap_angle(a: Any) -> np.ndarray | float:
    """Angles in radians wrapped to (-pi, pi]."""
    w = np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), 2 * np.pi)
    return float(w) if np.ndim(w) == 0 else w


def arc_factor(dtheta: Any) -> np.ndarray:
    """``sinc(dtheta / 2) = sin(dtheta / 2) / (dtheta / 2)``: chord length of a
    unit-length arc turning by ``dtheta`` radians (1 at dtheta = 0)."""
    return np.sinc(np.asarray(dtheta, dtype=np.float64) / (2 * np.pi))


def as_poses(odometry: Any, name: str = "odometry", *, min_rows: int = 2) -> np.ndarray:
    """A finite float64 array of poses (N, 3): x, y in metres, heading in radians."""
    P = as_matrix(odometry, name, min_rows=min_rows)
    if P.shape[1] != 3:
        raise ValueError(
            f"{name} must be poses of shape (N, 3) (x [m], y [m], heading [rad]), got shape {P.shape}"
        )
    return P


def increments(odometry: Any, *, direction: bool = False) -> np.ndarray:
    """Motion increments between consecutive odometry poses.

    Parameters
    ----------
    odometry : array of shape (N, 3)
        Poses ``(x, y, theta)``: metres, metres, radians; N >= 2.
    direction : bool, default False
        Also return the third column ``beta``: the angle (radians, in
        [-pi/2, pi/2]) from the arc's chord (the mid-step heading, reversed
        when reversing) to the odometry's displacement. It is 0 when the
        robot drove a circular arc; a robot that turns on the spot and then
        drives (a lane change between sparse frames) has ``beta = dtheta /
        2``. With it, :func:`dead_reckon` and :class:`sfanav.odometry.OdometryEKF`
        reproduce the odometry's displacements exactly, whatever the robot
        did between two frames.

    Returns
    -------
    ndarray of shape (N - 1, 2), or (N - 1, 3) with ``direction``
        ``(d, dtheta[, beta])`` per step: signed arc length in metres
        (negative when the displacement points against the mid-step heading,
        i.e. reversing) and the heading change in radians, wrapped to (-pi,
        pi]. Without ``direction`` a lateral component of the displacement
        (sliding sideways, a turn before driving) is folded into the length
        of the chord and its direction is lost.

    Example
    -------
    >>> P = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, np.pi / 2]])  # turn on the spot, drive 2 m
    >>> np.round(increments(P, direction=True), 3).tolist()
    [[2.221, 1.571, 0.785]]
    >>> np.round(dead_reckon(increments(P, direction=True))[-1], 6).tolist()
    [0.0, 2.0, 1.570796]
    """
    P = as_poses(odometry)
    dxy = np.diff(P[:, :2], axis=0)
    dth = wrap_angle(np.diff(P[:, 2]))
    mid = P[:-1, 2] + 0.5 * dth
    chord = np.hypot(dxy[:, 0], dxy[:, 1])
    back = dxy[:, 0] * np.cos(mid) + dxy[:, 1] * np.sin(mid) < 0
    sign = np.where(back, -1.0, 1.0)
    U = np.c_[sign * chord / arc_factor(dth), dth]
    if not direction:
        return U
    heading = np.arctan2(dxy[:, 1], dxy[:, 0]) + np.where(back, np.pi, 0.0)
    beta = np.where(chord > 0, wrap_angle(heading - mid), 0.0)
    return np.c_[U, beta]


def dead_reckon(steps: Any, start_pose: Any = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Integrates motion increments from a start pose (arc model; with a
    third column ``beta`` each displacement turned by it off the arc's chord,
    which reproduces the odometry exactly).

    Parameters
    ----------
    steps : array of shape (N - 1, 2) or (N - 1, 3)
        ``(d, dtheta[, beta])`` per step, metres and radians (see
        :func:`increments`).
    start_pose : array of shape (3,)
        ``(x, y, theta)`` of the first frame, metres and radians.

    Returns
    -------
    ndarray of shape (N, 3)
        Poses ``(x, y, theta)``; headings are not wrapped (they accumulate).
    """
    U = as_matrix(steps, "steps", min_rows=0)
    if U.shape[1] not in (2, 3):
        raise ValueError(f"steps must have shape (N - 1, 2) or (N - 1, 3) (d, dtheta[, beta]), got shape {U.shape}")
    s0 = as_real_array(start_pose, "start_pose").astype(np.float64).ravel()
    if s0.shape != (3,):
        raise ValueError(f"start_pose must be (x [m], y [m], heading [rad]), got shape {s0.shape}")
    check_finite(s0, "start_pose")
    theta = s0[2] + np.concatenate([[0.0], np.cumsum(U[:, 1])])
    mid = theta[:-1] + 0.5 * U[:, 1] + (U[:, 2] if U.shape[1] == 3 else 0.0)
    chord = U[:, 0] * arc_factor(U[:, 1])
    xy = np.cumsum(np.c_[chord * np.cos(mid), chord * np.sin(mid)], axis=0)
    out = np.empty((len(U) + 1, 3))
    out[0, :2] = s0[:2]
    out[1:, :2] = s0[:2] + xy
    out[:, 2] = theta
    return out
