"""The simulated robot: unicycle kinematics, camera mounts and wheel odometry.

Poses are (x, y, heading): metres and radians, heading counter-clockwise
from +x. Camera offsets are (forward, left) in metres in the robot frame.

Odometry follows the rotate-translate-rotate motion model: each step between
two poses is a first rotation, a straight translation and a second rotation;
each part is corrupted by noise whose variance grows with the distance
travelled or the angle turned, plus a systematic scale error, a systematic
heading drift per metre (unequal wheel diameters) and occasional wheel slip;
optionally per-step terms as a mower's odometry is usually specified (a
distance error proportional to the step, a heading error of ``a + b * |turn|``
per step: :meth:`OdometryNoise.mower`).
Integrated from a known start pose (as in thesis 5.3.2, where the robot starts
at its base station) dead reckoning drifts without bound, mostly through
heading errors, as in the thesis's figure 5.24. With all noise terms zero it
reproduces the true poses exactly.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

import numpy as np


def wrap_angle(a: Any) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(a, float) + np.pi) % (2 * np.pi) - np.pi


def check_poses(poses: Any, name: str = "poses") -> np.ndarray:
    """``poses`` as a float (N, 3) array of finite (x, y, heading)."""
    try:
        P = np.asarray(poses, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of (x, y, heading) rows") from None
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) = (x m, y m, heading rad), got {P.shape}")
    if not np.isfinite(P).all():
        bad = int(np.nonzero(~np.isfinite(P).all(axis=1))[0][0])
        raise ValueError(f"{name} has a NaN or infinite value in row {bad}")
    return P


def unicycle_step(pose: Sequence[float], v: float, omega: float, dt: float) -> np.ndarray:
    """Exact unicycle motion: forward speed ``v`` (m/s) and turn rate
    ``omega`` (rad/s) held for ``dt`` seconds from ``pose``; returns the new
    (x, y, heading)."""
    x, y, th = (float(p) for p in pose)
    dth = omega * dt
    if abs(dth) < 1e-12:
        return np.array([x + v * dt * np.cos(th), y + v * dt * np.sin(th), th])
    r = v / omega
    return np.array([x + r * (np.sin(th + dth) - np.sin(th)), y - r * (np.cos(th + dth) - np.cos(th)), th + dth])


@dataclass(frozen=True)
class OdometryNoise:
    """Wheel-odometry error model (all terms independent per step).

    Attributes
    ----------
    distance_sigma : float
        m / sqrt(m): the distance error is a random walk with standard
        deviation ``distance_sigma * sqrt(L)`` after L metres.
    scale_error : float
        Systematic fraction: odometry reports ``(1 + scale_error)`` times the
        true distance (wheel radius miscalibration).
    heading_sigma : float
        rad / sqrt(m): heading random walk per distance travelled.
    turn_sigma : float
        rad / sqrt(rad): heading random walk per angle turned.
    heading_drift : float
        rad / m: systematic heading error per metre travelled (positive: the
        odometry believes the robot turned left).
    slip_rate : float
        Slip events per metre travelled (Poisson).
    slip_distance : float
        m: mean extra distance the encoders report at a slip (exponential).
    slip_heading_sigma : float
        rad: heading error at a slip.
    distance_fraction : float
        Per step: the distance error's standard deviation is this fraction
        of the step's length (``0.02``: 2 %). Default 0 (off).
    step_heading_sigma : float
        rad per step: heading error of every step that moves or turns, the
        ``a`` of ``sigma = a + b * |turn|``. Default 0 (off).
    turn_fraction : float
        rad per rad: the ``b`` of ``sigma = a + b * |turn|``, the heading
        error growing linearly with the step's turn. Default 0 (off).

    The per-step terms (the last three) depend on how far apart the frames
    are; the others are per metre or per radian. With the per-step terms at
    0 (the default) the model and its random draws are exactly those of
    the earlier versions, so seeded datasets stay as they were.

    Examples
    --------
    >>> noise = OdometryNoise.mower(distance_fraction=0.02, heading_deg=0.5, drift_deg_per_m=0.1)
    >>> round(float(np.degrees(noise.heading_drift)), 3)
    0.1
    """

    distance_sigma: float = 0.01
    scale_error: float = 0.005
    heading_sigma: float = 0.004
    turn_sigma: float = 0.01
    heading_drift: float = 0.002
    slip_rate: float = 0.01
    slip_distance: float = 0.05
    slip_heading_sigma: float = 0.02
    distance_fraction: float = 0.0
    step_heading_sigma: float = 0.0
    turn_fraction: float = 0.0

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise TypeError(f"OdometryNoise.{k} must be a number, got {v!r}")
            if not np.isfinite(v):
                raise ValueError(f"OdometryNoise.{k} must be finite, got {v}")
            if k not in ("scale_error", "heading_drift") and v < 0:
                raise ValueError(f"OdometryNoise.{k} must be >= 0, got {v}")

    @classmethod
    def none(cls) -> "OdometryNoise":
        """Perfect odometry (reproduces the true poses)."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    @classmethod
    def mower(cls, distance_fraction: float = 0.02, heading_deg: float = 0.5, drift_deg_per_m: float = 0.1, *,
              turn_fraction: float = 0.01, slip_rate: float = 0.0, slip_distance: float = 0.5,
              slip_heading_deg: float = 0.0) -> "OdometryNoise":
        """A lawn mower's wheel odometry, specified per frame.

        Parameters
        ----------
        distance_fraction : float
            Standard deviation of each step's distance error as a fraction
            of the step (0.02: 2 %).
        heading_deg : float
            Standard deviation of each step's heading error (degrees), the
            ``a`` of ``sigma = a + b * |turn|``.
        drift_deg_per_m : float
            Systematic heading drift (degrees per metre; 0.05-0.3 is typical
            of unequal wheels and tyre wear; positive: the odometry believes
            the robot turned left).
        turn_fraction : float
            The ``b`` of ``sigma = a + b * |turn|`` (radians per radian).
        slip_rate : float
            Wheel-slip events per metre (Poisson); 0: none.
        slip_distance : float
            Mean extra distance (m, exponential) the encoders count at a slip
            (the wheels spin).
        slip_heading_deg : float
            Standard deviation of the heading error at a slip (degrees).

        Returns
        -------
        OdometryNoise
            Every other term (the per-metre random walks, the scale error) 0.

        Raises
        ------
        ValueError
            A negative or non-finite value (the drift may be negative).
        """
        return cls(distance_sigma=0.0, scale_error=0.0, heading_sigma=0.0, turn_sigma=0.0,
                   heading_drift=float(np.radians(drift_deg_per_m)), slip_rate=slip_rate,
                   slip_distance=slip_distance, slip_heading_sigma=float(np.radians(slip_heading_deg)),
                   distance_fraction=distance_fraction, step_heading_sigma=float(np.radians(heading_deg)),
                   turn_fraction=turn_fraction)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def simulate_odometry(poses: Any, noise: OdometryNoise | None = None,
                      rng: np.random.Generator | int | None = None) -> np.ndarray:
    """Dead-reckoned poses from noisy wheel odometry along true ``poses``.

    Parameters
    ----------
    poses : array (N, 3)
        True (x m, y m, heading rad), consecutive frames.
    noise : OdometryNoise
        Default ``OdometryNoise()``.
    rng : numpy Generator or int seed

    Returns
    -------
    ndarray (N, 3): odometry pose estimates, starting at the true first pose.
    """
    P = check_poses(poses)
    noise = OdometryNoise() if noise is None else noise
    if not isinstance(noise, OdometryNoise):
        raise TypeError(f"noise must be an OdometryNoise, got {type(noise).__name__}")
    rng = np.random.default_rng(rng)
    n = len(P)
    out = np.empty_like(P)
    if n == 0:
        return out
    out[0] = P[0]
    if n == 1:
        return out
    dx, dy = np.diff(P[:, 0]), np.diff(P[:, 1])
    trans = np.hypot(dx, dy)
    dth = wrap_angle(np.diff(P[:, 2]))
    moving = trans > 1e-12
    rot1 = np.where(moving, wrap_angle(np.arctan2(dy, dx) - P[:-1, 2]), 0.0)
    back = np.abs(rot1) > np.pi / 2  # driving backwards
    rot1 = np.where(back, wrap_angle(rot1 - np.pi), rot1)
    trans = np.where(back, -trans, trans)
    rot2 = wrap_angle(dth - rot1)
    m = np.abs(trans)
    z = rng.standard_normal((4, n - 1))
    trans_o = trans * (1 + noise.scale_error) + noise.distance_sigma * np.sqrt(m) * z[0]
    rot1_o = rot1 + noise.turn_sigma * np.sqrt(np.abs(rot1)) * z[1]
    rot2_o = (rot2 + noise.turn_sigma * np.sqrt(np.abs(rot2)) * z[2]
              + noise.heading_sigma * np.sqrt(m) * z[3] + noise.heading_drift * m)
    if noise.distance_fraction > 0 or noise.step_heading_sigma > 0 or noise.turn_fraction > 0:
        # per-step terms, drawn only when set (the earlier draws stay as they were)
        zs = rng.standard_normal((2, n - 1))
        active = moving | (np.abs(dth) > 1e-12)
        trans_o = trans_o + noise.distance_fraction * m * zs[0]
        rot2_o = rot2_o + np.where(active, noise.step_heading_sigma + noise.turn_fraction * np.abs(dth), 0.0) * zs[1]
    if noise.slip_rate > 0:
        k = rng.poisson(noise.slip_rate * m)
        slips = np.nonzero(k)[0]
        for i in slips:
            trans_o[i] += np.sign(trans[i]) * rng.exponential(noise.slip_distance, k[i]).sum()
            rot2_o[i] += noise.slip_heading_sigma * rng.standard_normal(k[i]).sum()
    th = P[0, 2] + np.concatenate([[0.0], np.cumsum(rot1_o + rot2_o)])
    move_dir = th[:-1] + rot1_o
    out[1:, 0] = P[0, 0] + np.cumsum(trans_o * np.cos(move_dir))
    out[1:, 1] = P[0, 1] + np.cumsum(trans_o * np.sin(move_dir))
    out[:, 2] = th
    return out


