"""A run without ground truth joined to an existing map: the positions of
its frames in the map's frame, from its odometry and loop closures to the
map's views, solved as a pose graph on GTSAM.

An updatable :class:`~sfanav.Localizer` keeps a readout memory
(:class:`~sfanav.localization.updates.ReadoutMemory`): for a bounded set of
its training views, their inputs to the network's top stage and their
positions in the map frame. :func:`join_run` places a new run (panoramas and
their odometry, in the odometry's own frame: unknown origin and heading,
drifting) in that frame:

1. **Map closures.** Every new frame's ``n_neighbors`` nearest memory views
   in slow-feature space (the ``n_outputs`` slowest features; the views'
   features recomputed from their stored stage inputs). A frame whose
   neighbours agree on one place (their positions within ``max_spread``
   metres RMS of their mean) gets a candidate closure: "this frame is at the
   neighbours' mean position", standard deviation the spread (at least
   ``min_sigma``).
2. **Alignment.** The odometry's systematic heading drift rate (over a grid,
   :data:`DRIFT_SEARCH_DEG`) and the rigid motion from the corrected
   odometry's frame to the map frame that most candidates agree with
   (RANSAC on pairs of candidates at least ``min_baseline`` metres apart,
   inliers within ``inlier_m``, refitted by
   least squares on the inliers). Fewer than ``min_closures`` inliers or
   than ``min_fraction`` of the candidates (chance agreement in a small
   garden is a few tens of per cent), or
   inliers within ``min_baseline`` metres RMS of each other (one place
   cannot fix the run's heading): the run cannot be joined (ValueError
   naming the counts).
3. **Pose graph.** One :class:`gtsam.Pose2` per new frame, started at the
   aligned odometry: the odometry as between factors (the random-walk noise
   model of :func:`~sfanav.odometry.pose_graph_gtsam.odometry_sigmas`), the
   map closures as translation priors with a Cauchy kernel (the old views'
   positions are fixed: the map does not move), and the panorama compass
   within the new run (places it passes twice, found by the slow features,
   their relative heading read off the two panoramas,
   :func:`~sfanav.odometry.pose_graph.relative_headings`) as heading-only
   closures with a Cauchy kernel. Solved by Levenberg-Marquardt in batch
   (``solver="lm"``) or by iSAM2 as the run grows (``solver="isam2"``:
   ``chunk`` frames and their closures per update, as a robot driving).

The memory keeps no panoramas, so the compass cannot compare a new frame
with an old view; closures to the map are positions only. The result's
positions are the run's ``xy`` for
:meth:`~sfanav.localization.updates.LocalizerUpdater.partial_fit`.
Measured in docs/updates.md ("Maps joined").

Example
-------
>>> joined = join_run(loc, images_b, odometry_b)  # doctest: +SKIP
>>> new = LocalizerUpdater(loc).partial_fit(images_b, joined.positions).localizer_  # doctest: +SKIP
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import check_int, check_nonneg_float, check_positive_float
from ..localization.error_metrics import align
from ..localization.localizer import Localizer
from ..localization.updates import top_stage_features, updatable_memory
from .dead_reckoning import as_poses, wrap_angle
from .pose_graph import place_pairs, relative_headings
from .pose_graph_gtsam import odometry_sigmas, require_gtsam, robust_weights

__all__ = ["MapClosures", "JoinedRun", "map_closures", "drift_corrected", "join_run", "SOLVERS",
           "DRIFT_SEARCH_DEG"]

DRIFT_SEARCH_DEG = tuple(np.round(np.arange(-3.0, 3.01, 0.1), 2))
"""Systematic heading drift rates (deg per m) the initial alignment tries."""

SOLVERS = ("lm", "isam2")
"""The back ends of :func:`join_run`."""

_HEADING_ONLY_SIGMA = 1e4  # m: the position sigma of a compass closure (its position is unknown)


@dataclass
class MapClosures:
    """Closures between a new run's frames and the map: frame ``frame[k]``
    is at ``position[k]`` (metres, map frame) with standard deviation
    ``sigma[k]`` (m, per axis); ``view[k]`` is its nearest memory view and
    ``distance[k]`` the slow-feature distance to it."""

    frame: np.ndarray
    position: np.ndarray
    sigma: np.ndarray
    view: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.frame)

    def subset(self, keep: Any) -> "MapClosures":
        k = np.asarray(keep)
        return MapClosures(self.frame[k], self.position[k], self.sigma[k], self.view[k], self.distance[k])


@dataclass
class JoinedRun:
    """A run placed in a map's frame by :func:`join_run`.

    Attributes
    ----------
    poses : ndarray (N, 3)
        x, y (m) in the map frame and heading (rad, unwrapped along the run)
        of every frame.
    closures : MapClosures
        The candidate closures to the map (all of them).
    weights : ndarray (M,)
        Each candidate's robust weight at the solution (>= 0.5: kept).
    residuals : ndarray (M,)
        Each candidate's residual at the solution: distance (m) between the
        frame's position and the closure's.
    alignment : (float, ndarray (2,))
        The initial rigid motion from the odometry frame (corrected by
        ``drift_rate``) to the map frame: rotation (rad) and translation (m).
    drift_rate : float
        The odometry's systematic heading drift (rad/m, positive: it
        believes it turned left) found with the alignment; the graph reads
        the odometry corrected by it (:func:`drift_corrected`).
    n_ransac_inliers : int
        Candidates the initial alignment agreed with.
    n_compass : int
        Compass closures within the run.
    odometry_chi : float
        RMS of the odometry factors' whitened residuals at the solution.
    solver : str
    seconds : float
        Wall time of the whole join (features, closures, solve).
    """

    poses: np.ndarray
    closures: MapClosures
    weights: np.ndarray
    residuals: np.ndarray
    alignment: tuple[float, np.ndarray]
    n_ransac_inliers: int
    n_compass: int
    odometry_chi: float
    solver: str
    seconds: float = 0.0
    drift_rate: float = 0.0

    @property
    def positions(self) -> np.ndarray:
        """(N, 2) the frames' positions in the map frame (metres)."""
        return self.poses[:, :2]

    @property
    def n_kept(self) -> int:
        """Closures to the map with a robust weight of at least 0.5."""
        return int(np.sum(self.weights >= 0.5))

    def info(self) -> dict[str, Any]:
        """A JSON-able summary (for a model file's ``info``)."""
        kept = self.weights >= 0.5
        return {"supervision": "odometry joined to the map", "solver": self.solver,
                "map closures": len(self.closures), "map closures kept": self.n_kept,
                "map closure residual median (m)": float(np.median(self.residuals[kept])) if kept.any() else None,
                "alignment inliers": int(self.n_ransac_inliers),
                "odometry heading drift (deg per m)": float(np.degrees(self.drift_rate)), "compass closures": int(self.n_compass),
                "odometry residual (sd)": float(self.odometry_chi), "seconds": float(self.seconds)}


