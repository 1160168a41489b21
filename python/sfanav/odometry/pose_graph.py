"""Positions without ground truth from odometry and image loop closures: a
2D pose graph whose loop closures are places the run passed twice, found by
the slow features and aligned by the panorama.

Wheel odometry measures distance well (about 1 %) but its heading drifts
(a systematic rate plus a random walk). A panoramic image is a compass: two
panoramas of one place differ by a column shift proportional to the
difference of their headings. :func:`fit_pose_graph`

1. pairs every frame with its nearest frames in slow-feature space among
   those at least ``min_travel`` metres of driving away (:func:`place_pairs`;
   the slow features code position and ignore heading),
2. measures the relative heading of each pair by circular cross-correlation
   of the two panoramas (:func:`relative_headings`, sub-column),
3. solves the headings of all frames by sparse weighted least squares:
   the odometry's heading changes (weights from the odometry noise model),
   an unknown systematic drift rate (rad/m) and the pairs' relative headings
   (robust Cauchy weights by iterative reweighting, so that a wrong pair
   does not bend the map),
4. integrates the odometry's distances along the solved headings,
5. refines the positions (``refine`` rounds): a readout (a GP of the slow
   features, by default) is fitted to the current positions, and the
   positions solve one sparse linear least-squares problem: the odometry's
   steps turned by the solved headings (distance random walk plus a lateral
   error from the headings' uncertainty) and, for every loop-closure pair,
   the offset between the two frames that the readout predicts (a smooth
   function of the slow features averages all passes through a place, so
   it corrects the drift of the odometry's distances between passes).

The result is in the odometry frame: the first frame keeps its odometry
pose. Nothing here reads ground truth.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from .._checks import (
    as_matrix,
    check_int,
    check_nonneg_float,
    check_positive_float,
    check_same_length,
)
from ..localization.readouts import make_readout
from .dead_reckoning import as_poses, wrap_angle
from ..loopclosure.closures import panorama_rows
from .metric_cost import noise_dict

REFINE_READOUT = {"kind": "gp", "n_outputs": 12}
"""The readout whose predicted offsets refine the positions (at most as many
outputs as the features have)."""

CLOSURE_METHODS = ("warping", "min-warping", "auto")
"""How :func:`fit_pose_graph` measures relative-pose closures
(``closure_method``): the warping (one landmark distance per hypothesis),
min-warping (one per image column), or both, keeping the map whose
closures fit it better (:func:`closure_misfit`, no ground truth)."""

DEFAULT_COMPASS_SIGMA_DEG = 5.0
"""Standard deviation (degrees) assumed for a pair's relative heading: the
panorama compass reads pairs of frames 1-2 m apart to a fraction of a degree
but parallax makes its error depend on the place by a few degrees."""


@dataclass
class PlacePairs:
    """Pairs of frames at about the same place: ``current[k]`` (the later
    frame) and ``past[k]``, ``distance[k]`` apart in slow-feature space."""

    current: np.ndarray
    past: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.current)


def travelled(odometry: np.ndarray) -> np.ndarray:
    """Cumulative odometry distance (m) at every frame, 0 at the first."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(odometry[:, :2], axis=0).T))])