@dataclass(frozen=True)
class GyroNoise:
    """Error model of a yaw gyro (the z axis of a mower's IMU), integrated
    between frames.

    Attributes
    ----------
    angle_random_walk : float
        rad / sqrt(s): white rate noise; the integrated heading's error
        grows as ``angle_random_walk * sqrt(t)``.
    bias : float
        rad / s: constant rate bias left after calibration (the integrated
        heading drifts by ``bias * t``).
    scale_error : float
        Systematic fraction: the gyro reports ``(1 + scale_error)`` times
        every turn.

    The defaults are those of a cheap MEMS gyro after a standstill
    calibration: 0.01 deg/sqrt(s), a bias of 0.005 deg/s (18 deg/h) and
    0.2 % scale error.

    Examples
    --------
    >>> GyroNoise().bias > 0
    True
    """

    angle_random_walk: float = float(np.radians(0.01))
    bias: float = float(np.radians(0.005))
    scale_error: float = 0.002

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise TypeError(f"GyroNoise.{k} must be a number, got {v!r}")
            if not np.isfinite(v):
                raise ValueError(f"GyroNoise.{k} must be finite, got {v}")
        if self.angle_random_walk < 0:
            raise ValueError(f"GyroNoise.angle_random_walk must be >= 0, got {self.angle_random_walk}")

    @classmethod
    def none(cls) -> "GyroNoise":
        """A perfect gyro (reproduces the true headings)."""
        return cls(0.0, 0.0, 0.0)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def simulate_gyro(poses: Any, times: Any, noise: GyroNoise | None = None,
                  rng: np.random.Generator | int | None = None) -> np.ndarray:
    """The heading integrated from a noisy yaw gyro along true ``poses``.

    Between consecutive frames the gyro measures the true turn (the wrapped
    heading change: a turn of more than 180 degrees between two frames
    reads as the shorter one) times ``1 + scale_error``, plus ``bias * dt``
    and ``angle_random_walk * sqrt(dt) * N(0, 1)``, ``dt`` the time between
    the frames. The result is continuous (not wrapped) and starts at the
    true first heading, as the odometry does: the gyro's turn between
    frames ``i`` and ``j`` is ``out[j] - out[i]``.

    Parameters
    ----------
    poses : array (N, 3)
        True (x m, y m, heading rad).
    times : array (N,)
        Seconds, non-decreasing.
    noise : GyroNoise
        Default ``GyroNoise()``.
    rng : numpy Generator or int seed

    Returns
    -------
    ndarray (N,): the gyro's heading (rad).

    Raises
    ------
    ValueError
        Bad poses, ``times`` of another length, not finite or decreasing.

    Examples
    --------
    >>> P = np.array([[0, 0, 0.0], [1, 0, 0.5], [2, 0, 1.0]])
    >>> simulate_gyro(P, [0, 1, 2], GyroNoise.none()).round(3).tolist()
    [0.0, 0.5, 1.0]
    """
    P = check_poses(poses)
    noise = GyroNoise() if noise is None else noise
    if not isinstance(noise, GyroNoise):
        raise TypeError(f"noise must be a GyroNoise, got {type(noise).__name__}")
    try:
        t = np.asarray(times, dtype=float)
    except (TypeError, ValueError):
        raise TypeError("times must be an array of seconds") from None
    if t.shape != (len(P),):
        raise ValueError(f"times must have shape ({len(P)},) (one per pose), got {t.shape}")
    if not np.isfinite(t).all():
        raise ValueError("times must be finite")
    dt = np.diff(t)
    if np.any(dt < 0):
        raise ValueError(f"times must not decrease (at index {int(np.nonzero(dt < 0)[0][0]) + 1})")
    rng = np.random.default_rng(rng)
    if len(P) == 0:
        return np.empty(0)
    turn = wrap_angle(np.diff(P[:, 2]))
    meas = turn * (1 + noise.scale_error) + noise.bias * dt
    if noise.angle_random_walk > 0:
        meas = meas + noise.angle_random_walk * np.sqrt(dt) * rng.standard_normal(len(dt))
    return P[0, 2] + np.concatenate([[0.0], np.cumsum(meas)])


