"""The run's 2-D pose graph on GTSAM: odometry factors between consecutive
frames, robust loop-closure factors, Levenberg-Marquardt in batch and iSAM2
run by run.

The graph has one :class:`gtsam.Pose2` variable per frame and, with
``drift="joint"``, one more: the odometry's systematic heading drift rate ``b`` (rad/m,
positive when the odometry believes it turned left), which every odometry
factor shares.

* **Odometry** between frames k and k+1 measures their relative pose in
  frame k as the odometry reports it, its heading change corrected by
  ``-b d_k`` (d_k the step's length). Its noise grows with distance and
  turn, from the same random-walk model as the hand-written solver
  (:func:`odometry_sigmas`). With ``drift="iterate"`` (the batch default:
  solve, re-estimate b from the odometry factors' heading residuals,
  correct, re-solve) or ``"none"`` it is a plain
  :class:`gtsam.BetweenFactorPose2`; with ``drift="joint"`` (the
  incremental solver's, where re-solving is not an option) b is a variable
  of the graph and the factor a :class:`gtsam.CustomFactor` on (pose k,
  pose k+1, b), because GTSAM has no between factor whose measurement
  depends on a third variable. Both find the same map; "iterate" is 4-7x
  faster (the custom factor calls Python at every linearisation).
* **Loop closures** (:class:`RelativePoses`) are
  :class:`gtsam.BetweenFactorPose2` with a robust kernel (Cauchy or Huber).
  A heading-only closure (the panorama compass) has a position standard
  deviation of :data:`HEADING_ONLY_SIGMA` metres: its whitened translation
  error is then ~1e-4 of a standard deviation, so it fixes the relative
  heading and does not pull the two frames together; a native factor keeps
  it fast and usable by iSAM2 and :class:`gtsam.Marginals` alike.
* The first frame has a tight prior at its odometry pose, ``b`` a wide one
  (:data:`DRIFT_PRIOR_SIGMA`) so that a run without closures stays solvable.

GTSAM is a dependency of sfanav (its relative-pose closures are the default
of training without ground truth); importing this module still works without
it, and the solvers raise ImportError naming the package. Measurements against the hand-written solver: docs/odometry.md,
"Pose graph on GTSAM".

Example
-------
>>> closures = RelativePoses.from_headings(past, current, rel, sigma=np.radians(5))  # doctest: +SKIP
>>> result = solve_pose_graph(odometry, closures)  # doctest: +SKIP
>>> result.poses, np.degrees(result.drift_rate)  # doctest: +SKIP
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_real_array, check_finite, check_int, check_positive_float
from .dead_reckoning import as_poses, wrap_angle
from .pose_graph import odometry_noise_model, step_distance_sigmas, step_heading_sigmas

HEADING_ONLY_SIGMA = 1e4
"""Position standard deviation (m) given to a closure whose position is
unknown (an infinite sigma in :class:`RelativePoses`)."""

DRIFT_PRIOR_SIGMA = 0.05
"""Standard deviation (rad/m, ~3 deg/m) of the prior on the drift rate
(centred on 0): wide for any real odometry, but it keeps a run without
closures solvable."""

PRIOR_SIGMAS = (1e-4, 1e-4, 1e-5)
"""Standard deviations (m, m, rad) of the prior holding the first frame at
its odometry pose."""

DRIFT_MODES = ("joint", "iterate", "none")
ROBUST_KERNELS = ("cauchy", "huber", "none")
_DRIFT_KEY = 2**62  # far from the frames' keys 0..N-1


def require_gtsam() -> Any:
    """The ``gtsam`` module, or ImportError naming the extra to install."""
    try:
        import gtsam
    except ImportError as exc:  # pragma: no cover - exercised where gtsam is absent
        raise ImportError("the GTSAM pose-graph back end needs the 'gtsam' package, a dependency of sfanav "
                          "(pip install gtsam); without it train with closures='heading' and solver='hand-written'"
                          ) from exc
    return gtsam


def has_gtsam() -> bool:
    """Whether ``gtsam`` can be imported."""
    try:
        require_gtsam()
    except ImportError:
        return False
    return True


@dataclass
class RelativePoses:
    """Loop-closure measurements: the pose of frame ``j`` in the frame of
    frame ``i`` (``dx``, ``dy`` in metres, ``dtheta`` = heading j - heading i
    in radians), with their uncertainty.

    Give either ``sigmas`` (M, 3): standard deviations of dx, dy (m) and
    dtheta (rad), ``inf`` for an unknown position (a heading-only closure),
    or ``covariance`` (M, 3, 3), finite and positive definite. Arrays are
    validated and converted to float64 / int64 on construction.

    Raises ValueError for mismatched lengths, negative or equal frame
    indices (i == j), non-finite measurements, non-positive sigmas, an
    infinite heading sigma, or a covariance that is not symmetric positive
    definite; TypeError for non-numeric input.
    """

    i: np.ndarray
    j: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dtheta: np.ndarray
    sigmas: np.ndarray | None = None
    covariance: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.i = _index(self.i, "i")
        self.j = _index(self.j, "j")
        m = len(self.i)
        for name in ("dx", "dy", "dtheta"):
            a = as_real_array(getattr(self, name), name).astype(np.float64).reshape(-1)
            check_finite(a, name)
            setattr(self, name, a)
        lengths = {n: len(getattr(self, n)) for n in ("i", "j", "dx", "dy", "dtheta")}
        if len(set(lengths.values())) != 1:
            raise ValueError(f"RelativePoses arrays must have one length, got {lengths}")
        same = np.flatnonzero(self.i == self.j)
        if len(same):
            raise ValueError(f"a closure joins a frame to itself (i == j == {self.i[same[0]]}, closure {same[0]})")
        if (self.sigmas is None) == (self.covariance is None):
            raise ValueError("RelativePoses needs exactly one of sigmas (M, 3) or covariance (M, 3, 3)")
        if self.sigmas is not None:
            s = as_real_array(self.sigmas, "sigmas").astype(np.float64)
            if s.shape != (m, 3):
                raise ValueError(f"sigmas must have shape ({m}, 3) (dx, dy, dtheta), got {s.shape}")
            if np.isnan(s).any() or (s <= 0).any():
                raise ValueError("sigmas must be positive (inf for an unknown position), got "
                                 f"{s[np.isnan(s) | (s <= 0)][0]}")
            if not np.isfinite(s[:, 2]).all():
                raise ValueError("the heading sigma (sigmas[:, 2]) must be finite")
            self.sigmas = s
        else:
            c = as_real_array(self.covariance, "covariance").astype(np.float64)
            if c.shape != (m, 3, 3):
                raise ValueError(f"covariance must have shape ({m}, 3, 3), got {c.shape}")
            check_finite(c, "covariance")
            if not np.allclose(c, np.swapaxes(c, 1, 2), rtol=1e-9, atol=1e-12):
                raise ValueError("covariance must be symmetric")
            if m and np.linalg.eigvalsh(c).min() <= 0:
                raise ValueError("covariance must be positive definite")
            self.covariance = c

    def __len__(self) -> int:
        return len(self.i)

    @classmethod
    def from_headings(cls, i: Any, j: Any, dtheta: Any, sigma: float) -> "RelativePoses":
        """Heading-only closures: relative headings ``dtheta`` (rad) of
        frame j with respect to frame i, standard deviation ``sigma`` (rad),
        position unknown."""
        sig = check_positive_float(sigma, "sigma")
        d = as_real_array(dtheta, "dtheta").astype(np.float64).reshape(-1)
        z = np.zeros(len(d))
        return cls(i, j, z, z.copy(), d, sigmas=np.c_[np.full((len(d), 2), np.inf), np.full(len(d), sig)])

    def heading_only(self) -> np.ndarray:
        """(M,) bool: closures whose position is unknown (an infinite sigma)."""
        if self.sigmas is None:
            return np.zeros(len(self), bool)
        return ~np.isfinite(self.sigmas[:, :2]).all(axis=1)

    def subset(self, keep: Any) -> "RelativePoses":
        """The closures selected by a boolean mask or indices."""
        k = np.asarray(keep)
        return RelativePoses(self.i[k], self.j[k], self.dx[k], self.dy[k], self.dtheta[k],
                             sigmas=None if self.sigmas is None else self.sigmas[k],
                             covariance=None if self.covariance is None else self.covariance[k])

    def covariance_of(self, k: int) -> np.ndarray:
        """The 3x3 covariance of closure ``k`` (an infinite position sigma
        becomes :data:`HEADING_ONLY_SIGMA`)."""
        if self.covariance is not None:
            return self.covariance[k]
        s = np.where(np.isfinite(self.sigmas[k]), self.sigmas[k], HEADING_ONLY_SIGMA)
        return np.diag(s * s)


def _index(a: Any, name: str) -> np.ndarray:
    arr = as_real_array(a, name).reshape(-1)
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)) or not np.all(arr == np.round(arr)):
            raise TypeError(f"{name} must hold frame indices (integers), got {arr.dtype} with fractions")
    arr = arr.astype(np.int64)
    if (arr < 0).any():
        raise ValueError(f"{name} must hold frame indices >= 0, got {arr.min()}")
    return arr


def odometry_sigmas(odometry: Any, odometry_noise: Any = None, heading_sigma: Any = None) -> np.ndarray:
    """Standard deviations (N - 1, 3) of each odometry step: along the step
    (m), across it (m) and of its heading change (rad).

    With d the step's length and dtheta its turn: heading
    :func:`~sfanav.odometry.pose_graph.step_heading_sigmas` (the
    hand-written solver's weights: random walk, slip and the per-step
    terms); along :func:`~sfanav.odometry.pose_graph.step_distance_sigmas`;
    across
    ``sqrt(distance_sigma^2 d + (d sigma_heading / 2)^2)`` (the heading
    error at mid-step turns the step). A floor of 1e-5 keeps standing
    frames finite.
    """
    P = as_poses(odometry, "odometry")
    nz = odometry_noise_model(odometry_noise)
    d = np.hypot(*np.diff(P[:, :2], axis=0).T)
    dth = wrap_angle(np.diff(P[:, 2]))
    sh = step_heading_sigmas(nz, d, dth)
    if heading_sigma is not None:
        sh = as_real_array(heading_sigma, "heading_sigma").astype(np.float64).reshape(-1)
        if sh.shape != d.shape or not np.all(np.isfinite(sh)) or np.any(sh <= 0):
            raise ValueError(f"heading_sigma must hold {len(d)} positive finite step sigmas, got shape {sh.shape}")
    sa = step_distance_sigmas(nz, d)
    sl = np.sqrt(nz["distance_sigma"] ** 2 * d + (0.5 * d * sh) ** 2 + 1e-10)
    return np.c_[sa, sl, sh]


def _step_covariances(odometry: np.ndarray, sig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Relative steps (N - 1, 3) in frame k and their covariances (N - 1, 3, 3)."""
    P = odometry
    dxy = np.diff(P[:, :2], axis=0)
    c, s = np.cos(P[:-1, 2]), np.sin(P[:-1, 2])
    local = np.c_[c * dxy[:, 0] + s * dxy[:, 1], -s * dxy[:, 0] + c * dxy[:, 1], wrap_angle(np.diff(P[:, 2]))]
    phi = np.arctan2(local[:, 1], local[:, 0])  # the step's direction in frame k
    cp, sp_ = np.cos(phi), np.sin(phi)
    R = np.stack([np.c_[cp, -sp_], np.c_[sp_, cp]], axis=1)  # (N-1, 2, 2)
    cov = np.zeros((len(local), 3, 3))
    cov[:, :2, :2] = R @ (np.eye(2)[None] * np.c_[sig[:, 0] ** 2, sig[:, 1] ** 2][:, :, None]) @ np.swapaxes(R, 1, 2)
    cov[:, 2, 2] = sig[:, 2] ** 2
    return local, cov