def _memory_features(localizer: Localizer) -> tuple[np.ndarray, np.ndarray]:
    """The memory views' slow features under the localizer's network and
    their positions."""
    mem = updatable_memory(localizer, "a run without ground truth cannot be joined to it")
    return top_stage_features(localizer.trained_network(), mem.inputs), mem.positions


def map_closures(features: Any, view_features: Any, view_positions: Any, *, n_neighbors: int = 3,
                 max_spread: float = 0.75, min_sigma: float = 0.25, n_outputs: int = 8) -> MapClosures:
    """Candidate closures of a run's frames to a map's views (step 1 of the
    module docstring).

    ``features`` (N, m): the run's slow features; ``view_features`` (V, m)
    and ``view_positions`` (V, 2): the map's views. Each frame whose
    ``n_neighbors`` nearest views (Euclidean, ``n_outputs`` slowest
    features) lie within ``max_spread`` metres RMS of their mean position
    gets a closure at that mean, sigma ``max(spread, min_sigma)``.
    ValueError for mismatched feature widths or too few views.
    """
    F = np.asarray(features, np.float64)
    V = np.asarray(view_features, np.float64)
    Y = np.asarray(view_positions, np.float64)
    if F.ndim != 2 or V.ndim != 2 or F.shape[1] != V.shape[1]:
        raise ValueError(f"the run's features {F.shape} and the map's view features {V.shape} must be 2-D with "
                         "the same number of columns")
    k = check_int(n_neighbors, "n_neighbors")
    if len(V) < k:
        raise ValueError(f"the map keeps {len(V)} views, fewer than n_neighbors={k}")
    q = min(check_int(n_outputs, "n_outputs"), F.shape[1])
    f, v = F[:, :q], V[:, :q]
    D = (f * f).sum(1)[:, None] + (v * v).sum(1)[None, :] - 2.0 * f @ v.T
    nn = np.argsort(D, axis=1)[:, :k]
    P = Y[nn]  # (N, k, 2)
    mean = P.mean(axis=1)
    spread = np.sqrt(((P - mean[:, None]) ** 2).sum(axis=2).mean(axis=1))
    ok = spread <= check_positive_float(max_spread, "max_spread")
    frames = np.flatnonzero(ok)
    sig = np.maximum(spread[ok], check_positive_float(min_sigma, "min_sigma"))
    dist = np.sqrt(np.maximum(D[frames, nn[ok, 0]], 0.0))
    return MapClosures(frames, mean[ok], sig, nn[ok, 0], dist)


