"""Fusion of SFA position estimates and odometry in an Extended Kalman
Filter (thesis 5.3.2).

State ``x = (x, y, theta)``: position in metres, heading in radians.

Prediction (Constant Turn Rate and Velocity model, driven by odometry): the
odometry increment of step k, ``u_k = (d_k, dtheta_k)`` (metres driven and
heading change in radians, :func:`sfanav.odometry.increments`), moves the
robot along a circular arc, i.e. at constant velocity ``d_k / dt`` and turn
rate ``dtheta_k / dt`` over the step (``dt`` cancels)::

    x'     = x + d k cos(theta + dtheta / 2)
    y'     = y + d k sin(theta + dtheta / 2)        k = sinc(dtheta / 2)
    theta' = theta + dtheta

which is the CTRV update ``x + v / w (sin(theta + w dt) - sin theta)``, ...
written without the division by the turn rate. Beyond the thesis, the
displacement keeps the direction the odometry measured: the increment's
third component ``beta`` (:func:`sfanav.odometry.increments` with
``direction=True``) turns it off the arc's chord, ``theta + dtheta / 2 +
beta`` in place of ``theta + dtheta / 2``. On dense frames ``beta`` is
about 0 and the model is the thesis's; between sparse frames where the
robot turned on the spot and then drove (a mower's lane change) the arc
puts the robot up to ``d sin(dtheta / 2)`` off (1.4 m after a 2 m step with
a quarter turn) and the filter lost the track at every row end. Process
noise enters
through the odometry: ``Q = V diag(sigma_d^2, sigma_theta^2) V^T``, ``V`` the
Jacobian of the motion with respect to ``u``, plus ``process_floor`` on the
diagonal.

Update: the SFA estimate (metric positions, e.g. from
:class:`sfanav.MetricLearner` after alignment, or a supervised
:class:`sfanav.QuadraticRegression`) measures ``(x, y)`` directly,
``H = [[1, 0, 0], [0, 1, 0]]``, noise ``R = sigma_r^2 I``.

Gating (beyond the thesis): a measurement whose squared Mahalanobis
distance ``y^T S^-1 y`` of the innovation exceeds the chi-square quantile of
``gate_probability`` (2 degrees of freedom: ``-2 ln(1 - p)``) is skipped, as
is any row of NaN (a missing estimate). After ``max_consecutive_gated``
skipped measurements in a row the next one is accepted anyway.

Divergence and recovery (beyond the thesis; :mod:`sfanav.odometry.recovery`):
the single-image estimates are a global localizer, so a filter that has
lost the robot (kidnapped, wheel slip, a jump in the data) re-initialises
from them. An estimate is *inconsistent* when its squared Mahalanobis
distance exceeds the chi-square quantile of ``divergence_probability``;
``reinit_after`` inconsistent estimates in a row (and, optionally, the sum
of the last ``nis_window`` accepted normalised innovations squared above its
chi-square quantile of ``nis_probability``) re-initialise the state at the
pose a rigid fit of those frames' odometry to their estimates gives, with
the covariance ``diag(reinit_std)^2``. An odometry step spanning more than
``gap_factor`` nominal steps (dropped frames) has its noise variance scaled
by that many steps; a step longer than ``jump_factor`` nominal steps is a
jump: its displacement gets a position standard deviation of its own length,
so the next estimate places the robot.

The filter is :class:`filterpy.kalman.ExtendedKalmanFilter` with the CTRV
prediction.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import (
    as_matrix,
    as_real_array,
    check_finite,
    check_int,
    check_nonneg_float,
    check_positive_float,
    check_same_length,
)
from .._progress import progress_bar
from .dead_reckoning import arc_factor, as_poses, dead_reckon, increments, wrap_angle
from .recovery import FilterEvent, pose_from_window, step_anomalies


def _direction(pose: np.ndarray, u: np.ndarray) -> float:
    """The displacement's direction (rad): the mid-step heading, turned by
    the increment's ``beta`` when it has one."""
    return float(pose[2] + 0.5 * float(u[1]) + (float(u[2]) if len(u) > 2 else 0.0))


def ctrv_motion(pose: np.ndarray, u: np.ndarray) -> np.ndarray:
    """One CTRV step: pose (3,) ``(x [m], y [m], theta [rad])`` moved by the
    increment u (2,) ``(d [m], dtheta [rad])`` or (3,) ``(d, dtheta, beta)``
    (:func:`sfanav.odometry.increments` with ``direction=True``: the
    displacement turned by ``beta`` off the arc's chord, as the odometry
    measured it)."""
    d, dth = float(u[0]), float(u[1])
    k = float(arc_factor(dth))
    h = _direction(pose, u)
    return np.array([pose[0] + d * k * np.cos(h), pose[1] + d * k * np.sin(h), pose[2] + dth])