def _robust(gtsam: Any, kernel: str, scale: float, base: Any) -> Any:
    if kernel == "none":
        return base
    est = gtsam.noiseModel.mEstimator.Cauchy if kernel == "cauchy" else gtsam.noiseModel.mEstimator.Huber
    return gtsam.noiseModel.Robust.Create(est.Create(scale), base)


def robust_weights(chi: np.ndarray, kernel: str, scale: float) -> np.ndarray:
    """The kernel's weight in [0, 1] of whitened residual norms ``chi``."""
    chi = np.asarray(chi, np.float64)
    if kernel == "cauchy":
        return 1.0 / (1.0 + (chi / scale) ** 2)
    if kernel == "huber":
        return np.minimum(1.0, scale / np.maximum(chi, 1e-300))
    return np.ones_like(chi)


def _odometry_drift_factor(gtsam: Any, k: int, step: np.ndarray, d: float, noise: Any) -> Any:
    """CustomFactor on (pose k, pose k+1, drift): the relative pose minus
    the odometry's, its heading change corrected by ``-b d``."""
    tx, ty, dth = (float(v) for v in step)

    def error(this: Any, values: Any, H: Any) -> np.ndarray:
        a = values.atPose2(this.keys()[0])
        c = values.atPose2(this.keys()[1])
        b = float(values.atVector(this.keys()[2])[0])
        H1, H2 = np.zeros((3, 3), order="F"), np.zeros((3, 3), order="F")
        rel = a.between(c, H1, H2)
        e = np.array([rel.x() - tx, rel.y() - ty, wrap_angle(rel.theta() - dth + b * d)])
        if H is not None:
            # the relative pose's translation moves by R(theta_rel) times a perturbation of its tangent space
            ct, st = np.cos(rel.theta()), np.sin(rel.theta())
            D = np.array([[ct, -st, 0.0], [st, ct, 0.0], [0.0, 0.0, 1.0]])
            H[0], H[1], H[2] = D @ H1, D @ H2, np.array([[0.0], [0.0], [d]])
        return e

    return gtsam.CustomFactor(noise, [k, k + 1, _DRIFT_KEY], error)