def _rigid(a: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
    """Rotation angle and translation of the rigid motion taking points a
    (K, 2) onto b (K, 2) in least squares."""
    al = align(a, b)
    R = al.rotation
    return float(np.arctan2(R[1, 0], R[0, 0])), np.asarray(al.translation, np.float64)


def _apply(theta: float, t: np.ndarray, xy: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return xy @ np.array([[c, s], [-s, c]]) + t


def drift_corrected(odometry: Any, drift_rate: float) -> np.ndarray:
    """The odometry (N, 3) re-integrated with every step's heading change
    corrected by ``-drift_rate * d`` (d the step's length in metres,
    ``drift_rate`` in rad/m, positive when the odometry believes it turned
    left): the first pose kept, each step's length and direction relative
    to its pose kept."""
    P = as_poses(odometry, "odometry")
    d = np.hypot(*np.diff(P[:, :2], axis=0).T)
    dxy = np.diff(P[:, :2], axis=0)
    c, s = np.cos(P[:-1, 2]), np.sin(P[:-1, 2])
    lx, ly = c * dxy[:, 0] + s * dxy[:, 1], -s * dxy[:, 0] + c * dxy[:, 1]
    h = P[0, 2] + np.concatenate([[0.0], np.cumsum(wrap_angle(np.diff(P[:, 2])) - float(drift_rate) * d)])
    ch, sh = np.cos(h[:-1]), np.sin(h[:-1])
    xy = P[0, :2] + np.concatenate([np.zeros((1, 2)), np.cumsum(np.c_[ch * lx - sh * ly, sh * lx + ch * ly], 0)])
    return np.c_[xy, h]


def _hypotheses(odo_xy: np.ndarray, target: np.ndarray, pairs: np.ndarray,
                inlier_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rigid motions (rotation (T,), translation (T, 2)) taking each pair of
    candidates' odometry positions onto their map positions (the two-point
    closed form), and their inlier counts (T,)."""
    a, b = odo_xy[pairs[:, 0]], odo_xy[pairs[:, 1]]
    p, q = target[pairs[:, 0]], target[pairs[:, 1]]
    u, v = b - a, q - p
    th = np.arctan2(v[:, 1], v[:, 0]) - np.arctan2(u[:, 1], u[:, 0])
    c, s = np.cos(th), np.sin(th)
    ma, mp = 0.5 * (a + b), 0.5 * (p + q)
    t = mp - np.c_[c * ma[:, 0] - s * ma[:, 1], s * ma[:, 0] + c * ma[:, 1]]
    X = odo_xy[None, :, 0] * c[:, None] - odo_xy[None, :, 1] * s[:, None] + t[:, 0:1]
    Y = odo_xy[None, :, 0] * s[:, None] + odo_xy[None, :, 1] * c[:, None] + t[:, 1:2]
    counts = ((X - target[None, :, 0]) ** 2 + (Y - target[None, :, 1]) ** 2 <= inlier_m ** 2).sum(axis=1)
    return th, t, counts


def _ransac(odometry: np.ndarray, frames: np.ndarray, target: np.ndarray, *, inlier_m: float, min_baseline: float,
            trials: int, drift_rates: np.ndarray,
            rng: np.random.Generator) -> tuple[float, float, np.ndarray, np.ndarray]:
    """The drift rate and rigid motion (odometry corrected by that rate ->
    map) most candidates agree with, refitted on its inliers: (drift rate,
    rotation, translation, inlier mask)."""
    m = len(frames)
    if m < 2:
        return 0.0, 0.0, np.zeros(2), np.zeros(m, bool)
    pairs = rng.integers(0, m, size=(trials, 2))
    best = (-1, 0.0, 0.0, np.zeros(2))
    for b in drift_rates:  # the smallest |rate| first: it wins ties
        xy = drift_corrected(odometry, b)[frames, :2]
        ok = np.hypot(*(xy[pairs[:, 0]] - xy[pairs[:, 1]]).T) >= max(min_baseline, 1e-9)
        if not ok.any():
            continue
        th, t, counts = _hypotheses(xy, target, pairs[ok], inlier_m)
        k = int(np.argmax(counts))
        if counts[k] > best[0]:
            best = (int(counts[k]), float(b), float(th[k]), t[k])
    _, b, th, t = best
    xy = drift_corrected(odometry, b)[frames, :2]
    inl = np.hypot(*(_apply(th, t, xy) - target).T) <= inlier_m
    for _ in range(3):  # refit on the inliers, then take the inliers of the refit
        if inl.sum() < 2:
            break
        th2, t2 = _rigid(xy[inl], target[inl])
        inl2 = np.hypot(*(_apply(th2, t2, xy) - target).T) <= inlier_m
        if inl2.sum() < inl.sum():
            break
        th, t, inl = th2, t2, inl2
    return b, th, t, inl


def _local_steps(P: np.ndarray, sig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Odometry steps (N - 1, 3) in the frame of their first pose and their
    covariances (N - 1, 3, 3): ``sig`` (along, across, heading) turned to
    the step's direction."""
    dxy = np.diff(P[:, :2], axis=0)
    c, s = np.cos(P[:-1, 2]), np.sin(P[:-1, 2])
    local = np.c_[c * dxy[:, 0] + s * dxy[:, 1], -s * dxy[:, 0] + c * dxy[:, 1], wrap_angle(np.diff(P[:, 2]))]
    phi = np.arctan2(local[:, 1], local[:, 0])
    cp, sp = np.cos(phi), np.sin(phi)
    cov = np.zeros((len(local), 3, 3))
    for k in range(len(local)):
        R = np.array([[cp[k], -sp[k]], [sp[k], cp[k]]])
        cov[k, :2, :2] = R @ np.diag([sig[k, 0] ** 2, sig[k, 1] ** 2]) @ R.T
        cov[k, 2, 2] = sig[k, 2] ** 2
    return local, cov


def join_run(localizer: Localizer, images: Any, odometry: Any, *, features: Any = None,
             odometry_noise: Any = None, n_outputs: int = 8, n_neighbors: int = 3, max_spread: float = 0.75,
             min_sigma: float = 0.25, inlier_m: float = 1.5, min_baseline: float = 2.0,
             min_closures: int = 10, min_fraction: float = 0.4, ransac_trials: int = 300,
             drift_search_deg: Any = DRIFT_SEARCH_DEG, robust_scale: float = 3.0, compass: bool = True,
             compass_sigma_deg: float = 5.0, min_travel: float = 5.0, solver: str = "lm", chunk: int = 50,
             random_state: int = 0, gyro: Any = None, gyro_noise: Any = None) -> JoinedRun:
    """Places a run without ground truth in a localizer's map frame (see
    the module docstring).

    Parameters
    ----------
    localizer : Localizer
        Fitted, with a readout memory (its map's views and positions).
    images : array (N, H, W[, C])
        The run's panoramas in temporal order, as the localizer takes them.
    odometry : array (N, 3)
        Their odometry poses: x, y (m), heading (rad) in the odometry's own
        frame (any origin and heading), finite.
    features : array (N, m), optional
        ``localizer.features(images)`` if already computed.
    odometry_noise : mapping or sfanav.sim.OdometryNoise, optional
        Noise model of the odometry factors (default
        :data:`~sfanav.odometry.DEFAULT_ODOMETRY_NOISE` with slip).
    n_outputs, n_neighbors, max_spread, min_sigma
        Map closures (:func:`map_closures`).
    inlier_m, min_baseline, ransac_trials, random_state
        The initial alignment: inlier distance (m), shortest odometry
        distance (m) between the two candidates of a hypothesis, hypotheses
        per drift rate, seed.
    drift_search_deg : sequence of float, default :data:`DRIFT_SEARCH_DEG`
        The odometry's systematic heading drift rates (deg/m) the alignment
        tries; the one most candidates agree with corrects the odometry.
    min_closures : int, default 10
        Fewest candidates agreeing with the alignment for the run to join.
    min_fraction : float, default 0.4
        Smallest fraction of the candidates agreeing with the alignment for
        the run to join (odometry unrelated to the images agrees by chance
        with 10-25 % in a 6x6 m garden, a run that belongs with 90 %).
    robust_scale : float, default 3
        Cauchy scale of every closure, in its standard deviations.
    compass : bool, default True
        Heading-only closures within the run (places passed twice; pairs
        at least ``min_travel`` metres of driving apart), standard deviation
        ``compass_sigma_deg``.
    solver : {"lm", "isam2"}, default "lm"
        Levenberg-Marquardt on the whole graph, or iSAM2 fed ``chunk``
        frames (with their closures) per update.
    gyro : array (N,) or None
        A yaw gyro's integrated heading (rad; :attr:`sfanav.Dataset.gyro`):
        fused with the odometry's turns first
        (:func:`sfanav.odometry.gyro.fuse_gyro`), and the odometry factors'
        heading sigmas become the fused ones, as in the training run's pose
        graph. ``gyro_noise``: its noise model
        (:data:`sfanav.odometry.gyro.DEFAULT_GYRO_NOISE`).

    Returns
    -------
    JoinedRun

    Raises
    ------
    ValueError
        Mismatched lengths (images, odometry, features), non-finite or
        mis-shaped odometry, a localizer without readout memory, an
        unknown solver, or too few closures to the map (the message gives
        the counts: candidates found, candidates agreeing on one rigid
        motion). TypeError / NotFittedError for a localizer that is not a
        fitted :class:`~sfanav.Localizer`. ImportError without ``gtsam``.

    Example
    -------
    >>> joined = join_run(loc, images_b, odometry_b)  # doctest: +SKIP
    >>> joined.positions.shape, joined.n_kept  # doctest: +SKIP
    """
    t0 = time.perf_counter()
    if odometry is None:
        raise ValueError("the run has no odometry: a run without ground truth joins the map through its "
                         "odometry and loop closures")
    P = as_poses(odometry, "odometry")
    a = np.asarray(images)
    if len(a) != len(P):
        raise ValueError(f"images has {len(a)} frames but odometry has {len(P)} poses; they must match")
    heading_sigma = None
    if gyro is not None:
        from .gyro import fuse_gyro

        fused = fuse_gyro(P, gyro, odometry_noise=odometry_noise, gyro_noise=gyro_noise)
        P, heading_sigma = fused.odometry, fused.heading_sigma
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    chunk = check_int(chunk, "chunk")
    min_closures = check_int(min_closures, "min_closures")
    min_fraction = check_nonneg_float(min_fraction, "min_fraction")
    scale = check_positive_float(robust_scale, "robust_scale")
    inlier_m = check_positive_float(inlier_m, "inlier_m")
    min_baseline = check_nonneg_float(min_baseline, "min_baseline")
    gtsam = require_gtsam()
    V, Y = _memory_features(localizer)
    F = localizer.features(a) if features is None else np.asarray(features, np.float64)
    if F.ndim != 2 or len(F) != len(P):
        raise ValueError(f"features must be (N, m) with N = {len(P)} frames, got shape {F.shape}")
    C = map_closures(F, V, Y, n_neighbors=n_neighbors, max_spread=max_spread, min_sigma=min_sigma,
                     n_outputs=n_outputs)
    rng = np.random.default_rng(random_state)
    rates = np.radians(np.asarray(drift_search_deg, np.float64).ravel())
    if not len(rates) or not np.isfinite(rates).all():
        raise ValueError("drift_search_deg must hold finite drift rates (deg per m)")
    rates = rates[np.argsort(np.abs(rates), kind="stable")]
    drift, theta0, t0xy, inl = _ransac(P, C.frame, C.position, inlier_m=inlier_m, min_baseline=min_baseline,
                                       trials=check_int(ransac_trials, "ransac_trials"), drift_rates=rates, rng=rng)
    P = drift_corrected(P, drift)  # the odometry the graph reads
    if inl.sum() < max(min_closures, min_fraction * len(C)):
        raise ValueError(f"no closures to the map found: {len(C)} of the run's {len(P)} frames resemble a place of "
                         f"the map, and only {int(inl.sum())} of them agree on one placement of the run "
                         f"(at least {min_closures} and {min_fraction:.0%} of them needed); does the run drive "
                         "through the mapped area, and does its odometry belong to its images?")
    span = P[C.frame[inl], :2]
    span = float(np.sqrt(((span - span.mean(axis=0)) ** 2).sum(axis=1).mean()))
    if span < min_baseline:
        raise ValueError(f"no closures to the map found along the run: the {int(inl.sum())} frames that agree on a "
                         f"placement lie within {span:.2f} m RMS of each other (at least min_baseline = "
                         f"{min_baseline} m needed to fix the run's heading in the map)")
    # the initial guess: the odometry moved by the alignment
    init = np.c_[_apply(theta0, t0xy, P[:, :2]), np.unwrap(P[:, 2]) + theta0]
    # compass closures within the run
    if compass:
        pairs = place_pairs(F, P, n_neighbors=n_neighbors, min_travel=min_travel, n_outputs=n_outputs)
        rel = relative_headings(a, pairs.current, pairs.past) if len(pairs) else np.zeros(0)
    else:
        pairs, rel = None, np.zeros(0)
    n_compass = 0 if pairs is None else len(pairs)
    sig = odometry_sigmas(P, odometry_noise, heading_sigma)
    steps, cov = _local_steps(P, sig)
    g = gtsam

    def robust(base: Any) -> Any:
        return g.noiseModel.Robust.Create(g.noiseModel.mEstimator.Cauchy.Create(scale), base)

    def factors_upto(lo: int, hi: int) -> Any:
        """Factors whose newest frame is in [lo, hi)."""
        graph = g.NonlinearFactorGraph()
        for k in range(max(lo - 1, 0), hi - 1):
            graph.add(g.BetweenFactorPose2(k, k + 1, g.Pose2(*steps[k]), g.noiseModel.Gaussian.Covariance(cov[k])))
        sel = (C.frame >= lo) & (C.frame < hi)
        for k in np.flatnonzero(sel):
            graph.add(g.PoseTranslationPrior2D(int(C.frame[k]), C.position[k],
                                               robust(g.noiseModel.Isotropic.Sigma(2, float(C.sigma[k])))))
        if n_compass:
            s = np.radians(check_positive_float(compass_sigma_deg, "compass_sigma_deg"))
            for k in np.flatnonzero((pairs.current >= lo) & (pairs.current < hi)):
                base = g.noiseModel.Diagonal.Sigmas(np.array([_HEADING_ONLY_SIGMA, _HEADING_ONLY_SIGMA, s]))
                graph.add(g.BetweenFactorPose2(int(pairs.past[k]), int(pairs.current[k]), g.Pose2(0.0, 0.0, rel[k]),
                                               robust(base)))
        return graph

    def values(lo: int, hi: int, start: np.ndarray) -> Any:
        v = g.Values()
        for k in range(lo, hi):
            v.insert(k, g.Pose2(*start[k]))
        return v

    n = len(P)
    if solver == "lm":
        params = g.LevenbergMarquardtParams()
        params.setMaxIterations(100)
        est = g.LevenbergMarquardtOptimizer(factors_upto(0, n), values(0, n, init), params).optimize()
    else:
        params = g.ISAM2Params()
        params.setRelinearizeThreshold(0.01)
        params.relinearizeSkip = 1
        isam = g.ISAM2(params)
        for lo in range(0, n, chunk):
            hi = min(n, lo + chunk)
            start = init.copy()
            if lo > 0:  # the new frames continue from the latest estimate of the last one, by the odometry
                last = isam.calculateEstimatePose2(lo - 1)
                for k in range(lo, hi):
                    rel_k = g.Pose2(*P[lo - 1]).between(g.Pose2(*P[k]))
                    p = last.compose(rel_k)
                    start[k] = (p.x(), p.y(), p.theta())
            isam.update(factors_upto(lo, hi), values(lo, hi, start))
        for _ in range(3):
            isam.update()
        est = isam.calculateEstimate()
    poses = np.array([[p.x(), p.y(), p.theta()] for p in (est.atPose2(k) for k in range(n))])
    corr = np.unwrap(wrap_angle(poses[:, 2] - init[:, 2]))
    poses[:, 2] = init[:, 2] + corr - 2 * np.pi * np.round(corr[0] / (2 * np.pi))
    res = np.hypot(*(poses[C.frame, :2] - C.position).T)
    w = robust_weights(res / C.sigma, "cauchy", scale)
    chi = _odometry_chi(poses, steps, cov)
    return JoinedRun(poses, C, w, res, (theta0, t0xy), int(inl.sum()), n_compass, chi, solver,
                     time.perf_counter() - t0, drift_rate=drift)


def _odometry_chi(poses: np.ndarray, steps: np.ndarray, cov: np.ndarray) -> float:
    """RMS over the odometry factors of the whitened residual norm per
    degree of freedom."""
    if not len(steps):
        return 0.0
    a = poses[:-1]
    d = np.diff(poses[:, :2], axis=0)
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    rel = np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap_angle(np.diff(poses[:, 2]))]
    e = rel - steps
    e[:, 2] = wrap_angle(e[:, 2])
    m = np.einsum("ki,kij,kj->k", e, np.linalg.inv(cov), e)
    return float(np.sqrt(np.mean(m / 3.0)))
