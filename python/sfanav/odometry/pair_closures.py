"""Relative-pose loop closures for the pose graph's place pairs: the
relative heading and the direction of the baseline from the two panoramas
(the warping method, :func:`sfanav.loopclosure.relative_poses`), the
distance from the slow features' local gradient and the current map.

A heading-only closure (the panorama compass) fixes how the two passes of
a place are turned against each other but not where they lie: on parallel
lanes the map keeps the odometry's distances and bends. A relative-pose
closure also ties the position of one frame to the other's, so a closure
between neighbouring lanes fixes their lateral offset.

:func:`pair_relative_poses` measures, for every pair (past ``i``, current
``j``):

* the relative heading and the bearing of ``j`` seen from ``i``, with their
  standard deviations and correlation, from the panoramas;
* the distance of the two frames: the current map's own distance
  (standard deviation ``map_distance_sigma``: the map without relative
  positions is off by a few decimetres between lanes), with
  ``use_gradient`` combined by inverse variance with the length of the
  offset that the slow features' local gradient explains (:func:`local_gradients`, a
  linear fit of the features against the current map's positions around
  frame ``i``; :func:`sfanav.loopclosure.relative_pose.gradient_offsets`
  gives its standard deviation from the fit's residual);

and returns them as :class:`~sfanav.odometry.pose_graph_gtsam.RelativePoses`
closures from ``i`` to ``j``. Pairs whose bearing is uninformative (its
standard deviation above ``max_sigma_bearing_deg``) stay heading-only with
the compass's heading. Measurements: docs/odometry.md, "Relative-pose
closures and the gyro on the mower survey".

Example
-------
>>> closures = pair_relative_poses(rows, F, xy, past, current, compass, np.radians(5))  # doctest: +SKIP
>>> solve_pose_graph(odometry, closures).poses  # doctest: +SKIP
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._checks import as_matrix, check_int, check_positive_float
from ..loopclosure.relative_pose import gradient_offsets, relative_poses_by_method
from .pose_graph_gtsam import HEADING_ONLY_SIGMA, RelativePoses

WARP_OPTIONS = {"n_bearings": 48, "ratios": (0.03, 0.08, 0.15, 0.25, 0.4), "max_turn_deg": 20.0}
"""The warping's grid for the pose graph's pairs: coarser than
:func:`~sfanav.loopclosure.relative_poses`'s default (its cost is the
grid's size times the pairs'; the sub-grid parabola keeps the precision)."""


CORRELATION_RADIUS = 1.5
"""Metres: relative-pose closures whose midpoints lie this close share one
place's warping error (:func:`decorrelate`). Chosen on eleven runs' maps
against 1.0 and 2.0 m (docs/odometry.md, "Correlated bearing errors")."""


def local_gradients(features: Any, positions: Any, centres: Any, *, n_neighbors: int = 30) -> np.ndarray:
    """The slow features' gradient ``dF/d(x, y)`` (M, m, 2), per metre, at
    each frame of ``centres`` (M,): the least-squares plane through the
    features of the ``n_neighbors`` frames nearest to it in ``positions``
    (N, 2) (its own included). NaN where those frames lie on a line (the
    plane is not determined across it)."""
    F = as_matrix(features, "features")
    X = as_matrix(positions, "positions")
    if X.shape[1] != 2 or len(X) != len(F):
        raise ValueError(f"positions must have shape ({len(F)}, 2), got {X.shape}")
    k = min(check_int(n_neighbors, "n_neighbors", minimum=3), len(X))
    c = np.asarray(centres, np.int64).reshape(-1)
    _, nn = cKDTree(X).query(X[c], k=k)
    nn = nn.reshape(len(c), k)
    out = np.full((len(c), F.shape[1], 2), np.nan)
    for r in range(len(c)):
        d = X[nn[r]] - X[c[r]]
        A = np.c_[np.ones(k), d]
        s = np.linalg.svd(A[:, 1:] - A[:, 1:].mean(axis=0), compute_uv=False)
        if s[-1] <= 1e-3 * max(s[0], 1e-12) or s[-1] < 1e-6:
            continue
        coef = np.linalg.lstsq(A, F[nn[r]], rcond=None)[0]
        out[r] = coef[1:].T
    return out


def decorrelate(covariance: Any, midpoints: Any, radius: float) -> np.ndarray:
    """Closures' covariances (M, 3, 3) with the position block (the first
    two rows and columns) multiplied by the number of closures whose
    ``midpoints`` (M, 2), metres, lie within ``radius`` of theirs (itself
    included): ``n`` closures of one place whose position errors are fully
    correlated carry the information of one, so each gets ``n`` times its
    variance. The heading block is left as it is (the compass's heading
    errors are small and independent). Returns a new array.

    Why: the warping assumes every landmark at one distance; in a garden
    whose landmarks are not, its bearing errs alike for every pair of a
    place (errors of closures within 1 m correlate 0.07-0.32 on five runs,
    against 0.0 for random pairs; docs/odometry.md), and a pose graph that counts each as
    independent is pulled off by the shared error.

    >>> cov = np.tile(np.eye(3), (3, 1, 1))
    >>> decorrelate(cov, [[0.0, 0.0], [0.5, 0.0], [9.0, 0.0]], 1.0)[:, 0, 0].tolist()
    [2.0, 2.0, 1.0]
    """
    C = np.array(covariance, dtype=np.float64)
    mid = as_matrix(midpoints, "midpoints", min_rows=0)
    if C.ndim != 3 or C.shape[1:] != (3, 3) or mid.shape != (len(C), 2):
        raise ValueError(f"covariance must be (M, 3, 3) and midpoints (M, 2), got {C.shape} and {mid.shape}")
    r = check_positive_float(radius, "radius")
    if len(C) == 0:
        return C
    n = np.array([len(x) for x in cKDTree(mid).query_ball_point(mid, r)], dtype=np.float64)
    f = np.sqrt(n)
    C[:, :2, :] *= f[:, None, None]
    C[:, :, :2] *= f[:, None, None]
    return C


def _rotate_to_j(cov: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """Covariances of (dx, dy, dtheta) in frame i, expressed with the
    position error in frame j (GTSAM's Pose2 local coordinates of the
    measured pose)."""
    c, s = np.cos(dtheta), np.sin(dtheta)
    T = np.zeros((len(cov), 3, 3))
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1], T[:, 2, 2] = c, s, -s, c, 1.0
    out = T @ cov @ np.swapaxes(T, 1, 2)
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def pair_relative_poses_by_method(*args: Any, methods: Any = ("warping", "min-warping"),
                                  **kwargs: Any) -> dict[str, RelativePoses]:
    """:func:`pair_relative_poses` by several warping methods at once
    (``methods``, of :data:`sfanav.loopclosure.relative_pose.METHODS`):
    ``{method: RelativePoses}``, the scores of both from one pass of the
    core. Arguments as :func:`pair_relative_poses` (``warp`` without a
    ``method``); raises as it does, and ValueError for an unknown method."""
    return _pair_relative_poses(*args, methods=tuple(methods), **kwargs)


def pair_relative_poses(images: Any, features: Any, positions: Any, i_idx: Any, j_idx: Any, compass: Any,
                        compass_sigma: float, **kwargs: Any) -> RelativePoses:
    """Loop closures from ``i`` (earlier) to ``j`` for place pairs: relative
    poses where the panoramas tell the baseline's direction, heading-only
    (the compass's) elsewhere. See the module docstring.

    Parameters
    ----------
    images : array (N, H, W[, C])
        The run's 360-degree panoramas.
    features : array (N, m)
        Their slow features (the slowest ones the pairs were found with).
    positions : array (N, 2)
        The current map (m), e.g. the heading-only pose graph's.
    i_idx, j_idx : int arrays (M,)
        The pairs (pose of ``j`` in the frame of ``i``).
    compass, compass_sigma
        The pairs' relative headings (rad, (M,)) from the panorama compass
        and their standard deviation (rad), for the heading-only closures.
    map_distance_sigma : float, default 0.5
        Standard deviation (m) of the map's own distance of a pair.
    use_gradient : bool, default False
        Also measure the distance by the features' local gradient. Off by
        default: on the mower survey its distances came out 0.12 m short
        (median) and the map worse than with heading-only closures, while
        the first map's own distance (0.11 m median error) made it better
        (docs/odometry.md).
    n_neighbors : int, default 30
        Frames of the gradient's local fit.
    gradient_fraction : float, default 0.3
        Standard deviation of the gradient's distance as a fraction of it,
        added (in quadrature) to the fit's own: the gradient is fitted on
        the current map, whose local scale errs, and the features are not
        linear over the neighbourhood.
    max_sigma_bearing_deg : float, default 30
        Pairs whose bearing is less certain stay heading-only.
    gray : bool, default True
        Compare the panoramas' channel means (3x faster on RGB).
    warp : dict, optional
        Keywords of :func:`sfanav.loopclosure.relative_poses` (default
        :data:`WARP_OPTIONS`).
    correlation_radius : float or None, default :data:`CORRELATION_RADIUS`
        Metres. The warping's bearing errors are not independent: closures
        of one place share the landmarks whose unequal distances bias the
        warping alike (:func:`decorrelate`). With a radius, each closure's
        position covariance is multiplied by the number of relative-pose
        closures whose midpoints (in ``positions``) lie within it, so the
        closures of one place count as one measurement. None: each closure
        independent.

    Returns
    -------
    RelativePoses
        M closures in pair order, with covariances (heading-only ones with a
        position sigma of :data:`~sfanav.odometry.pose_graph_gtsam.HEADING_ONLY_SIGMA`).

    Raises
    ------
    ValueError, TypeError
        As :func:`sfanav.loopclosure.relative_poses`; mismatched lengths;
        non-positive sigmas.
    """
    out = _pair_relative_poses(images, features, positions, i_idx, j_idx, compass, compass_sigma, **kwargs)
    return next(iter(out.values()))


def _pair_relative_poses(images: Any, features: Any, positions: Any, i_idx: Any, j_idx: Any, compass: Any,
                         compass_sigma: float, *, map_distance_sigma: float = 0.5, use_gradient: bool = False,
                         n_neighbors: int = 30, gradient_fraction: float = 0.3,
                         max_sigma_bearing_deg: float = 30.0, gray: bool = True,
                         warp: dict[str, Any] | None = None,
                         correlation_radius: float | None = CORRELATION_RADIUS,
                         methods: tuple[str, ...] | None = None) -> dict[str, RelativePoses]:
    F = as_matrix(features, "features")
    X = as_matrix(positions, "positions")
    i = np.asarray(i_idx, np.int64).reshape(-1)
    j = np.asarray(j_idx, np.int64).reshape(-1)
    rel = np.asarray(compass, np.float64).reshape(-1)
    if not (len(i) == len(j) == len(rel)):
        raise ValueError(f"i_idx, j_idx and compass must have one length, got {len(i)}, {len(j)}, {len(rel)}")
    if X.shape != (len(F), 2):
        raise ValueError(f"positions must have shape ({len(F)}, 2), got {X.shape}")
    cs = check_positive_float(compass_sigma, "compass_sigma")
    ms = check_positive_float(map_distance_sigma, "map_distance_sigma")
    gf = check_positive_float(gradient_fraction, "gradient_fraction")
    maxb = np.radians(check_positive_float(max_sigma_bearing_deg, "max_sigma_bearing_deg"))
    radius = None if correlation_radius is None else check_positive_float(correlation_radius, "correlation_radius")
    m = len(i)
    dist = np.maximum(np.hypot(*(X[j] - X[i]).T), 1e-3)
    w = np.full(m, 1.0 / ms**2)
    if use_gradient and m and F.shape[1] > 2:
        G = local_gradients(F, X, i, n_neighbors=n_neighbors)
        ok = np.isfinite(G).all(axis=(1, 2))
        if ok.any():
            try:
                off, cov = gradient_offsets(F, i[ok], j[ok], G[ok])
            except ValueError:  # a singular local gradient: the map's distance alone
                off, cov = None, None
            if off is not None:
                fd = np.hypot(*off.T)
                u = off / np.maximum(fd, 1e-12)[:, None]
                fv = np.einsum("ki,kij,kj->k", u, cov, u) + (gf * fd) ** 2
                good = np.isfinite(fv) & (fv > 0)
                idx = np.flatnonzero(ok)[good]
                wf = 1.0 / fv[good]
                dist[idx] = (dist[idx] * w[idx] + fd[good] * wf) / (w[idx] + wf)
                w[idx] = w[idx] + wf
    dsig = 1.0 / np.sqrt(w)
    # only the pairs' frames, gray (the warping compares columns; colour adds cost, not geometry)
    used, inv = np.unique(np.r_[i, j], return_inverse=True)
    sub = np.asarray(images)[used]
    if gray and sub.ndim == 4:
        sub = sub.astype(np.float32).mean(axis=3)
    wopts = dict(WARP_OPTIONS if warp is None else warp)
    methods = methods or (wopts.get("method", "warping"),)
    wopts.pop("method", None)
    rps = relative_poses_by_method(sub, inv[:m], inv[m:], distance=np.maximum(dist, 1e-3), distance_sigma=dsig,
                                   methods=methods, **wopts)
    out = {}
    for name, rp in rps.items():
        rp.i, rp.j = i, j
        out[name] = _closures(rp, X, rel, cs, maxb, radius)
    return out


def _closures(rp: Any, X: np.ndarray, rel: np.ndarray, cs: float, maxb: float, radius: float | None) -> RelativePoses:
    """The pose graph's closures from one method's relative poses (see
    :func:`pair_relative_poses`)."""
    i, j, m = rp.i, rp.j, len(rp.i)
    good = rp.informative(maxb) & np.isfinite(rp.covariance).all(axis=(1, 2))
    cov = np.zeros((m, 3, 3))
    cov[:, 0, 0] = cov[:, 1, 1] = HEADING_ONLY_SIGMA**2
    cov[:, 2, 2] = cs**2
    if good.any():
        full = _rotate_to_j(rp.covariance[good], rp.dtheta[good])
        full += np.eye(3)[None] * 1e-10
        cov[good] = full
    if radius is not None and good.any():
        cov[good] = decorrelate(cov[good], 0.5 * (X[i[good]] + X[j[good]]), radius)
    dx = np.where(good, rp.dx, 0.0)
    dy = np.where(good, rp.dy, 0.0)
    dth = np.where(good, rp.dtheta, rel)
    return RelativePoses(i, j, dx, dy, dth, covariance=cov)
