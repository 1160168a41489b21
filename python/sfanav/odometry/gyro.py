"""A yaw gyro fused with the wheel odometry's heading changes.

Most robot mowers carry an IMU. Its yaw gyro, integrated between frames,
measures each step's turn far better than the wheels (whose heading error
grows with the distance, the turns and slip), but it drifts by its bias.
:func:`fuse_gyro` combines the two turns of every step by inverse variance
and rebuilds the odometry along the fused headings: each step keeps its
length and its direction relative to the heading at its start (as the
wheels measured them), and is turned by the fused heading. The pose graphs
(:func:`~sfanav.odometry.fit_pose_graph`, both back ends) and the EKF
(:meth:`~sfanav.odometry.OdometryEKF.run`) then read the fused odometry and
the fused per-step heading standard deviation.

Noise assumption (:data:`DEFAULT_GYRO_NOISE`): the gyro's turn over a step
of ``d`` metres turning ``dtheta`` radians has the standard deviation
``sqrt(heading_sigma^2 d + (turn_fraction dtheta)^2)``: an angle random
walk per metre travelled (a gyro's noise grows with time; at the mower's
steady speed time and distance are proportional, and the per-metre form
needs no timestamps) that also covers the bias left after calibration (its
systematic part is a heading drift per metre, which the pose graph
estimates as it does the wheels'), plus a scale error of the turn. The
defaults, 0.05 deg/sqrt(m) and 0.5 %, are a cheap MEMS gyro's (0.01
deg/sqrt(s) and 0.005 deg/s of bias at 0.4 m/s, 0.2 % scale error) with a
margin. The wheels' heading noise comes from the odometry noise model
(:func:`~sfanav.odometry.pose_graph_gtsam.odometry_sigmas`).

Example
-------
>>> import numpy as np
>>> odo = np.c_[np.arange(5.0), np.zeros(5), np.r_[0, 0.1, 0.2, 0.3, 0.4]]   # the wheels believe they turn
>>> fused = fuse_gyro(odo, np.zeros(5))                                      # the gyro says straight
>>> bool(np.abs(fused.odometry[:, 2]).max() < 0.01)
True
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_real_array, check_nonneg_float
from .dead_reckoning import as_poses, wrap_angle

DEFAULT_GYRO_NOISE = {"heading_sigma": float(np.radians(0.05)), "turn_fraction": 0.005}
"""The gyro's turn noise: ``heading_sigma`` (rad/sqrt(m)) and
``turn_fraction`` (of the turn); see the module docstring."""


@dataclass
class GyroFusion:
    """The odometry with the gyro fused into its heading changes.

    Attributes
    ----------
    odometry : ndarray (N, 3)
        x, y (m), heading (rad, continuous): the steps of the wheels turned
        by the fused headings, from the first odometry pose.
    heading_sigma : ndarray (N - 1,)
        Standard deviation (rad) of each step's fused heading change.
    gyro_weight : ndarray (N - 1,)
        The gyro's share in [0, 1] of each step's heading change.
    """

    odometry: np.ndarray
    heading_sigma: np.ndarray
    gyro_weight: np.ndarray


def gyro_noise_model(gyro_noise: Mapping[str, float] | None = None) -> dict[str, float]:
    """:data:`DEFAULT_GYRO_NOISE` updated by ``gyro_noise`` (validated:
    known keys, finite, >= 0)."""
    out = dict(DEFAULT_GYRO_NOISE)
    if gyro_noise is None:
        return out
    if not isinstance(gyro_noise, Mapping):
        raise TypeError(f"gyro_noise must be a mapping (heading_sigma, turn_fraction), got {type(gyro_noise).__name__}")
    for k, v in gyro_noise.items():
        if k not in out:
            raise ValueError(f"unknown gyro_noise key {k!r}; known: {sorted(out)}")
        out[k] = check_nonneg_float(v, f"gyro_noise[{k!r}]")
    return out


def as_gyro(gyro: Any, n: int) -> np.ndarray:
    """The gyro's integrated heading (n,) as float64: ValueError for another
    length or non-finite values, TypeError for non-numbers."""
    g = as_real_array(gyro, "gyro").astype(np.float64)
    if g.ndim != 1:
        raise ValueError(f"gyro must be one integrated heading per frame (shape ({n},)), got shape {g.shape}")
    if len(g) != n:
        raise ValueError(f"gyro has {len(g)} headings but the odometry has {n} poses; they must match")
    bad = np.flatnonzero(~np.isfinite(g))
    if len(bad):
        raise ValueError(f"gyro must be finite; frame {bad[0]} has {g[bad[0]]}")
    return g


def fuse_turns(odometry_turn: np.ndarray, odometry_variance: np.ndarray, gyro_turn: np.ndarray, distance: np.ndarray,
               gyro_noise: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse-variance fusion of the turns (K,) of K steps (rad): the
    odometry's with variance ``odometry_variance`` (rad^2), the gyro's with
    the variance of the noise model over steps of ``distance`` (m). The
    odometry's turn is taken on the gyro's branch (a turn wrapped by the
    odometry is unwrapped near the gyro's). Returns (turn, variance, the
    gyro's weight)."""
    gn = gyro_noise_model(gyro_noise)
    vo = np.asarray(odometry_variance, np.float64)
    tg = np.asarray(gyro_turn, np.float64)
    to = np.asarray(odometry_turn, np.float64)
    to = to + np.round((tg - to) / (2 * np.pi)) * 2 * np.pi
    vg = gn["heading_sigma"] ** 2 * np.asarray(distance, np.float64) + (gn["turn_fraction"] * tg) ** 2 + 1e-14
    wg = vo / (vo + vg)
    return wg * tg + (1 - wg) * to, vo * vg / (vo + vg), wg