@dataclass
class Robot:
    """A robot with cameras at fixed offsets and noisy wheel odometry.

    Attributes
    ----------
    cameras : dict of str to (forward, left)
        Camera name -> offset in the robot frame (m). One centred camera by
        default; :meth:`two_cameras` mounts one on each side (thesis 7.1.1).
    size : float
        Side length of the robot (m); trajectories keep half of it clear of
        borders and obstacles.
    noise : OdometryNoise
    gyro : GyroNoise, optional
        A yaw gyro (an IMU): datasets simulated with this robot get the
        column ``gyro_heading`` (:func:`simulate_gyro`). None (default): no gyro.
    """

    cameras: dict[str, tuple[float, float]] = field(default_factory=lambda: {"center": (0.0, 0.0)})
    size: float = 0.7
    noise: OdometryNoise = field(default_factory=OdometryNoise)
    gyro: GyroNoise | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.noise, OdometryNoise):
            raise TypeError(f"noise must be an OdometryNoise, got {type(self.noise).__name__}")
        if self.gyro is not None and not isinstance(self.gyro, GyroNoise):
            raise TypeError(f"gyro must be a GyroNoise or None, got {type(self.gyro).__name__}")
        if not self.cameras:
            raise ValueError("a robot needs at least one camera")
        cams = {}
        for name, off in self.cameras.items():
            if not isinstance(name, str) or not name or "," in name:
                raise ValueError(f"camera names must be non-empty strings without commas, got {name!r}")
            try:
                f, l_ = (float(v) for v in off)
            except (TypeError, ValueError):
                raise ValueError(f"camera {name!r}: offset must be (forward, left) in metres, got {off!r}") from None
            cams[name] = (f, l_)
        self.cameras = cams
        if not self.size > 0:
            raise ValueError(f"robot size must be positive (m), got {self.size}")

    @classmethod
    def two_cameras(cls, separation: float = 0.7, **kwargs: Any) -> "Robot":
        """Cameras ``"left"`` and ``"right"`` ``separation`` metres apart,
        on the robot's sides (thesis 7.1.1)."""
        if not separation > 0:
            raise ValueError(f"separation must be positive (m), got {separation}")
        return cls(cameras={"left": (0.0, separation / 2), "right": (0.0, -separation / 2)}, **kwargs)

    def camera_poses(self, poses: Any) -> dict[str, np.ndarray]:
        """Pose (N, 3) of each camera for robot ``poses`` (N, 3)."""
        P = check_poses(poses)
        c, s = np.cos(P[:, 2]), np.sin(P[:, 2])
        out = {}
        for name, (f, l_) in self.cameras.items():
            q = P.copy()
            q[:, 0] += c * f - s * l_
            q[:, 1] += s * f + c * l_
            out[name] = q
        return out

    def odometry(self, poses: Any, rng: np.random.Generator | int | None = None) -> np.ndarray:
        """Dead-reckoned robot poses along ``poses`` (see :func:`simulate_odometry`)."""
        return simulate_odometry(poses, self.noise, rng)

    def gyro_headings(self, poses: Any, times: Any, rng: np.random.Generator | int | None = None) -> np.ndarray:
        """The gyro's heading (N,) along robot ``poses`` (see :func:`simulate_gyro`).

        Raises
        ------
        ValueError
            The robot has no gyro (``gyro`` is None).
        """
        if self.gyro is None:
            raise ValueError("this robot has no gyro; give Robot(gyro=GyroNoise())")
        return simulate_gyro(poses, times, self.gyro, rng)

    def to_dict(self) -> dict[str, Any]:
        out = {"cameras": {k: list(v) for k, v in self.cameras.items()}, "size": self.size,
               "odometry_noise": self.noise.to_dict()}
        if self.gyro is not None:
            out["gyro_noise"] = self.gyro.to_dict()
        return out


