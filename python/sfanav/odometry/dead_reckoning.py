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


def increments(odometry: Any) -> np.ndarray:
    """Motion increments between consecutive odometry poses.

    Parameters
    ----------
    odometry : array of shape (N, 3)
        Poses ``(x, y, theta)``: metres, metres, radians; N >= 2.

    Returns
    -------
    ndarray of shape (N - 1, 2)
        ``(d, dtheta)`` per step: signed arc length in metres (negative when
        the displacement points against the mid-step heading, i.e. reversing)
        and the heading change in radians, wrapped to (-pi, pi]. A lateral
        component of the displacement (sliding sideways) is folded into the
        length of the chord.
    """
    P = as_poses(odometry)
    dxy = np.diff(P[:, :2], axis=0)
    dth = wrap_angle(np.diff(P[:, 2]))
    mid = P[:-1, 2] + 0.5 * dth
    chord = np.hypot(dxy[:, 0], dxy[:, 1])
    sign = np.where(dxy[:, 0] * np.cos(mid) + dxy[:, 1] * np.sin(mid) < 0, -1.0, 1.0)
    return np.c_[sign * chord / arc_factor(dth), dth]


def dead_reckon(steps: Any, start_pose: Any = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Integrates motion increments from a start pose (arc model).

    Parameters
    ----------
    steps : array of shape (N - 1, 2)
        ``(d, dtheta)`` per step, metres and radians (see :func:`increments`).
    start_pose : array of shape (3,)
        ``(x, y, theta)`` of the first frame, metres and radians.

    Returns
    -------
    ndarray of shape (N, 3)
        Poses ``(x, y, theta)``; headings are not wrapped (they accumulate).
    """
    U = as_matrix(steps, "steps", n_cols=2, min_rows=0)
    s0 = as_real_array(start_pose, "start_pose").astype(np.float64).ravel()
    if s0.shape != (3,):
        raise ValueError(f"start_pose must be (x [m], y [m], heading [rad]), got shape {s0.shape}")
    check_finite(s0, "start_pose")
    theta = s0[2] + np.concatenate([[0.0], np.cumsum(U[:, 1])])
    mid = theta[:-1] + 0.5 * U[:, 1]
    chord = U[:, 0] * arc_factor(U[:, 1])
    xy = np.cumsum(np.c_[chord * np.cos(mid), chord * np.sin(mid)], axis=0)
    out = np.empty((len(U) + 1, 3))
    out[0, :2] = s0[:2]
    out[1:, :2] = s0[:2] + xy
    out[:, 2] = theta
    return out