def fuse_gyro(odometry: Any, gyro: Any, *, odometry_noise: Any = None,
              gyro_noise: Mapping[str, float] | None = None) -> GyroFusion:
    """Fuses a yaw gyro's turns with the odometry's, step by step, by
    inverse variance, and rebuilds the odometry along the fused headings.

    Parameters
    ----------
    odometry : array (N, 3)
        Odometry poses x, y (m), heading (rad) of consecutive frames.
    gyro : array (N,)
        The gyro's integrated heading (rad; only its differences are used),
        e.g. :attr:`sfanav.Dataset.gyro` of one run.
    odometry_noise : mapping or sfanav.sim.OdometryNoise, optional
        The wheels' noise model (as :func:`~sfanav.odometry.fit_pose_graph`).
    gyro_noise : mapping, optional
        The gyro's (:data:`DEFAULT_GYRO_NOISE`).

    Returns
    -------
    GyroFusion

    Raises
    ------
    ValueError
        Non-finite or mis-shaped odometry, a gyro of another length or with
        non-finite values, bad noise values. TypeError for non-numbers.
    """
    from .pose_graph_gtsam import odometry_sigmas

    P = as_poses(odometry, "odometry")
    g = as_gyro(gyro, len(P))
    so = odometry_sigmas(P, odometry_noise)[:, 2]
    d = np.hypot(*np.diff(P[:, :2], axis=0).T)
    dth, var, wg = fuse_turns(wrap_angle(np.diff(P[:, 2])), so**2, np.diff(g), d, gyro_noise)
    sig = np.sqrt(var)
    theta = P[0, 2] + np.concatenate([[0.0], np.cumsum(dth)])
    dxy = np.diff(P[:, :2], axis=0)
    c, s = np.cos(P[:-1, 2]), np.sin(P[:-1, 2])
    local = np.c_[c * dxy[:, 0] + s * dxy[:, 1], -s * dxy[:, 0] + c * dxy[:, 1]]
    cn, sn = np.cos(theta[:-1]), np.sin(theta[:-1])
    step = np.c_[cn * local[:, 0] - sn * local[:, 1], sn * local[:, 0] + cn * local[:, 1]]
    xy = P[0, :2] + np.concatenate([np.zeros((1, 2)), np.cumsum(step, axis=0)])
    return GyroFusion(np.c_[xy, theta], sig, wg)