class Simulator:
    """Closed-loop simulation: a robot driving in a world, seeing through its
    cameras and counting wheel odometry.

    Parameters
    ----------
    world : World
    camera : PanoramicCamera or OmniCamera
        The camera model of every mount.
    robot : Robot, optional
    lighting : Lighting, optional
    pose : (x, y, heading), optional
        Start pose (default the origin facing +x); odometry starts there.
    seed : int
        Seed of the odometry noise.

    Examples
    --------
    >>> sim = Simulator(World.generate(0), PanoramicCamera(600, 60))   # doctest: +SKIP
    >>> images = sim.observe()          # {"center": (60, 600, 3) uint8}
    >>> sim.step(v=0.3, omega=0.1, dt=0.5)
    """

    def __init__(self, world: Any, camera: Any, robot: Robot | None = None, lighting: Any = None,
                 pose: Sequence[float] = (0.0, 0.0, 0.0), seed: int = 0):
        from .render import Renderer

        self.world = world
        self.camera = camera
        self.robot = robot or Robot()
        self.renderer = Renderer(world, lighting)
        self.rng = np.random.default_rng(seed)
        self.reset(pose)

    def reset(self, pose: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """Puts the robot at ``pose``; odometry restarts there, time at 0."""
        p = check_poses([pose], "pose")[0]
        self.pose = p.copy()
        self.odometry_pose = p.copy()
        self.time = 0.0

    def step(self, v: float, omega: float, dt: float) -> bool:
        """Drives with speed ``v`` (m/s) and turn rate ``omega`` (rad/s) for
        ``dt`` s. The move is refused (returns False, the robot stays; time
        passes) when the robot (a disc of diameter ``robot.size``) would leave
        the area or touch an obstacle on the way."""
        if not dt > 0:
            raise ValueError(f"dt must be positive (s), got {dt}")
        new = unicycle_step(self.pose, v, omega, dt)
        self.time += dt
        # check the swept path every 5 cm, not just the end (thin walls)
        n = max(1, int(np.ceil(abs(v) * dt / 0.05)))
        path = np.array([unicycle_step(self.pose, v, omega, dt * k / n) for k in range(1, n + 1)])
        if not bool(self.world.free(path[:, 0], path[:, 1], self.robot.size / 2).all()):
            return False
        odo = simulate_odometry(np.stack([self.pose, new]), self.robot.noise, self.rng)
        # apply the noisy increment to the odometry pose (relative motion in the robot frame)
        d = odo[1] - odo[0]
        c, s = np.cos(self.odometry_pose[2] - odo[0, 2]), np.sin(self.odometry_pose[2] - odo[0, 2])
        self.odometry_pose = self.odometry_pose + np.array([c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]])
        self.pose = new
        return True

    def observe(self, lighting: Any = None) -> dict[str, np.ndarray]:
        """One image per camera at the current pose and time."""
        poses = self.robot.camera_poses(self.pose[None, :])
        return {name: self.renderer.render(self.camera, p[0], self.time, lighting) for name, p in poses.items()}