def place_pairs(features: Any, odometry: Any, *, n_neighbors: int = 3, min_travel: float = 5.0, n_outputs: int = 8,
                chunk: int = 512) -> PlacePairs:
    """Each frame's ``n_neighbors`` nearest frames in slow-feature space
    (Euclidean, the ``n_outputs`` slowest features) among those at least
    ``min_travel`` metres of odometry driving away, as unique pairs.

    ``features`` (N, m) and ``odometry`` (N, 3) are one run's frames in
    temporal order. Raises ValueError for mismatched or non-finite input.
    """
    F = as_matrix(features, "features")
    P = as_poses(odometry, "odometry")
    check_same_length(F, P, "features", "odometry")
    k = check_int(n_neighbors, "n_neighbors", minimum=1)
    gap = check_nonneg_float(min_travel, "min_travel")
    f = np.ascontiguousarray(F[:, : min(int(n_outputs), F.shape[1])], dtype=np.float64)
    s = travelled(P)
    n = len(f)
    sq = (f * f).sum(axis=1)
    cur, past, dist = [], [], []
    for a in range(0, n, chunk):
        q = np.arange(a, min(n, a + chunk))
        D = sq[q, None] + sq[None, :] - 2.0 * (f[q] @ f.T)
        D[np.abs(s[q, None] - s[None, :]) < gap] = np.inf
        kk = min(k, n)
        nn = np.argpartition(D, kk - 1, axis=1)[:, :kk]
        d = np.take_along_axis(D, nn, axis=1)
        ok = np.isfinite(d)
        i = np.broadcast_to(q[:, None], nn.shape)[ok]
        j = nn[ok]
        cur.append(np.maximum(i, j))
        past.append(np.minimum(i, j))
        dist.append(np.sqrt(np.maximum(d[ok], 0.0)))
    if not cur or sum(len(c) for c in cur) == 0:
        return PlacePairs(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    c, p, d = np.concatenate(cur), np.concatenate(past), np.concatenate(dist)
    _, first = np.unique(c * n + p, return_index=True)
    return PlacePairs(c[first].astype(np.int64), p[first].astype(np.int64), d[first])


def relative_headings(images: Any, current: Any, past: Any, *, chunk: int = 256) -> np.ndarray:
    """Heading of ``current`` minus heading of ``past`` (rad, in (-pi, pi]),
    for pairs of 360-degree panoramas, by the column shift that maximises
    the circular cross-correlation of their rows (mean-free per row), with
    parabolic sub-column interpolation of the peak.

    ``images`` (N, H, W[, C]); column ``j`` of a panorama looks at a bearing
    decreasing with ``j`` (as :func:`sfanav.sim.bearings`), so a left turn
    shifts the scene to larger columns.
    """
    R = panorama_rows(images)
    cur = np.asarray(current, np.int64)
    pst = np.asarray(past, np.int64)
    W = R.shape[2]
    out = np.empty(len(cur))
    for t in range(0, len(cur), chunk):
        idx = np.arange(t, min(len(cur), t + chunk))
        a = R[cur[idx]].astype(np.float32)
        b = R[pst[idx]].astype(np.float32)
        a -= a.mean(axis=2, keepdims=True)
        b -= b.mean(axis=2, keepdims=True)
        A, B = np.fft.rfft(a, axis=2), np.fft.rfft(b, axis=2)
        corr = np.fft.irfft((A * np.conj(B)).sum(axis=1), n=W, axis=1)  # corr[s] = sum_w a[w] b[w - s]
        s = np.argmax(corr, axis=1)
        m = np.arange(len(s))
        cm, c0, cp = corr[m, (s - 1) % W], corr[m, s], corr[m, (s + 1) % W]
        den = cm - 2 * c0 + cp
        frac = np.where(den < 0, 0.5 * (cm - cp) / np.where(den < 0, den, -1.0), 0.0)
        out[idx] = (s + frac) * 2 * np.pi / W
    return wrap_angle(out)


@dataclass
class PoseGraph:
    """A solved pose graph of one run.

    Attributes
    ----------
    poses : ndarray (N, 3)
        x, y (m), heading (rad, unwrapped) of every frame in the odometry
        frame (the first frame keeps its odometry pose).
    drift_rate : float
        The odometry's estimated systematic heading drift, rad per metre
        (positive: the odometry believes it turned left).
    pairs : PlacePairs
        The loop-closure pairs.
    relative_heading : ndarray (M,)
        Each pair's measured relative heading (rad).
    weights : ndarray (M,)
        Each pair's final robust weight in [0, 1] (small: an outlier).
    refined : int
        Rounds of position refinement kept (see :func:`refine_positions`).
    refine_chi : float
        The last refinement round's odometry residual RMS (in standard
        deviations; NaN without refinement): above 2 the round was refused.
    offset_sigma : float
        The last refinement round's standard deviation of the readout's
        pair offsets (m; NaN without refinement).
    refine_trace : list of dict
        Every refinement round tried (:func:`refine_positions`' ``trace``).
    closures : RelativePoses or None
        The relative-pose closures the map was solved with (None with
        heading-only closures).
    closure_method : str or None
        What measured them ("warping" or "min-warping"; None without).
    method_misfits : dict
        With ``closure_method="auto"``: each method's map's
        :attr:`misfit` (the lower won).
    """

    poses: np.ndarray
    drift_rate: float
    pairs: PlacePairs
    relative_heading: np.ndarray
    weights: np.ndarray
    refined: int = 0
    refine_chi: float = float("nan")
    offset_sigma: float = float("nan")
    refine_trace: list[dict[str, float]] = field(default_factory=list)
    closures: Any = None
    closure_method: str | None = None
    method_misfits: dict[str, float] = field(default_factory=dict)

    @property
    def misfit(self) -> float:
        """:func:`closure_misfit` of the final map against its own
        closures (NaN without relative-pose closures)."""
        if self.closures is None or len(self.closures) == 0:
            return float("nan")
        return closure_misfit(self.poses[:, :2], self.poses[:, 2], self.closures)

    @property
    def n_inliers(self) -> int:
        """Pairs with a robust weight of at least 0.5."""
        return int(np.sum(self.weights >= 0.5))

    def info(self) -> dict[str, Any]:
        """A JSON-able summary."""
        return {"loop closures": len(self.pairs), "loop closures kept": self.n_inliers,
                "odometry heading drift (deg per m)": float(np.degrees(self.drift_rate)),
                "refinement rounds kept": int(self.refined),
                "refinement odometry residual (sd)": None if not np.isfinite(self.refine_chi)
                else float(self.refine_chi),
                "refinement offset sigma (m)": None if not np.isfinite(self.offset_sigma)
                else float(self.offset_sigma),
                "refinement rounds tried": [{k: (float(v) if np.isfinite(v) else None) for k, v in r.items()}
                                            for r in self.refine_trace],
                **({"closure method": self.closure_method} if self.closure_method else {}),
                **({"closure misfit by method": {k: (float(v) if np.isfinite(v) else None)
                                                 for k, v in self.method_misfits.items()}}
                   if self.method_misfits else {})}


def _solve_headings(odometry: np.ndarray, pairs: PlacePairs, rel: np.ndarray, noise: Mapping[str, float],
                    sigma: float, iterations: int, robust: float,
                    step_sigma: np.ndarray | None = None) -> tuple[np.ndarray, float, np.ndarray]:
    n = len(odometry)
    e = np.arange(n - 1)
    dth = wrap_angle(np.diff(odometry[:, 2]))
    dd = np.hypot(*np.diff(odometry[:, :2], axis=0).T)
    st = step_heading_sigmas(noise, dd, dth)
    if step_sigma is not None:  # a gyro fused in: its per-step sigmas
        st = np.asarray(step_sigma, np.float64)
    theta = odometry[0, 2] + np.concatenate([[0.0], np.cumsum(dth)])
    i, j = pairs.current, pairs.past
    m = len(i)
    w = np.ones(m)
    # unknowns: theta_0..theta_{n-1}, drift rate b; odometry: theta_{k+1} - theta_k + b d_k = dth_k
    rows_o = np.concatenate([e, e, e])
    cols_o = np.concatenate([e + 1, e, np.full(n - 1, n)])
    vals_o = np.concatenate([1 / st, -1 / st, dd / st])
    anchor = 1e3
    b = 0.0
    for _ in range(iterations):
        meas = theta[i] - theta[j] + wrap_angle(rel - (theta[i] - theta[j]))  # nearest unwrapping
        sw = np.sqrt(w) / sigma
        rows = np.concatenate([rows_o, n - 1 + np.arange(m), n - 1 + np.arange(m), [n - 1 + m]])
        cols = np.concatenate([cols_o, i, j, [0]])
        vals = np.concatenate([vals_o, sw, -sw, [anchor]])
        A = sp.csr_matrix((vals, (rows, cols)), shape=(n + m, n + 1))
        rhs = np.concatenate([dth / st, sw * meas, [anchor * odometry[0, 2]]])
        sol = spsolve((A.T @ A).tocsc(), A.T @ rhs)
        if not np.all(np.isfinite(sol)):
            raise ValueError("the pose graph's heading system is singular (a run without motion?)")
        theta, b = sol[:n], float(sol[n])
        r = (theta[i] - theta[j] - meas) / sigma
        w = 1.0 / (1.0 + (r / robust) ** 2)
    return theta, b, w


def turned_steps(odometry: np.ndarray, headings: np.ndarray) -> np.ndarray:
    """The odometry's per-step displacements (N - 1, 2), metres, turned by
    the heading correction ``headings - odometry heading`` (mid-step)."""
    P = np.asarray(odometry, np.float64)
    dxy = np.diff(P[:, :2], axis=0)
    corr = np.asarray(headings, np.float64) - np.unwrap(P[:, 2])
    turn = 0.5 * (corr[1:] + corr[:-1])
    c, s = np.cos(turn), np.sin(turn)
    return np.c_[c * dxy[:, 0] - s * dxy[:, 1], s * dxy[:, 0] + c * dxy[:, 1]]


def integrate(odometry: np.ndarray, headings: np.ndarray) -> np.ndarray:
    """Positions (N, 2) from :func:`turned_steps`, from the first frame's
    odometry position."""
    step = turned_steps(odometry, headings)
    return np.asarray(odometry, np.float64)[0, :2] + np.concatenate([np.zeros((1, 2)), np.cumsum(step, axis=0)])


SLIP_DEFAULTS = {"slip_rate": 0.01, "slip_distance": 0.05, "slip_heading_sigma": 0.02}
"""Wheel slip assumed when the noise model gives none: events per metre, the
mean extra distance (m) and the heading error (rad) of one (the defaults of
:class:`sfanav.sim.OdometryNoise`)."""


PER_STEP_NOISE = {"step_heading_sigma": 0.0, "distance_fraction": 0.0, "turn_fraction": 0.0}
"""Noise per odometry step beside the random walk (zero when the noise
model gives none): a heading error per step (rad), a distance error as a
fraction of the step's length, a turn error as a fraction of the step's
turn (the per-step fields of :class:`sfanav.sim.OdometryNoise`, e.g. its
``mower`` model, which puts all of its noise there)."""


def odometry_noise_model(odometry_noise: Any = None) -> dict[str, float]:
    """The odometry's noise model as both pose-graph back ends read it: the
    random walk (``distance_sigma``, ``heading_sigma``, ``turn_sigma`` of
    :data:`~sfanav.odometry.DEFAULT_ODOMETRY_NOISE`), the slip model
    (:data:`SLIP_DEFAULTS` where not given) and the per-step terms
    (:data:`PER_STEP_NOISE`)."""
    out = dict(noise_dict(odometry_noise))
    raw = odometry_noise.to_dict() if hasattr(odometry_noise, "to_dict") else (odometry_noise or {})
    for k, v in {**SLIP_DEFAULTS, **PER_STEP_NOISE}.items():
        out[k] = check_nonneg_float(raw.get(k, v), f"odometry_noise[{k!r}]") if isinstance(raw, Mapping) else v
    return out


def step_heading_sigmas(noise: Mapping[str, float], d: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """Standard deviation (rad) of each odometry step's heading change:
    ``sqrt((heading_sigma^2 + slip_rate slip_heading_sigma^2) d +
    turn_sigma^2 |dtheta| + step_heading_sigma^2 + (turn_fraction dtheta)^2)``
    for steps of ``d`` metres turning ``dtheta`` rad (a floor of 1e-5 keeps
    standing frames finite)."""
    slip = noise.get("slip_rate", 0.0) * noise.get("slip_heading_sigma", 0.0) ** 2  # rad^2 per m (Poisson)
    return np.sqrt((noise["heading_sigma"] ** 2 + slip) * d + noise["turn_sigma"] ** 2 * np.abs(dtheta)
                   + noise.get("step_heading_sigma", 0.0) ** 2 + (noise.get("turn_fraction", 0.0) * dtheta) ** 2
                   + 1e-10)


def step_distance_sigmas(noise: Mapping[str, float], d: np.ndarray) -> np.ndarray:
    """Standard deviation (m) of each odometry step's length along it:
    ``sqrt((distance_sigma^2 + 2 slip_rate slip_distance^2) d +
    (distance_fraction d)^2)`` (floor 1e-5 m)."""
    slip = 2.0 * noise.get("slip_rate", 0.0) * noise.get("slip_distance", 0.0) ** 2  # m^2 per m (exponential)
    return np.sqrt((noise["distance_sigma"] ** 2 + slip) * d + (noise.get("distance_fraction", 0.0) * d) ** 2 + 1e-10)


def _solve_positions(step: np.ndarray, sd: np.ndarray, pairs: PlacePairs, offsets: np.ndarray, sigma: float,
                     first: np.ndarray) -> np.ndarray:
    """Positions (N, 2) from the steps (N - 1, 2) of standard deviation sd
    and the pairs' offsets (M, 2) of standard deviation sigma, by sparse
    least squares, the first frame held at ``first``."""
    n, m = len(step) + 1, len(pairs)
    i, j, e = pairs.current, pairs.past, np.arange(n - 1)
    anchor = 1e3
    rows = np.concatenate([e, e, n - 1 + np.arange(m), n - 1 + np.arange(m), [n - 1 + m]])
    cols = np.concatenate([e + 1, e, i, j, [0]])
    vals = np.concatenate([1 / sd, -1 / sd, np.full(m, 1 / sigma), np.full(m, -1 / sigma), [anchor]])
    A = sp.csr_matrix((vals, (rows, cols)), shape=(n + m, n)).tocsc()
    normal = (A.T @ A).tocsc()
    out = np.empty((n, 2))
    for ax in range(2):
        rhs = np.concatenate([step[:, ax] / sd, offsets[:, ax] / sigma, [anchor * first[ax]]])
        out[:, ax] = spsolve(normal, A.T @ rhs)
    if not np.all(np.isfinite(out)):
        raise ValueError("the pose graph's position system is singular")
    return out


def _area(new: np.ndarray, old: np.ndarray) -> float:
    """The area of ``new`` relative to ``old``: the determinant of the
    least-squares linear map from ``old``'s centred points to ``new``'s (1:
    the same size; a squeeze of one axis by 3 % gives 0.97 however the
    other axis turns; a shear or a stretch of one axis with a squeeze of
    the other keeps it near 1)."""
    a, b = new - new.mean(axis=0), old - old.mean(axis=0)
    M, *_ = np.linalg.lstsq(b, a, rcond=None)
    return float(abs(np.linalg.det(M)))


def closure_misfit(positions: Any, headings: Any, closures: Any, keep: Any = None) -> float:
    """How far a map is from the relative positions its closures measured:
    the median over the closures with a measured position of the squared
    Mahalanobis distance (2 degrees of freedom) between the map's relative
    position of frame ``j`` seen from frame ``i`` and the measured one,
    under the closure's position covariance (in the measured pose's frame,
    as GTSAM's between factor). ``positions`` (N, 2) m and ``headings``
    (N,) rad are the map; ``closures`` a
    :class:`~sfanav.odometry.pose_graph_gtsam.RelativePoses`; ``keep``
    (M,) bool selects closures (e.g. the robust solve's inliers). NaN when
    no closure measures a position.

    >>> from sfanav.odometry.pose_graph_gtsam import RelativePoses
    >>> c = RelativePoses([0], [1], [1.0], [0.0], [0.0], sigmas=[[0.1, 0.1, 0.01]])
    >>> round(closure_misfit([[0, 0], [1.2, 0]], [0, 0], c), 6)
    4.0
    """
    from .pose_graph_gtsam import HEADING_ONLY_SIGMA

    P = np.asarray(positions, np.float64)
    th = np.asarray(headings, np.float64)
    m = len(closures.i)
    cov = np.array([closures.covariance_of(k)[:2, :2] for k in range(m)]).reshape(m, 2, 2)
    sel = np.diagonal(cov, axis1=1, axis2=2).max(axis=1) < (0.1 * HEADING_ONLY_SIGMA) ** 2
    if keep is not None:
        sel &= np.asarray(keep, bool)
    if not sel.any():
        return float("nan")
    i, j = closures.i[sel], closures.j[sel]

    def turned_back(v: np.ndarray, angle: np.ndarray) -> np.ndarray:  # vectors (K, 2) into frames turned by angle
        c, s_ = np.cos(angle), np.sin(angle)
        return np.c_[c * v[:, 0] + s_ * v[:, 1], -s_ * v[:, 0] + c * v[:, 1]]

    rel = turned_back(P[j] - P[i], th[i])  # j's position in i's frame
    r = turned_back(rel - np.c_[closures.dx[sel], closures.dy[sel]], closures.dtheta[sel])  # in the measured pose's
    m2 = np.einsum("ki,kij,kj->k", r, np.linalg.inv(cov[sel]), r)
    return float(np.median(m2))


def refine_positions(features: np.ndarray, odometry: np.ndarray, headings: np.ndarray, positions: np.ndarray,
                     pairs: PlacePairs, *, noise: Mapping[str, float], readout: Mapping[str, Any],
                     rounds: int, offset_sigma: float | None, heading_sigma: float,
                     max_chi: float = 2.0, max_scale_change: float = 0.02, closures: Any = None,
                     closure_keep: Any = None, max_misfit_growth: float | None = None,
                     trace: list[dict[str, float]] | None = None) -> tuple[np.ndarray, int, float, float]:
    """Positions (N, 2) refined by ``rounds`` of: fit ``readout`` (a spec of
    :func:`sfanav.localization.make_readout`) to the current positions, then
    solve the positions from the odometry steps turned by ``headings``
    (standard deviation ``distance_sigma * sqrt(d)`` along, with the slip
    model, and ``heading_sigma * d`` across each step of d metres) and the
    readout's offsets of the loop-closure pairs, the first frame fixed at
    its odometry position.

    The offsets' standard deviation ``offset_sigma`` (m; None: estimated)
    is, when estimated, the RMS length of the pairs' offset residuals,
    re-solved until it settles (it starts at 0.05 m): the readout's errors
    are correlated along the run, so the per-axis residual would trust them
    too much. A round is kept only if the refined positions still agree
    with the odometry: the RMS of the steps' residuals in units of their
    standard deviation (without the largest 1 %, where slips are) at most
    ``max_chi``, and the map's area (:func:`_area`: the determinant of the
    linear map from the unrefined positions to the refined ones) within
    ``max_scale_change`` of the unrefined map's: odometry fixes the scale;
    a run whose places are seen from only one side, such as the parallel
    lanes of a serpentine, gives offsets the readout shrinks across the
    lanes, which squeeze the map along one axis (5.1.1: 3 % in one round,
    whose training positions it made 0.23 -> 0.30 m worse, while the size
    test before, the RMS distance from the centroid against the last
    round's, let it pass), whereas a run with crossings gets its shape
    corrected at about the same area (docs/odometry.md, "Where the
    refinement hurts"). With ``closures`` (relative-pose closures the
    positions were solved with; ``closure_keep`` their inliers) and
    ``max_misfit_growth``, a round is also refused when it moves the map
    away from what the closures measured: its :func:`closure_misfit` more
    than ``max_misfit_growth`` times the unrefined map's. ``trace``, if a
    list, receives one dict per round tried (``chi``, ``area``,
    ``misfit``; the unrefined map's misfit first as ``misfit0``).
    Returns (positions, rounds kept, the last round's step RMS, the offsets'
    standard deviation of the last round)."""
    P = np.asarray(positions, np.float64).copy()
    P0 = P.copy()
    if rounds == 0 or len(pairs) == 0:
        return P, 0, float("nan"), float("nan")
    step = turned_steps(odometry, headings)
    d = np.hypot(*step.T)
    sd = np.sqrt(step_distance_sigmas(noise, d) ** 2 + (heading_sigma * d) ** 2 + 1e-8)
    i, j = pairs.current, pairs.past
    spec = dict(readout)
    if spec.get("n_outputs") is not None:
        spec["n_outputs"] = min(int(spec["n_outputs"]), features.shape[1])
    accepted = 0
    chi = sigma = float("nan")
    misfit0 = closure_misfit(P0, headings, closures, closure_keep) if closures is not None else float("nan")
    for _ in range(rounds):
        G = make_readout(spec).fit(features, P).predict(features)
        off = G[i] - G[j]
        sig = 0.05 if offset_sigma is None else float(offset_sigma)
        new = _solve_positions(step, sd, pairs, off, sig, odometry[0, :2])
        for _ in range(8 if offset_sigma is None else 0):  # estimated: re-solve until the spread settles
            est = max(float(np.sqrt(np.mean(((new[i] - new[j] - off) ** 2).sum(axis=1)))), 1e-3)
            settled = abs(est - sig) <= 0.05 * sig
            sig = est
            new = _solve_positions(step, sd, pairs, off, sig, odometry[0, :2])
            if settled:
                break
        r2 = np.sort((((np.diff(new, axis=0) - step) / sd[:, None]) ** 2).sum(axis=1) / 2)
        chi = float(np.sqrt(np.mean(r2[: max(1, int(np.ceil(0.99 * len(r2))))])))  # the rarest 1 %: slips
        sigma = sig
        area = _area(new, P0)
        misfit = closure_misfit(new, headings, closures, closure_keep) if closures is not None else float("nan")
        if trace is not None:
            trace.append({"chi": chi, "area": area, "misfit": misfit, "misfit0": misfit0, "offset sigma": sig})
        grew = (max_misfit_growth is not None and np.isfinite(misfit0) and misfit0 > 0
                and misfit > max_misfit_growth * misfit0)
        if chi > max_chi or abs(area - 1.0) > max_scale_change or grew:
            break  # the offsets contradict the odometry, the scale or the closures: keep the last round's map
        P = new
        accepted += 1
    return P, accepted, chi, sigma


MAX_MISFIT_GROWTH = 1.1
"""The default of :func:`fit_pose_graph`'s ``max_misfit_growth``: with
relative-pose closures a refinement round is kept only if the closures'
measured relative positions fit its map at most 10 % worse than the
unrefined one (chosen on 19 runs: docs/odometry.md, "The refinement
against relative-pose closures").
"""

SOLVERS = ("hand-written", "gtsam")
"""The back ends of :func:`fit_pose_graph`."""

PAIR_CLOSURES = ("heading", "relative-pose")
"""The kinds of closure :func:`fit_pose_graph` makes of its place pairs."""


def _solve_gtsam(P: np.ndarray, pairs: PlacePairs, rel: np.ndarray, sigma: float, odometry_noise: Any,
                 robust: float, extra: Any, *, step_sigma: np.ndarray | None = None,
                 closures: Any = None) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Positions, headings, drift rate and the pairs' robust weights from the
    GTSAM back end (``closures``: the pairs' own, default heading-only;
    ``extra``: further closures, appended after the pairs; ``step_sigma``:
    the odometry's per-step heading sigmas)."""
    from .pose_graph_gtsam import RelativePoses, solve_pose_graph

    if closures is None:
        closures = RelativePoses.from_headings(pairs.past, pairs.current, rel, sigma)
    if extra is not None:
        if not isinstance(extra, RelativePoses):
            raise TypeError(f"relative_poses must be a RelativePoses, got {type(extra).__name__}")
        closures = _concat(closures, extra)
    res = solve_pose_graph(P, closures, odometry_noise=odometry_noise, robust="cauchy", robust_scale=robust,
                           heading_sigma=step_sigma)
    return res.poses[:, :2], res.poses[:, 2], res.drift_rate, res.weights[: len(pairs)]


def _concat(a: Any, b: Any) -> Any:
    """Two RelativePoses as one (covariances throughout)."""
    from .pose_graph_gtsam import RelativePoses

    cov = np.array([a.covariance_of(k) for k in range(len(a))] + [b.covariance_of(k) for k in range(len(b))])
    return RelativePoses(np.r_[a.i, b.i], np.r_[a.j, b.j], np.r_[a.dx, b.dx], np.r_[a.dy, b.dy],
                         np.r_[a.dtheta, b.dtheta], covariance=cov.reshape(-1, 3, 3))


def fit_pose_graph(images: Any, features: Any, odometry: Any, *, odometry_noise: Any = None,
                   compass_sigma_deg: float = DEFAULT_COMPASS_SIGMA_DEG, n_neighbors: int = 3,
                   min_travel: float = 5.0, n_outputs: int = 8, iterations: int = 8,
                   robust: float = 3.0, refine: int = 2, refine_readout: Mapping[str, Any] | None = None,
                   offset_sigma: float | None = None, heading_sigma_deg: float = 1.0,
                   solver: str = "hand-written", relative_poses: Any = None,
                   pair_closures: str = "heading", pair_options: Mapping[str, Any] | None = None,
                   gyro: Any = None, gyro_noise: Mapping[str, float] | None = None,
                   max_misfit_growth: float | None = MAX_MISFIT_GROWTH,
                   closure_method: str = "warping") -> PoseGraph:
    """Solves the pose graph of one run from its panoramas, slow features and
    odometry (see the module docstring).

    Parameters
    ----------
    images : array (N, H, W[, C])
        The run's 360-degree panoramas in temporal order (any dtype).
    features : array (N, m)
        Their slow features (slowest first).
    odometry : array (N, 3)
        Odometry poses: x, y (m), heading (rad), finite.
    odometry_noise : mapping or sfanav.sim.OdometryNoise, optional
        ``heading_sigma`` (rad/sqrt(m)), ``turn_sigma`` (rad/sqrt(rad)),
        ``slip_rate`` (1/m) and ``slip_heading_sigma`` (rad) weight the
        odometry's heading changes, ``distance_sigma`` (m/sqrt(m)) and
        ``slip_distance`` (m) its steps in the refinement; defaults
        :data:`~sfanav.odometry.DEFAULT_ODOMETRY_NOISE` and
        :data:`SLIP_DEFAULTS`.
    compass_sigma_deg : float, default 5
        Standard deviation of a pair's relative heading, degrees.
    n_neighbors, min_travel, n_outputs
        As :func:`place_pairs`.
    iterations : int, default 8
        Reweighting rounds.
    robust : float, default 3
        Cauchy scale of the pairs' residuals, in units of
        ``compass_sigma_deg``.
    refine : int, default 2
        Rounds of position refinement by the readout's offsets (0: the
        odometry's distances along the solved headings only).
    refine_readout : mapping, optional
        The readout spec of the refinement (default :data:`REFINE_READOUT`,
        the sfanav default's GP).
    offset_sigma : float, optional
        Standard deviation (m) of a pair's offset predicted by the readout;
        by default estimated from the pairs' residuals (see
        :func:`refine_positions`).
    heading_sigma_deg : float, default 1
        Uncertainty of the solved headings (degrees): the lateral error of
        an odometry step is this times its length.
    solver : {"hand-written", "gtsam"}, default "hand-written"
        The back end of steps 3-4: ``"hand-written"`` solves the headings
        by sparse least squares and integrates the positions; ``"gtsam"``
        solves the poses by Levenberg-Marquardt on a GTSAM pose graph
        (:func:`sfanav.odometry.pose_graph_gtsam.solve_pose_graph`: the
        pairs as heading-only closures with a Cauchy kernel of scale
        ``robust``, the drift rate a variable of the graph; needs the
        ``gtsam`` extra). The refinement is the same for both.
    relative_poses : RelativePoses, optional
        Further closures with a measured relative position
        (:class:`sfanav.odometry.pose_graph_gtsam.RelativePoses`), added to
        the compass's; only with ``solver="gtsam"``.
    pair_closures : {"heading", "relative-pose"}, default "heading"
        The place pairs' closures: the compass's relative heading, or
        (``solver="gtsam"`` only) relative poses measured from the two
        panoramas after a first heading-only solve
        (:func:`sfanav.odometry.pair_closures.pair_relative_poses`: the
        relative heading and the baseline's direction from the panoramas,
        the distance from the first map, optionally with the slow
        features' local gradient; pairs with an uninformative bearing stay
        heading-only), solved again with the Cauchy kernel. Measured in
        docs/odometry.md (mower survey: 0.39 to 0.07 m on a crossing
        pattern, 0.48 to 0.39 m on a serpentine; minutes for ~1000 pairs).
    pair_options : mapping, optional
        Keywords of :func:`~sfanav.odometry.pair_closures.pair_relative_poses`
        (``map_distance_sigma``, ``use_gradient``, ``n_neighbors``,
        ``max_sigma_bearing_deg``, ``warp``).
    gyro : array (N,), optional
        A yaw gyro's integrated heading (rad; :attr:`sfanav.Dataset.gyro`):
        its turns are fused with the odometry's by inverse variance
        (:func:`sfanav.odometry.gyro.fuse_gyro`) before either back end
        reads the odometry, with the fused heading sigma per step.
    gyro_noise : mapping, optional
        The gyro's noise model (:data:`sfanav.odometry.gyro.DEFAULT_GYRO_NOISE`).
    max_misfit_growth : float or None, default :data:`MAX_MISFIT_GROWTH`
        With relative-pose closures, refuse a refinement round whose map
        fits the closures' measured relative positions worse than this
        many times the unrefined map (:func:`closure_misfit`); None: no
        such test. Heading-only closures measure no position: no test.
    closure_method : {"warping", "min-warping", "auto"}, default "warping"
        With relative-pose closures, how the panoramas measure them
        (:data:`CLOSURE_METHODS`; the ``method`` of
        :func:`sfanav.loopclosure.relative_poses`). ``"auto"`` solves the
        graph with each (refinement included) and keeps the map whose own
        closures fit it better (the lower :attr:`PoseGraph.misfit`, in
        :attr:`PoseGraph.method_misfits`; a tie keeps the warping):
        min-warping wins where landmarks at unequal distances bias the
        warping over long baselines (lanes), the warping where short
        baselines make min-warping's bearings noisier (dense gardens).
        Twice the closures' and the refinement's cost. Measured in docs/relative-pose.md,
        "Choosing the method without ground truth".

    Returns
    -------
    PoseGraph
        With no pairs found, the poses are the odometry's with the drift
        rate removed by nothing (``drift_rate`` 0): dead reckoning.

    Raises
    ------
    ValueError
        Mismatched lengths, non-finite values, images that are not
        panoramas, an unknown solver, ``relative_poses`` with the
        hand-written solver, ``pair_closures="relative-pose"`` without
        ``solver="gtsam"``, a gyro of another length or not finite, an
        unknown ``closure_method`` or one also given in ``pair_options``'
        ``warp``. ImportError: ``solver="gtsam"`` without gtsam.
    """
    if closure_method not in CLOSURE_METHODS:
        raise ValueError(f"closure_method must be one of {CLOSURE_METHODS}, got {closure_method!r}")
    warp = dict((pair_options or {}).get("warp") or {})
    if "method" in warp and closure_method != "warping":
        raise ValueError(f"the warping method is given twice: closure_method={closure_method!r} and "
                         f"pair_options['warp']['method']={warp['method']!r}; give closure_method only")
    P = as_poses(odometry, "odometry")
    if pair_closures not in PAIR_CLOSURES:
        raise ValueError(f"pair_closures must be one of {PAIR_CLOSURES}, got {pair_closures!r}")
    if pair_closures == "relative-pose" and solver != "gtsam":
        raise ValueError("pair_closures='relative-pose' needs solver='gtsam'")
    step_sigma = None
    if gyro is not None:
        from .gyro import fuse_gyro

        fused = fuse_gyro(P, gyro, odometry_noise=odometry_noise, gyro_noise=gyro_noise)
        P, step_sigma = fused.odometry, fused.heading_sigma
    F = as_matrix(features, "features")
    check_same_length(F, P, "features", "odometry")
    R = panorama_rows(images)
    if len(R) != len(P):
        raise ValueError(f"images has {len(R)} frames but odometry has {len(P)} poses; they must match")
    sigma = np.radians(check_positive_float(compass_sigma_deg, "compass_sigma_deg"))
    iterations = check_int(iterations, "iterations", minimum=1)
    robust = check_positive_float(robust, "robust")
    noise = odometry_noise_model(odometry_noise)
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    if relative_poses is not None and solver != "gtsam":
        raise ValueError("relative_poses (closures with a relative position) need solver='gtsam'")
    pairs = place_pairs(F, P, n_neighbors=n_neighbors, min_travel=min_travel, n_outputs=n_outputs)
    if len(pairs) == 0 and relative_poses is None:
        th = np.unwrap(P[:, 2])
        return PoseGraph(np.c_[P[:, :2], th], 0.0, pairs, np.zeros(0), np.zeros(0))
    rounds = check_int(refine, "refine", minimum=0)
    offset_sigma = None if offset_sigma is None else check_positive_float(offset_sigma, "offset_sigma")
    heading_sigma = np.radians(check_positive_float(heading_sigma_deg, "heading_sigma_deg"))
    rel = relative_headings(R, pairs.current, pairs.past)

    def refined(xy: np.ndarray, theta: np.ndarray, drift: float, w: np.ndarray, closures: Any = None,
                method: str | None = None) -> PoseGraph:
        """The pose graph after the refinement of its positions."""
        kept = PlacePairs(pairs.current[w >= 0.5], pairs.past[w >= 0.5], pairs.distance[w >= 0.5])
        trace: list[dict[str, float]] = []
        xy, done, chi, osig = refine_positions(F, P, theta, xy, kept, noise=noise,
                                               readout=refine_readout or REFINE_READOUT, rounds=rounds,
                                               offset_sigma=offset_sigma, heading_sigma=heading_sigma,
                                               closures=closures, closure_keep=w >= 0.5,
                                               max_misfit_growth=max_misfit_growth, trace=trace)
        return PoseGraph(np.c_[xy, theta], drift, pairs, rel, w, refined=done, refine_chi=chi, offset_sigma=osig,
                         refine_trace=trace, closures=closures, closure_method=method)

    if solver != "gtsam":
        theta, drift, w = _solve_headings(P, pairs, rel, noise, sigma, iterations, robust, step_sigma)
        return refined(integrate(P, theta), theta, drift, w)
    xy, theta, drift, w = _solve_gtsam(P, pairs, rel, sigma, odometry_noise, robust, relative_poses,
                                       step_sigma=step_sigma)
    if pair_closures != "relative-pose" or not len(pairs):
        return refined(xy, theta, drift, w)
    from . import pair_closures as pc  # looked up at the call: studies wrap pair_relative_poses

    args = (images, F[:, : min(int(n_outputs), F.shape[1])], xy, pairs.past, pairs.current, rel, sigma)
    popts = dict(pair_options or {})
    if closure_method == "auto":
        measured = pc.pair_relative_poses_by_method(*args, methods=("warping", "min-warping"), **popts)
    else:
        if closure_method != "warping":
            popts["warp"] = {**(popts.get("warp") or pc.WARP_OPTIONS), "method": closure_method}
        used = str((popts.get("warp") or pc.WARP_OPTIONS).get("method", "warping"))
        measured = {used: pc.pair_relative_poses(*args, **popts)}
    graphs = {m: refined(*_solve_gtsam(P, pairs, rel, sigma, odometry_noise, robust, relative_poses,
                                       step_sigma=step_sigma, closures=c), closures=c, method=m)
              for m, c in measured.items()}
    if closure_method != "auto":
        return next(iter(graphs.values()))
    # the map its own closures fit better (a tie or NaN: the warping)
    misfits = {m: g.misfit for m, g in graphs.items()}
    out = graphs["min-warping" if misfits["min-warping"] < misfits["warping"] else "warping"]
    out.method_misfits = misfits
    return out