@dataclass
class GraphResult:
    """A pose graph solved by GTSAM.

    Attributes
    ----------
    poses : ndarray (N, 3)
        x, y (m), heading (rad, unwrapped along the run) of every frame, in
        the odometry frame (the first frame at its odometry pose).
    drift_rate : float
        Estimated systematic heading drift of the odometry, rad/m (0 with
        ``drift="none"``).
    weights : ndarray (M,)
        Each closure's robust weight in [0, 1] at the solution (below 0.5:
        treated as an outlier).
    chi : ndarray (M,)
        Each closure's whitened residual norm at the solution.
    error : float
        The graph's final (robust) error.
    iterations : int
        Optimizer iterations (summed over the drift re-solves of
        ``drift="iterate"``).
    seconds : float
        Wall time of building and solving.
    """

    poses: np.ndarray
    drift_rate: float
    weights: np.ndarray
    chi: np.ndarray
    error: float
    iterations: int
    seconds: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n_inliers(self) -> int:
        """Closures with a robust weight of at least 0.5."""
        return int(np.sum(self.weights >= 0.5))


def _check_options(drift: str, robust: str, robust_scale: float) -> float:
    if drift not in DRIFT_MODES:
        raise ValueError(f"drift must be one of {DRIFT_MODES}, got {drift!r}")
    if robust not in ROBUST_KERNELS:
        raise ValueError(f"robust must be one of {ROBUST_KERNELS}, got {robust!r}")
    return check_positive_float(robust_scale, "robust_scale")