def _dsinc_half(dth: float) -> float:
    """d/d(dth) of sinc(dth / 2)."""
    h = 0.5 * dth
    if abs(h) < 1e-4:
        return 0.5 * (-h / 3.0)
    return 0.5 * (h * np.cos(h) - np.sin(h)) / (h * h)


def ctrv_jacobians(pose: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of :func:`ctrv_motion`: F (3, 3) with respect to the pose and
    V (3, 2) with respect to the increment's ``(d, dtheta)`` (``beta`` held:
    the odometry's noise is in distance and turn)."""
    d, dth = float(u[0]), float(u[1])
    k = float(arc_factor(dth))
    h = _direction(pose, u)
    c, s = np.cos(h), np.sin(h)
    F = np.array([[1.0, 0.0, -d * k * s], [0.0, 1.0, d * k * c], [0.0, 0.0, 1.0]])
    dk = _dsinc_half(dth)
    V = np.array([
        [k * c, d * (dk * c - 0.5 * k * s)],
        [k * s, d * (dk * s + 0.5 * k * c)],
        [0.0, 1.0],
    ])
    return F, V


def _measurement_scales(values: Any, n: int) -> np.ndarray:
    """Per-frame measurement scales (n,), finite and >= 1 (ValueError else)."""
    a = as_real_array(values, "measurement_scale").astype(np.float64).reshape(-1)
    if a.shape != (n,):
        raise ValueError(f"measurement_scale must hold one factor per frame ({n}), got shape {a.shape}")
    if not np.isfinite(a).all() or (a < 1).any():
        raise ValueError("measurement_scale must be finite factors >= 1 on the measurement noise")
    return a


def _chi2_2dof(p: float) -> float:
    return float(-2.0 * np.log1p(-p))


_H = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _hjac(x: Any) -> np.ndarray:
    return _H


def _hx(x: Any) -> np.ndarray:
    return _H @ x


@dataclass(frozen=True)
class FilterStep:
    """The filter's account of one frame (:meth:`OdometryEKF.step`).

    Attributes
    ----------
    pose : ndarray (3,)
        Fused pose ``(x [m], y [m], theta [rad])``, heading wrapped.
    covariance : ndarray (3, 3)
        Its posterior covariance (m^2, m rad, rad^2).
    mahalanobis : float
        Mahalanobis distance of the estimate's innovation (NaN: no estimate).
    gated, reinitialized, jumped : bool
        The estimate was gated; the filter re-initialised from the recent
        estimates; the step leading here was a jump.
    events : tuple of FilterEvent
        This frame's events, ``frame`` counting the frames since :meth:`OdometryEKF.start`.
    """

    pose: np.ndarray
    covariance: np.ndarray
    mahalanobis: float
    gated: bool
    reinitialized: bool
    jumped: bool
    events: tuple




_FILTER_CLASS: Any = None


def _ctrv_filter_class() -> Any:
    """filterpy's ExtendedKalmanFilter with the CTRV state prediction
    (filterpy's own ``predict_x`` is linear, ``F x + B u``)."""
    global _FILTER_CLASS
    if _FILTER_CLASS is None:
        from filterpy.kalman import ExtendedKalmanFilter

        class CTRVFilter(ExtendedKalmanFilter):
            def predict_x(self, u: Any = 0) -> None:
                self.x = ctrv_motion(self.x[:, 0], u).reshape(3, 1)

        _FILTER_CLASS = CTRVFilter
    return _FILTER_CLASS


class OdometryEKF:
    """EKF fusing odometry (prediction, CTRV model) with absolute SFA position
    estimates (update), thesis 5.3.2.

    Parameters
    ----------
    distance_noise : float, default 0.01
        Standard deviation of the odometry distance of one step, metres.
    heading_noise : float, default 0.01
        Standard deviation of the odometry heading change of one step, radians.
    measurement_noise : float, default 0.2
        Standard deviation of each coordinate of an SFA estimate, metres.
    turn_noise : float, default 0
        Extra heading noise proportional to the turn: a step that turns by
        dtheta radians adds ``turn_noise**2 * |dtheta|`` to the heading
        variance (rad per sqrt(rad); wheel odometry errs most in turns).
        0: the thesis's model (per-step noise only).
    initial_std : (float, float), default (0.01, 0.01)
        Standard deviation of the start position (metres, each axis) and
        heading (radians): the start pose is known (thesis).
    process_floor : float, default 1e-9
        Added to the diagonal of Q (numerical safety).
    gate_probability : float or None, default None
        Mahalanobis gating of outlying SFA estimates (see the module
        docstring); e.g. 0.999. None: every estimate is used (thesis).
    max_consecutive_gated : int, default 20
        After this many gated estimates in a row the next one is accepted.
    reinit_after : int or None, default 4
        Re-initialise after this many inconsistent estimates in a row
        (frames with estimates; missing ones neither count nor break the
        run). None: never (the filter before recovery existed).
    divergence_probability : float, default 0.999
        An estimate is inconsistent when its squared Mahalanobis distance
        exceeds the chi-square quantile (2 dof) of this probability
        (independent of the gate: it counts when gating is off too).
    nis_window : int or None, default None
        Windowed innovation test: re-initialise when the sum of the last
        ``nis_window`` accepted (consistent) normalised innovations squared
        exceeds the chi-square quantile (``2 nis_window`` dof) of
        ``nis_probability``; catches a filter that is biased without being
        gated. None: off (a measurement noise chosen too small would fire it).
    nis_probability : float, default 1 - 1e-6
    reinit_std : (float or None, float), default (None, 0.2)
        Standard deviation of the position (metres, each axis; None: twice
        ``measurement_noise``) and heading (radians) after a
        re-initialisation. The heading comes from the rigid fit when the
        frames span at least 5 ``measurement_noise`` metres, else it is
        kept and its standard deviation doubled.
    gap_factor : float or None, default 3
        A step spanning more than this many nominal steps (by ``stamps``,
        else by its distance against the run's median step) has its
        odometry noise variance multiplied by that many. None: off.
    jump_factor : float or None, default 8
        A step longer than this many nominal steps is a jump (see
        :func:`sfanav.odometry.recovery.step_anomalies`). None: off.

    Attributes (after :meth:`run`)
    ----------
    poses_ : ndarray (N, 3)
        Fused poses ``(x [m], y [m], theta [rad])`` (headings wrapped).
    covariances_ : ndarray (N, 3, 3)
        Posterior covariances.
    gated_ : ndarray of bool (N,)
        True where an available SFA estimate was rejected by the gate.
    n_gated_ : int
        Number of gated estimates.
    n_missing_ : int
        Number of rows of NaN in the measurements (no estimate).
    mahalanobis_ : ndarray (N,)
        Mahalanobis distance of each innovation (NaN where missing).
    log_likelihood_ : float
        Sum of the innovations' Gaussian log-likelihoods over the accepted
        updates (for tuning the noise without ground truth).
    reinitialized_ : ndarray of bool (N,)
        True where the filter re-initialised from the estimates.
    n_reinitializations_ : int
    jumps_ : ndarray of bool (N,)
        True at frames reached by a jump step.
    events_ : list of FilterEvent
        Re-initialisations, jumps and gaps in frame order.

    Example
    -------
    >>> t = np.arange(40.0)
    >>> truth = np.c_[t, np.zeros(40), np.zeros(40)]
    >>> truth[20:, 1] += 20.0                          # kidnapped: carried 20 m sideways
    >>> odometry = np.c_[t, np.zeros(40), np.zeros(40)]   # the wheels saw nothing
    >>> ekf = OdometryEKF(0.02, 0.01, 0.2, gate_probability=0.999)
    >>> poses = ekf.run(odometry, truth[:, :2], truth[0])
    >>> ekf.n_reinitializations_, bool(abs(poses[-1, 1] - 20) < 0.5)
    (1, True)
    """

    def __init__(
        self,
        distance_noise: float = 0.01,
        heading_noise: float = 0.01,
        measurement_noise: float = 0.2,
        *,
        turn_noise: float = 0.0,
        initial_std: tuple[float, float] = (0.01, 0.01),
        process_floor: float = 1e-9,
        gate_probability: float | None = None,
        max_consecutive_gated: int = 20,
        reinit_after: int | None = 4,
        divergence_probability: float = 0.999,
        nis_window: int | None = None,
        nis_probability: float = 1 - 1e-6,
        reinit_std: tuple[float | None, float] = (None, 0.2),
        gap_factor: float | None = 3.0,
        jump_factor: float | None = 8.0,
    ) -> None:
        self.distance_noise = distance_noise
        self.heading_noise = heading_noise
        self.measurement_noise = measurement_noise
        self.turn_noise = turn_noise
        self.initial_std = initial_std
        self.process_floor = process_floor
        self.gate_probability = gate_probability
        self.max_consecutive_gated = max_consecutive_gated
        self.reinit_after = reinit_after
        self.divergence_probability = divergence_probability
        self.nis_window = nis_window
        self.nis_probability = nis_probability
        self.reinit_std = reinit_std
        self.gap_factor = gap_factor
        self.jump_factor = jump_factor

    _PARAMS = ("distance_noise", "heading_noise", "measurement_noise", "turn_noise", "initial_std", "process_floor",
               "gate_probability", "max_consecutive_gated", "reinit_after", "divergence_probability", "nis_window",
               "nis_probability", "reinit_std", "gap_factor", "jump_factor")

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self._PARAMS}

    def set_params(self, **params: Any) -> "OdometryEKF":
        for k, v in params.items():
            if k not in self._PARAMS:
                raise ValueError(f"unknown parameter {k!r} for OdometryEKF")
            setattr(self, k, v)
        return self

    def __repr__(self) -> str:
        return (
            f"OdometryEKF(distance_noise={self.distance_noise!r}, heading_noise={self.heading_noise!r}, "
            f"measurement_noise={self.measurement_noise!r}, turn_noise={self.turn_noise!r}, "
            f"gate_probability={self.gate_probability!r})"
        )

    def _check(self) -> tuple[float, float, float, float, np.ndarray, float, float | None, int]:
        sd = check_nonneg_float(self.distance_noise, "distance_noise")
        sh = check_nonneg_float(self.heading_noise, "heading_noise")
        sr = check_nonneg_float(self.measurement_noise, "measurement_noise")
        st = check_nonneg_float(self.turn_noise, "turn_noise")
        if sr == 0:
            raise ValueError("measurement_noise must be > 0 (metres)")
        init = as_real_array(self.initial_std, "initial_std").astype(np.float64).ravel()
        if init.shape != (2,) or not np.all(np.isfinite(init)) or np.any(init < 0):
            raise ValueError(f"initial_std must be (position std [m], heading std [rad]) >= 0, got {self.initial_std!r}")
        floor = check_nonneg_float(self.process_floor, "process_floor")
        gp = self.gate_probability
        gate = None
        if gp is not None:
            gp = float(gp)
            if not 0 < gp < 1:
                raise ValueError(f"gate_probability must be in (0, 1) or None, got {self.gate_probability!r}")
            gate = _chi2_2dof(gp)
        mcg = check_int(self.max_consecutive_gated, "max_consecutive_gated", minimum=0)
        P0 = np.diag([init[0] ** 2, init[0] ** 2, init[1] ** 2]) + floor * np.eye(3)
        return sd, sh, sr, st, P0, floor, gate, mcg

    def _check_recovery(self, sr: float) -> dict[str, Any]:
        """The recovery parameters, validated (ValueError/TypeError naming the bad one)."""
        from scipy.stats import chi2

        ra = None if self.reinit_after is None else check_int(self.reinit_after, "reinit_after", minimum=1)
        dp = float(self.divergence_probability)
        if not 0 < dp < 1:
            raise ValueError(f"divergence_probability must be in (0, 1), got {self.divergence_probability!r}")
        nw = None if self.nis_window is None else check_int(self.nis_window, "nis_window", minimum=2)
        npb = float(self.nis_probability)
        if not 0 < npb < 1:
            raise ValueError(f"nis_probability must be in (0, 1), got {self.nis_probability!r}")
        rs = self.reinit_std
        if not isinstance(rs, (tuple, list)) or len(rs) != 2:
            raise ValueError(f"reinit_std must be (position std [m] or None, heading std [rad]), got {rs!r}")
        ps = 2.0 * sr if rs[0] is None else check_positive_float(rs[0], "reinit_std[0]")
        hs = check_positive_float(rs[1], "reinit_std[1]")
        return {"reinit_after": ra, "divergence": _chi2_2dof(dp), "nis_window": nw,
                "nis_bound": None if nw is None else float(chi2.ppf(npb, 2 * nw)),
                "position_std": ps, "heading_std": hs}

    def run(self, odometry: Any, measurements: Any, start_pose: Any, stamps: Any = None, *, gyro: Any = None,
            gyro_noise: Any = None, measurement_scale: Any = None) -> np.ndarray:
        """Filters one run.

        Parameters
        ----------
        odometry : array (N, 3)
            Odometry poses ``(x [m], y [m], theta [rad])`` in the odometry's own
            frame; only their increments are used (re-anchored at
            ``start_pose``).
        measurements : array (N, 2)
            SFA position estimates in metres, in the frame of ``start_pose``;
            rows of NaN are missing estimates (prediction only).
        start_pose : array (3,)
            Known start pose ``(x [m], y [m], theta [rad])`` of the first sample.
        stamps : array (N,), optional
            Frame times in seconds, increasing: steps over dropped frames are
            found by their duration (without: by their length).
        gyro : array (N,), optional
            A yaw gyro's integrated heading (rad, :attr:`sfanav.Dataset.gyro`):
            each step's turn in the prediction is the inverse-variance
            fusion of the odometry's (variance ``heading_noise**2 +
            turn_noise**2 |dtheta|``) and the gyro's, with the fused
            variance (:func:`sfanav.odometry.gyro.fuse_turns`).
        gyro_noise : mapping, optional
            The gyro's noise model (:data:`sfanav.odometry.gyro.DEFAULT_GYRO_NOISE`).
        measurement_scale : array (N,), optional
            Per frame, a factor >= 1 on the measurement's standard deviation
            (``measurement_noise`` times it; e.g.
            :func:`sfanav.odometry.fusion.novelty_scale` of the images'
            novelty): the gate, the divergence test and the update all see
            the scaled noise. None: 1 everywhere.

        Returns
        -------
        ndarray (N, 3)
            Fused poses (also in ``poses_``).
        """
        P = as_poses(odometry, min_rows=1)
        Z = as_real_array(measurements, "measurements").astype(np.float64, copy=False)
        if Z.ndim != 2 or Z.shape[1] != 2:
            raise ValueError(f"measurements must have shape (N, 2) (x, y in metres), got shape {Z.shape}")
        check_same_length(P, Z, "odometry", "measurements")
        if np.isinf(Z).any():
            raise ValueError("measurements contain infinity (use NaN rows for missing estimates)")
        ms = np.ones(len(P)) if measurement_scale is None else _measurement_scales(measurement_scale, len(P))
        s0 = as_real_array(start_pose, "start_pose").astype(np.float64).ravel()
        if s0.shape != (3,):
            raise ValueError(f"start_pose must be (x [m], y [m], heading [rad]), got shape {s0.shape}")
        check_finite(s0, "start_pose")
        sd, sh, sr, st, *_ = self._check()
        self._check_recovery(sr)
        U = increments(P, direction=True) if len(P) > 1 else np.zeros((0, 3))
        turn_var = sh**2 + st**2 * np.abs(U[:, 1])
        if gyro is not None:
            from .gyro import as_gyro, fuse_turns

            U = U.copy()
            U[:, 1], turn_var, _ = fuse_turns(U[:, 1], turn_var + 1e-14, np.diff(as_gyro(gyro, len(P))), np.abs(U[:, 0]),
                                              gyro_noise)
        if stamps is not None and len(np.ravel(np.asarray(stamps))) != len(P):
            raise ValueError(f"stamps must have one time per frame ({len(P)}), got {len(np.ravel(np.asarray(stamps)))}")
        scale, jump = step_anomalies(U[:, :2], stamps, gap_factor=self.gap_factor, jump_factor=self.jump_factor)
        self.start(s0)
        N = len(P)
        poses = np.empty((N, 3))
        covs = np.empty((N, 3, 3))
        gated = np.zeros(N, bool)
        reinit = np.zeros(N, bool)
        jumped = np.zeros(N, bool)
        maha = np.full(N, np.nan)
        events: list[FilterEvent] = []
        for k in range(N):
            st_k = self._advance(P[k], Z[k], *((U[k - 1], turn_var[k - 1], scale[k - 1], bool(jump[k - 1]))
                                               if k > 0 else (None, 0.0, 1.0, False)), float(ms[k]))
            poses[k], covs[k], maha[k] = st_k.pose, st_k.covariance, st_k.mahalanobis
            gated[k], reinit[k], jumped[k] = st_k.gated, st_k.reinitialized, st_k.jumped
            events.extend(st_k.events)
        self.poses_ = poses
        self.covariances_ = covs
        self.gated_ = gated
        self.n_gated_ = int(gated.sum())
        self.n_missing_ = self._live["n_missing"]
        self.mahalanobis_ = maha
        self.log_likelihood_ = float(self._live["loglik"])
        self.reinitialized_ = reinit
        self.n_reinitializations_ = int(reinit.sum())
        self.jumps_ = jumped
        self.events_ = events
        return poses

    def start(self, start_pose: Any) -> "OdometryEKF":
        """Starts filtering online at ``start_pose`` (3,) ``(x [m], y [m],
        theta [rad])``, the pose of the first frame given to :meth:`step`.
        Validates the parameters (ValueError/TypeError naming a bad one).
        :meth:`run` is this and one :meth:`step` per frame."""
        s0 = as_real_array(start_pose, "start_pose").astype(np.float64).ravel()
        if s0.shape != (3,):
            raise ValueError(f"start_pose must be (x [m], y [m], heading [rad]), got shape {s0.shape}")
        check_finite(s0, "start_pose")
        sd, sh, sr, st, P0, floor, gate, mcg = self._check()
        rec = self._check_recovery(sr)
        ekf = _ctrv_filter_class()(dim_x=3, dim_z=2)
        ekf.x = s0.reshape(3, 1).copy()
        ekf.P = P0.copy()
        ekf.R = sr**2 * np.eye(2)
        self._live = {"ekf": ekf, "sd": sd, "sh": sh, "st": st, "floor": floor, "gate": gate, "mcg": mcg,
                      "rec": rec, "min_spread": 5.0 * sr, "k": 0, "last": None, "streak": 0, "n_missing": 0,
                      "loglik": 0.0, "bad_run": [], "nis": [], "recent": {}}
        return self

    def step(self, odometry_pose: Any, measurement: Any, *, scale: float = 1.0, jump: bool = False,
             measurement_scale: float = 1.0) -> "FilterStep":
        """One frame online (after :meth:`start`): the prediction by the
        odometry increment from the previous frame's odometry pose to
        ``odometry_pose`` (3,) (none on the first frame), then the update by
        ``measurement`` (2,) metres (NaN: none). ``scale`` (>= 1) multiplies
        the step's odometry noise variance (a gap) and ``jump`` treats its
        displacement as unknown (:func:`sfanav.odometry.recovery.step_anomalies`
        decides both in :meth:`run`). Returns the frame's :class:`FilterStep`:
        the numbers :meth:`run` gives for the frames so far with those scales
        and jumps. ``measurement_scale`` (>= 1) multiplies the measurement's
        standard deviation (:meth:`run`'s ``measurement_scale``). Memory
        stays bounded however many frames are stepped.

        Example
        -------
        >>> ekf = OdometryEKF(0.02, 0.01, 0.2).start((0.0, 0.0, 0.0))
        >>> r = ekf.step((0.0, 0.0, 0.0), (0.1, 0.0))
        >>> r = ekf.step((1.0, 0.0, 0.0), (1.0, 0.0))
        >>> r.pose.shape, r.covariance.shape
        ((3,), (3, 3))
        """
        if getattr(self, "_live", None) is None:
            raise ValueError("step needs start(start_pose) first")
        p = as_real_array(odometry_pose, "odometry_pose").astype(np.float64).ravel()
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"odometry_pose must be a finite (x [m], y [m], heading [rad]), got {odometry_pose!r}")
        z = as_real_array(measurement, "measurement").astype(np.float64).ravel()
        if z.shape != (2,) or np.isinf(z).any():
            raise ValueError(f"measurement must be (x, y) in metres or NaN (none), got {measurement!r}")
        sc = float(scale)
        if not (np.isfinite(sc) and sc >= 1):
            raise ValueError(f"scale must be a number >= 1 (nominal steps), got {scale!r}")
        msc = float(_measurement_scales([measurement_scale], 1)[0])
        lv = self._live
        u, tv = None, 0.0
        if lv["last"] is not None:
            u = increments(np.stack([lv["last"], p]), direction=True)[0]
            tv = lv["sh"] ** 2 + lv["st"] ** 2 * abs(float(u[1]))
        return self._advance(p, z, u, tv, sc, bool(jump), msc)

    def _advance(self, pose: np.ndarray, z: np.ndarray, u: Any, turn_var: float, scale: float,
                 jump: bool, measurement_scale: float = 1.0) -> "FilterStep":
        """Predicts by the increment u (None on the first frame) and updates by z: the recursion of :meth:`run`."""
        lv = self._live
        ekf, rec, floor = lv["ekf"], lv["rec"], lv["floor"]
        k = lv["k"]
        events: list[FilterEvent] = []
        jumped = gated = reinit = False
        maha = np.nan
        if u is not None:
            x = ekf.x[:, 0]
            F, V = ctrv_jacobians(x, u)
            ekf.F = F
            Mk = np.diag([lv["sd"] ** 2, turn_var]) * scale
            Q = V @ Mk @ V.T + floor * np.eye(3)
            if scale > 1:
                events.append(FilterEvent(k, "gap", float(scale)))
            if jump:  # the displacement is unknown within its own length
                Q[:2, :2] += u[0] ** 2 * np.eye(2)
                jumped = True
                events.append(FilterEvent(k, "jump", float(abs(u[0]))))
                lv["bad_run"], lv["nis"] = [], []  # the odometry across a jump does not tie frames together
            ekf.Q = Q
            ekf.predict(u=u)  # x = ctrv_motion(x, u), P = F P F^T + Q
        if np.isnan(z).any():
            lv["n_missing"] += 1
        else:
            lv["recent"][k] = (pose, z)
            R = ekf.R * measurement_scale**2
            y = z - ekf.x[:2, 0]
            S = ekf.P[:2, :2] + R
            m2 = float(y @ np.linalg.solve(S, y))
            maha = np.sqrt(m2)
            lv["bad_run"] = lv["bad_run"] + [k] if m2 > rec["divergence"] else []
            trigger, window = None, []
            if rec["reinit_after"] is not None and len(lv["bad_run"]) >= rec["reinit_after"]:
                trigger, window = "divergence", lv["bad_run"]
            elif rec["nis_window"] is not None and m2 <= rec["divergence"]:
                lv["nis"] = (lv["nis"] + [(k, m2)])[-rec["nis_window"]:]
                if len(lv["nis"]) == rec["nis_window"] and sum(v for _, v in lv["nis"]) > rec["nis_bound"]:
                    trigger, window = "innovation", [j for j, _ in lv["nis"]]
            if trigger is not None:
                old = ekf.x[:2, 0].copy()
                Pw = np.array([lv["recent"][j][0] for j in window])
                Zw = np.array([lv["recent"][j][1] for j in window])
                self._reinitialize(ekf, Pw, Zw, rec, lv["min_spread"], floor)
                reinit = True
                events.append(FilterEvent(k, trigger, float(np.hypot(*(ekf.x[:2, 0] - old)))))
                lv["bad_run"], lv["nis"], lv["streak"] = [], [], 0
            elif lv["gate"] is not None and m2 > lv["gate"] and lv["streak"] < lv["mcg"]:
                gated = True
                lv["streak"] += 1
            else:
                lv["streak"] = 0
                ekf.update(z.reshape(2, 1), _hjac, _hx, R=R)
                lv["loglik"] += -0.5 * (m2 + np.log(np.linalg.det(S)) + 2 * np.log(2 * np.pi))
        keep = set(lv["bad_run"]) | {j for j, _ in lv["nis"]}  # the frames a re-initialisation may fit
        for j in [j for j in lv["recent"] if j not in keep]:
            del lv["recent"][j]
        ekf.x[2, 0] = wrap_angle(ekf.x[2, 0])
        lv["k"], lv["last"] = k + 1, pose
        return FilterStep(ekf.x[:, 0].copy(), ekf.P.copy(), float(maha), gated, reinit, jumped, tuple(events))

    @staticmethod
    def _reinitialize(ekf: Any, Pw: np.ndarray, Zw: np.ndarray, rec: dict[str, Any], min_spread: float,
                      floor: float) -> None:
        """Moves the filter to the pose of the window's odometry poses Pw (n, 3)
        and estimates Zw (n, 2) (the last row is the current frame) with the
        re-initialisation covariance."""
        pose, known = pose_from_window(Pw, Zw, min_spread=min_spread)
        hs = rec["heading_std"]
        if not known:  # heading kept: the estimates moved to the current frame by the odometry in that heading
            th = float(ekf.x[2, 0])
            a = th - Pw[-1, 2]
            rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            moved = Zw + (Pw[-1, :2] - Pw[:, :2]) @ rot.T
            pose = np.array([*np.median(moved, axis=0), th])
            hs = 2.0 * hs
        ps = rec["position_std"]
        ekf.x = pose.reshape(3, 1)
        ekf.P = np.diag([ps**2, ps**2, hs**2]) + floor * np.eye(3)

    @staticmethod
    def dead_reckoning(odometry: Any, start_pose: Any) -> np.ndarray:
        """Odometry alone re-anchored at the start pose: (N, 3) poses (what the
        filter predicts without measurements)."""
        return dead_reckon(increments(as_poses(odometry), direction=True), start_pose)