def reframed_odometry(odometry: Any, start: Any = (7.0, -3.0, 1.1), *, drift_deg_per_m: float = 0.5,
                      heading_noise_deg: float = 0.2, seed: int = 0) -> np.ndarray:
    """A run's odometry (N, 3: x m, y m, heading rad) as the odometry of
    another drive along the same path would report it: re-integrated from
    the pose ``start`` (x m, y m, heading rad) of a frame of its own, each
    step keeping its length and its turn, plus a systematic heading drift
    (``drift_deg_per_m`` degrees per metre) and a heading random walk
    (``heading_noise_deg`` degrees per step, seeded). What a second run looks
    like to a map it must join (:func:`sfanav.odometry.map_joining.join_run`).

    Example
    -------
    >>> odo = np.c_[np.arange(5.0), np.zeros(5), np.zeros(5)]
    >>> out = reframed_odometry(odo, (0.0, 0.0, np.pi / 2), drift_deg_per_m=0, heading_noise_deg=0)
    >>> bool(np.allclose(out[-1], [0.0, 4.0, np.pi / 2]))
    True
    """
    odo = np.asarray(odometry, dtype=np.float64)
    if odo.ndim != 2 or odo.shape[1] != 3 or len(odo) < 1 or not np.isfinite(odo).all():
        raise ValueError(f"odometry must be finite poses of shape (N, 3), got shape {odo.shape}")
    x0, y0, theta = (float(v) for v in start)
    rng = np.random.default_rng(seed)
    dxy = np.diff(odo[:, :2], axis=0)
    d = np.hypot(*dxy.T)
    c, s = np.cos(odo[:-1, 2]), np.sin(odo[:-1, 2])
    local = np.c_[c * dxy[:, 0] + s * dxy[:, 1], -s * dxy[:, 0] + c * dxy[:, 1]]
    dth = (np.diff(np.unwrap(odo[:, 2])) + np.radians(drift_deg_per_m) * d
           + np.radians(heading_noise_deg) * rng.standard_normal(len(d)))
    h = theta + np.concatenate([[0.0], np.cumsum(dth)])
    ch, sh = np.cos(h[:-1]), np.sin(h[:-1])
    steps = np.c_[ch * local[:, 0] - sh * local[:, 1], sh * local[:, 0] + ch * local[:, 1]]
    out = np.empty_like(odo)
    out[:, :2] = np.vstack([[x0, y0], [x0, y0] + np.cumsum(steps, axis=0)])
    out[:, 2] = h
    return out