def _check_closures(closures: RelativePoses | None, n: int) -> RelativePoses:
    if closures is None:
        z = np.zeros(0)
        return RelativePoses(z.astype(np.int64), z.astype(np.int64), z, z, z, sigmas=np.zeros((0, 3)))
    if not isinstance(closures, RelativePoses):
        raise TypeError(f"closures must be a RelativePoses, got {type(closures).__name__}")
    if len(closures) and max(closures.i.max(), closures.j.max()) >= n:
        raise ValueError(f"closures refer to frame {max(closures.i.max(), closures.j.max())} but the odometry has "
                         f"{n} frames")
    return closures


class _Builder:
    """Factors of one run (shared by the batch and incremental solvers)."""

    def __init__(self, gtsam: Any, noise: Any, drift: str, robust: str, scale: float,
                 heading_sigma: np.ndarray | None = None):
        self.g, self.noise, self.drift, self.robust, self.scale = gtsam, noise, drift, robust, scale
        self.heading_sigma = heading_sigma  # per-step override of the whole run (batch only)

    def odometry(self, P: np.ndarray, first: int, b: float) -> tuple[Any, list[float]]:
        """Factors between frames first..first+len(P)-1 (P their odometry)."""
        g = self.g
        graph = g.NonlinearFactorGraph()
        sig = odometry_sigmas(P, self.noise, self.heading_sigma)
        step, cov = _step_covariances(P, sig)
        d = np.hypot(*np.diff(P[:, :2], axis=0).T)
        for k in range(len(step)):
            model = g.noiseModel.Gaussian.Covariance(cov[k])
            if self.drift == "joint":
                graph.add(_odometry_drift_factor(g, first + k, step[k], float(d[k]), model))
            else:
                m = g.Pose2(step[k, 0], step[k, 1], step[k, 2] - b * d[k])
                graph.add(g.BetweenFactorPose2(first + k, first + k + 1, m, model))
        return graph, list(d)

    def closures(self, C: RelativePoses) -> Any:
        g = self.g
        graph = g.NonlinearFactorGraph()
        for k in range(len(C)):
            cov = C.covariance_of(k)
            if not np.any(cov - np.diag(np.diag(cov))):  # diagonal: better conditioned with a huge sigma
                base = g.noiseModel.Diagonal.Sigmas(np.sqrt(np.diag(cov)))
            else:
                base = g.noiseModel.Gaussian.Covariance(cov)
            graph.add(g.BetweenFactorPose2(int(C.i[k]), int(C.j[k]), g.Pose2(C.dx[k], C.dy[k], C.dtheta[k]),
                                           _robust(g, self.robust, self.scale, base)))
        return graph

    def priors(self, pose0: np.ndarray) -> Any:
        g = self.g
        graph = g.NonlinearFactorGraph()
        graph.add(g.PriorFactorPose2(0, g.Pose2(*pose0), g.noiseModel.Diagonal.Sigmas(np.array(PRIOR_SIGMAS))))
        if self.drift == "joint":
            graph.add(g.PriorFactorVector(_DRIFT_KEY, np.zeros(1),
                                          g.noiseModel.Diagonal.Sigmas(np.array([DRIFT_PRIOR_SIGMA]))))
        return graph