@dataclass
class GridSearchResult:
    """Outcome of :func:`grid_search`.

    Attributes
    ----------
    best_params : dict
        ``distance_noise``, ``heading_noise``, ``measurement_noise`` of the best run.
    best_score : float
        Its score: MED in metres (``criterion="med"``) or the negative
        log-likelihood of the innovations (``"nll"``).
    criterion : str
    results : list of dict
        One per grid point: the three noise values and ``score`` (and ``med``
        when ground truth was given).
    best_poses : ndarray (N, 3)
        The best run's fused poses.
    time : float
        Wall time in seconds.
    """

    best_params: dict[str, float]
    best_score: float
    criterion: str
    results: list[dict[str, float]]
    best_poses: np.ndarray
    time: float


def _grid(values: Any, name: str) -> list[float]:
    vals = [float(v) for v in (values if isinstance(values, Iterable) else [values])]
    if not vals or any(not np.isfinite(v) or v < 0 for v in vals):
        raise ValueError(f"{name} must be one or more finite values >= 0, got {values!r}")
    return vals


def grid_search(
    odometry: Any,
    measurements: Any,
    start_pose: Any,
    xy_true: Any = None,
    *,
    distance_noise: Iterable[float] = (0.003, 0.01, 0.03),
    heading_noise: Iterable[float] = (0.003, 0.01, 0.03),
    measurement_noise: Iterable[float] = (0.05, 0.1, 0.2, 0.4),
    criterion: str | None = None,
    ekf_params: Mapping[str, Any] | None = None,
    progress: bool = True,
    measurement_scale: Any = None,
) -> GridSearchResult:
    """Chooses the process and measurement noise of :class:`OdometryEKF` by
    grid search (thesis 5.3.2: "chosen based on a grid search").

    Parameters
    ----------
    odometry, measurements, start_pose
        As :meth:`OdometryEKF.run`.
    xy_true : array (N, 2), optional
        Ground-truth positions in metres (a calibration run).
    distance_noise, heading_noise, measurement_noise : iterables of float
        Candidate standard deviations: metres per step, radians per step, metres.
    criterion : {"med", "nll"} or None
        ``"med"``: the smallest mean Euclidean distance from ``xy_true``
        (needs it; what the thesis did). ``"nll"``: the smallest negative
        log-likelihood of the innovations, which needs no ground truth.
        Default: "med" with ground truth, else "nll".
    ekf_params : mapping, optional
        Other :class:`OdometryEKF` parameters (e.g. ``gate_probability``).
    progress : bool, default True
        A tqdm progress bar over the grid.
    measurement_scale : array (N,), optional
        Per-frame factors on the measurement noise (:meth:`OdometryEKF.run`):
        the grid's ``measurement_noise`` is then the noise of a frame with
        factor 1.
    """
    t0 = time.perf_counter()
    if criterion is None:
        criterion = "med" if xy_true is not None else "nll"
    if criterion not in ("med", "nll"):
        raise ValueError(f"criterion must be 'med' or 'nll', got {criterion!r}")
    T = None
    if xy_true is not None:
        T = as_matrix(xy_true, "xy_true", n_cols=2)
        check_same_length(T, as_poses(odometry, min_rows=1), "xy_true", "odometry")
    elif criterion == "med":
        raise ValueError("criterion='med' needs ground truth: pass xy_true, or use criterion='nll'")
    grid = list(itertools.product(_grid(distance_noise, "distance_noise"), _grid(heading_noise, "heading_noise"),
                                  _grid(measurement_noise, "measurement_noise")))
    bar = progress_bar(progress, len(grid), "EKF grid search", unit="run")
    results = []
    best = None
    try:
        for sd, sh, sr in grid:
            ekf = OdometryEKF(sd, sh, sr, **dict(ekf_params or {}))
            poses = ekf.run(odometry, measurements, start_pose, measurement_scale=measurement_scale)
            row = {"distance_noise": sd, "heading_noise": sh, "measurement_noise": sr}
            if T is not None:
                row["med"] = float(np.linalg.norm(poses[:, :2] - T, axis=1).mean())
            row["nll"] = -ekf.log_likelihood_
            row["score"] = row[criterion]
            results.append(row)
            if best is None or row["score"] < best[0]["score"]:
                best = (row, poses)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    assert best is not None
    bp = {k: best[0][k] for k in ("distance_noise", "heading_noise", "measurement_noise")}
    return GridSearchResult(bp, float(best[0]["score"]), criterion, results, best[1], time.perf_counter() - t0)