def _poses_of(values: Any, odometry: np.ndarray) -> np.ndarray:
    """The frames' poses (N, 3), headings on the branch of the odometry's
    unwrapped headings (as the hand-written solver's)."""
    n = len(odometry)
    out = np.array([[p.x(), p.y(), p.theta()] for p in (values.atPose2(k) for k in range(n))])
    ref = np.unwrap(odometry[:, 2])
    corr = np.unwrap(wrap_angle(out[:, 2] - ref))  # the correction grows smoothly along the run
    out[:, 2] = ref + corr - 2 * np.pi * np.round(corr[0] / (2 * np.pi))
    return out


def closure_residuals(poses: np.ndarray, closures: RelativePoses) -> np.ndarray:
    """Whitened residual norms (M,) of the closures at ``poses`` (N, 3):
    ``sqrt(e' S^-1 e)`` with e the local coordinates of the relative pose
    with respect to the measured one and S its covariance."""
    gtsam = require_gtsam()
    out = np.empty(len(closures))
    for k in range(len(closures)):
        a, c = gtsam.Pose2(*poses[closures.i[k]]), gtsam.Pose2(*poses[closures.j[k]])
        meas = gtsam.Pose2(closures.dx[k], closures.dy[k], closures.dtheta[k])
        e = meas.localCoordinates(a.between(c))
        out[k] = np.sqrt(e @ np.linalg.solve(closures.covariance_of(k), e))
    return out


def _drift_update(poses: np.ndarray, P: np.ndarray, sig: np.ndarray, b: float) -> float:
    """The drift rate that best explains the odometry factors' heading
    residuals at ``poses`` (weighted least squares on the step lengths)."""
    d = np.hypot(*np.diff(P[:, :2], axis=0).T)
    r = wrap_angle(np.diff(poses[:, 2]) - (wrap_angle(np.diff(P[:, 2])) - b * d))  # solved minus measured
    w = 1.0 / sig[:, 2] ** 2
    return b - float(np.sum(w * r * d) / max(np.sum(w * d * d), 1e-300))


def solve_pose_graph(odometry: Any, closures: RelativePoses | None = None, *, odometry_noise: Any = None,
                     drift: str = "iterate", robust: str = "cauchy", robust_scale: float = 3.0,
                     max_iterations: int = 100, drift_iterations: int = 10,
                     heading_sigma: Any = None) -> GraphResult:
    """Solves a run's pose graph by Levenberg-Marquardt (batch).

    Parameters
    ----------
    odometry : array (N, 3)
        Odometry poses x, y (m), heading (rad) of consecutive frames.
    closures : RelativePoses, optional
        Loop closures; none: dead reckoning (the drift rate stays 0: with
        ``drift="joint"`` by its prior, with "iterate" because the
        odometry factors then have no residual).
    odometry_noise : mapping or sfanav.sim.OdometryNoise, optional
        Noise model of the odometry factors (:func:`odometry_sigmas`).
    drift : {"iterate", "joint", "none"}, default "iterate"
        ``"joint"``: the drift rate is a variable of the graph;
        ``"iterate"``: solve, re-estimate the rate from the odometry
        factors' heading residuals, correct the odometry, re-solve (at most
        ``drift_iterations`` solves, until the rate changes by < 1e-6
        rad/m); ``"none"``: no drift.
    robust : {"cauchy", "huber", "none"}, default "cauchy"
        Kernel of the closure factors.
    robust_scale : float, default 3
        The kernel's scale in standard deviations of a closure.
    max_iterations : int, default 100
        Levenberg-Marquardt iterations per solve.
    heading_sigma : array (N - 1,), optional
        Standard deviations (rad) of the odometry's heading changes, in
        place of the noise model's (a gyro fused in:
        :func:`sfanav.odometry.gyro.fuse_gyro`).

    Returns
    -------
    GraphResult

    Raises
    ------
    ValueError
        Non-finite or mis-shaped odometry, closures beyond the run, an
        unknown mode. ImportError without ``gtsam``.
    """
    t0 = time.perf_counter()
    gtsam = require_gtsam()
    P = as_poses(odometry, "odometry")
    n = len(P)
    scale = _check_options(drift, robust, robust_scale)
    C = _check_closures(closures, n)
    max_it = check_int(max_iterations, "max_iterations", minimum=1)
    rounds = check_int(drift_iterations, "drift_iterations", minimum=1) if drift == "iterate" else 1
    sig = odometry_sigmas(P, odometry_noise, heading_sigma)  # validates heading_sigma
    build = _Builder(gtsam, odometry_noise, drift, robust, scale, None if heading_sigma is None else sig[:, 2])
    init = gtsam.Values()
    for k in range(n):
        init.insert(k, gtsam.Pose2(*P[k]))
    if drift == "joint":
        init.insert(_DRIFT_KEY, np.zeros(1))
    fixed = build.closures(C)
    fixed.push_back(build.priors(P[0]))
    b, its = 0.0, 0
    for _ in range(rounds):
        graph, _ = build.odometry(P, 0, b)
        graph.push_back(fixed)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(max_it)
        opt = gtsam.LevenbergMarquardtOptimizer(graph, init, params)
        values = opt.optimize()
        its += opt.iterations()
        poses = _poses_of(values, P)
        if drift == "joint":
            b = float(values.atVector(_DRIFT_KEY)[0])
        elif drift == "iterate":
            new = _drift_update(poses, P, sig, b)
            done = abs(new - b) < 1e-6
            b = new
            init = values
            if done:
                break
    err = float(graph.error(values))
    chi = closure_residuals(poses, C)
    return GraphResult(poses, b, robust_weights(chi, robust, scale), chi, err, its, time.perf_counter() - t0)


class IncrementalPoseGraph:
    """A run's pose graph solved by iSAM2 as it grows: frames (odometry)
    and closures are added run by run, each :meth:`update` folds them in.

    The factors are those of :func:`solve_pose_graph` (``drift`` "joint"
    or "none"; re-solving for the drift would undo the incremental
    solver's point).

    Example
    -------
    >>> g = IncrementalPoseGraph(odometry_noise=noise)  # doctest: +SKIP
    >>> g.add_frames(odometry[:300]); g.update()  # doctest: +SKIP
    >>> g.add_frames(odometry[300:]); g.add_closures(closures); g.update()  # doctest: +SKIP
    >>> g.poses_  # doctest: +SKIP
    """

    def __init__(self, *, odometry_noise: Any = None, drift: str = "joint", robust: str = "cauchy",
                 robust_scale: float = 3.0, relinearize_threshold: float = 0.01):
        self.gtsam = require_gtsam()
        scale = _check_options(drift, robust, robust_scale)
        if drift == "iterate":
            raise ValueError("IncrementalPoseGraph supports drift='joint' or 'none', not 'iterate'")
        self.odometry_noise, self.drift, self.robust, self.robust_scale = odometry_noise, drift, robust, scale
        params = self.gtsam.ISAM2Params()
        params.setRelinearizeThreshold(check_positive_float(relinearize_threshold, "relinearize_threshold"))
        params.relinearizeSkip = 1
        self.isam = self.gtsam.ISAM2(params)
        self._build = _Builder(self.gtsam, odometry_noise, drift, robust, scale)
        self._odo = np.zeros((0, 3))
        self._graph = self.gtsam.NonlinearFactorGraph()
        self._values = self.gtsam.Values()
        self._closures: list[RelativePoses] = []
        self.n_frames_ = 0

    def add_frames(self, odometry: Any) -> "IncrementalPoseGraph":
        """Appends frames (their odometry poses (K, 3), consecutive with the
        frames already added; the first call fixes the frame of the map).
        The odometry's reference frame must be the same across calls."""
        g = self.gtsam
        P = as_poses(odometry, "odometry", min_rows=1)
        first = self.n_frames_
        if first == 0:
            self._graph.push_back(self._build.priors(P[0]))
            self._values.insert(0, g.Pose2(*P[0]))
            if self.drift == "joint":
                self._values.insert(_DRIFT_KEY, np.zeros(1))
            chain = P
        else:
            chain = np.r_[self._odo[-1:], P]
        if len(chain) > 1:
            graph, _ = self._build.odometry(chain, max(first - 1, 0), 0.0)
            self._graph.push_back(graph)
            # initial guesses: the latest estimate of the last frame, composed with the odometry steps
            last = self._estimate(first - 1) if first > 0 else g.Pose2(*P[0])
            o_last = g.Pose2(*chain[0])
            for k in range(1, len(chain)):
                guess = last.compose(o_last.between(g.Pose2(*chain[k])))
                self._values.insert(max(first - 1, 0) + k, guess)
        self._odo = np.r_[self._odo, P]
        self.n_frames_ = len(self._odo)
        return self

    def _estimate(self, k: int) -> Any:
        if self._values.exists(k):
            return self._values.atPose2(k)
        return self.isam.calculateEstimatePose2(k)

    def add_closures(self, closures: RelativePoses) -> "IncrementalPoseGraph":
        """Adds loop closures between frames already added."""
        C = _check_closures(closures, self.n_frames_)
        self._graph.push_back(self._build.closures(C))
        self._closures.append(C)
        return self

    def update(self, extra_iterations: int = 0) -> "IncrementalPoseGraph":
        """Folds the pending frames and closures in (one iSAM2 update, plus
        ``extra_iterations`` empty updates that relinearise further)."""
        self.isam.update(self._graph, self._values)
        for _ in range(check_int(extra_iterations, "extra_iterations", minimum=0)):
            self.isam.update()
        self._graph = self.gtsam.NonlinearFactorGraph()
        self._values = self.gtsam.Values()
        return self

    @property
    def poses_(self) -> np.ndarray:
        """Current estimate (N, 3) of the frames added and updated."""
        return _poses_of(self.isam.calculateEstimate(), self._odo)

    @property
    def drift_rate_(self) -> float:
        """Current estimate of the drift rate (rad/m; 0 with drift='none')."""
        if self.drift != "joint":
            return 0.0
        return float(self.isam.calculateEstimate().atVector(_DRIFT_KEY)[0])
