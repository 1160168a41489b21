"""Relative poses of loop closures from two panoramas: the relative heading,
the direction of the baseline and (given a distance) the offset, with a
covariance, as a 2-D pose-graph factor.

Two 360-degree panoramas of one place taken at two nearby positions differ
by a rotation (a column shift, the relative heading) and by parallax: seen
from the second position every landmark has moved away from the direction
of the baseline and towards its opposite, the more the nearer it is. The
*warping method* of snapshot homing (Franz, Schoelkopf, Mallot and Buelthoff
1998, "Where did I take that snapshot?") models this with one parameter per
hypothesis: all landmarks at one distance ``R`` from frame ``i``; for a
baseline direction ``alpha`` (in frame ``i``), a ratio ``nu = d / R`` and a
relative heading ``psi``, a landmark at bearing ``b`` from ``i`` appears
from ``j`` at bearing

    atan2(sin b - nu sin alpha, cos b - nu cos alpha) - psi.

:func:`relative_poses` warps the columns of panorama ``i`` for every
hypothesis on a grid (``n_bearings`` directions, the ``ratios``, every
column shift), scores it by the mean squared difference between each column
of ``i`` and the (linearly interpolated) column of ``j`` it predicts, and
takes the best hypothesis (refined between grid points by a parabola). The
scores become a pseudo-posterior (``exp(-(S - S_min) / (2 tau))`` with
``tau = temperature * S_min / (W * K)``, ``K`` values per column: the
residual variance of the best hypothesis, inflated for the correlation of
neighbouring pixels), whose spread gives the standard deviations of the
baseline direction and the relative heading and their correlation: flat
scores (a featureless scene) give a spread over the whole circle.

``method="min-warping"`` (Moeller 2009, "Local visual homing by warping
of two-dimensional images") drops the one-distance assumption: each column
of ``i`` takes its own best ratio of the grid (its landmark's distance),
and a hypothesis is a baseline direction and a heading only. Landmarks at
unequal distances then no longer pull the direction and the heading
towards the nearer ones (docs/relative-pose.md, "Min-warping").

The warping gives direction, not distance: ``nu`` mixes the distance of the
frames with the unknown distance of the landmarks. The distance comes from
outside: a prior (``distance``, e.g. the odometry's or the lane spacing)
and/or the slow features' local gradient (``features`` and ``gradient``:
:func:`gradient_offsets` solves ``F_j - F_i = G (p_j - p_i)`` by least
squares; its length is frame-free). See docs/relative-pose.md for the
methods considered, the choice and the measurement.

>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> pano = rng.random((1, 4, 72))
>>> images = np.concatenate([pano, np.roll(pano, 6, axis=2)])   # frame 1 turned 30 deg left
>>> rp = relative_poses(images, [0], [1])
>>> round(float(np.degrees(rp.dtheta[0])), 1)
30.0
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_images, as_matrix, as_real_array, check_int, check_positive_float
from .closures import panorama_rows

DEFAULT_RATIOS = (0.02, 0.05, 0.1, 0.15, 0.22, 0.3, 0.4)
"""Ratios ``nu = d / R`` (distance between the frames over the assumed
distance of the landmarks) that the warping tries."""

DEFAULT_TEMPERATURE = 48.0
"""Inflation of the pseudo-posterior's temperature over independent pixel
noise (neighbouring pixels are correlated); calibrated on the measurement in
docs/relative-pose.md."""

METHODS = ("warping", "min-warping")
"""The warping variants :func:`relative_poses` offers: one landmark distance
per hypothesis, or one per column (min-warping)."""

DEFAULT_DISTANCE_FRACTION = 0.3
"""Standard deviation of a distance prior, as a fraction of it, when
``distance_sigma`` is not given."""


@dataclass
class RelativePoses:
    """Relative poses of pairs of frames, in the frame of ``i``.

    Attributes (all arrays (M,), angles in rad, lengths in m)
    ----------
    i, j : int64
        The frames of each pair.
    dtheta : float64
        Heading of ``j`` minus heading of ``i``, in (-pi, pi].
    bearing : float64
        Direction of ``j`` seen from ``i``, in ``i``'s frame
        (counter-clockwise from ``i``'s heading), in (-pi, pi].
    distance : float64
        Distance between the frames (NaN without a distance source).
    dx, dy : float64
        Position of ``j`` in ``i``'s frame (x ahead, y left);
        ``distance * (cos, sin)(bearing)``, NaN without a distance.
    sigma_dtheta, sigma_bearing, sigma_distance : float64
        Standard deviations (``inf`` when the images or the distance sources
        cannot tell).
    covariance : float64 (M, 3, 3)
        Covariance of ``(dx, dy, dtheta)``, ready for a
        ``BetweenFactorPose2`` from ``i`` to ``j``; without a distance its
        position rows and columns are ``inf`` on the diagonal and 0 off it.
    contrast : float64
        ``1 - S_min / S_median`` of the warping scores: 0 for images that
        tell nothing, near 1 for a distinct best match.
    """

    i: np.ndarray
    j: np.ndarray
    dtheta: np.ndarray
    bearing: np.ndarray
    distance: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    sigma_dtheta: np.ndarray
    sigma_bearing: np.ndarray
    sigma_distance: np.ndarray
    covariance: np.ndarray
    contrast: np.ndarray

    def __len__(self) -> int:
        return len(self.i)

    def informative(self, max_sigma_bearing: float = np.radians(30.0)) -> np.ndarray:
        """Bool (M,): pairs whose baseline direction is known to within
        ``max_sigma_bearing`` rad (one standard deviation)."""
        return np.isfinite(self.sigma_bearing) & (self.sigma_bearing <= max_sigma_bearing)


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * np.asarray(a, float)))


def _column_bearings(W: int) -> np.ndarray:
    """Bearing of each column (rad, counter-clockwise from the heading), as
    :func:`sfanav.sim.bearings`: the middle column looks ahead."""
    return -2 * np.pi * (np.arange(W) + 0.5 - W / 2) / W


def _warp_columns(W: int, alphas: np.ndarray, ratios: np.ndarray) -> np.ndarray:
    """Fractional column (A, N, W) of panorama ``j`` where column ``u`` of
    panorama ``i`` appears for each baseline direction and ratio, with zero
    relative heading (a heading ``psi`` adds ``psi W / (2 pi)`` columns)."""
    b = _column_bearings(W)[None, None, :]
    a = alphas[:, None, None]
    nu = ratios[None, :, None]
    bj = np.arctan2(np.sin(b) - nu * np.sin(a), np.cos(b) - nu * np.cos(a))
    return (W / 2 - 0.5 - bj * W / (2 * np.pi)) % W


def _parabola(prof: np.ndarray, k: int) -> float:
    """Sub-grid offset (in grid steps, within +-0.5) of the minimum of a
    circular profile at its grid minimum ``k``."""
    n = len(prof)
    m, c, p = prof[(k - 1) % n], prof[k], prof[(k + 1) % n]
    den = m - 2 * c + p
    return float(np.clip(0.5 * (m - p) / den, -0.5, 0.5)) if den > 0 else 0.0


def _normalised(rows: np.ndarray) -> np.ndarray | None:
    """Rows (K, W) mean-free per row and scaled to unit overall standard
    deviation; None for an image without contrast."""
    a = rows - rows.mean(axis=1, keepdims=True)
    s = float(np.sqrt((a * a).mean()))
    scale = max(float(np.abs(rows).max()), 1e-12)
    return None if s <= 1e-6 * scale else a / s


def _pair_setup(a: np.ndarray, b: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The normalised row images of a pair and the relative headings (column
    shifts) to try: every shift, or a window around the circular
    cross-correlation's best shift (the panorama compass); None for an image
    without contrast."""
    W = a.shape[1]
    na, nb = _normalised(a), _normalised(b)
    if na is None or nb is None:
        return None
    if window >= W // 2:
        return na, nb, np.arange(W, dtype=float)
    corr = np.fft.irfft((np.fft.rfft(nb, axis=1) * np.conj(np.fft.rfft(na, axis=1))).sum(axis=0), n=W)
    s0 = int(np.argmax(corr))
    return na, nb, (s0 + np.arange(-window, window + 1)).astype(float)


def _scores_reference(na: np.ndarray, nb: np.ndarray, cols: np.ndarray, shifts: np.ndarray,
                      min_warping: bool = False) -> np.ndarray:
    """The warping scores (A, N, S) of one pair in numpy (min-warping: (A, 1,
    S), each column's best ratio): the reference the core's
    :func:`sfanav._core.warp_scores` is tested against."""
    W = na.shape[1]
    D = (na * na).sum(0)[:, None] + (nb * nb).sum(0)[None, :] - 2.0 * (na.T @ nb)  # D[u, v]
    flat = D.ravel()
    A, N, _ = cols.shape
    rowbase = np.arange(W) * W
    S = np.empty((A, 1 if min_warping else N, len(shifts)))
    for a0 in range(0, A, 16):
        c = cols[a0 : a0 + 16, :, None, :] + shifts[None, None, :, None]  # (a, N, S, W)
        f = np.floor(c)
        t = c - f
        f = f.astype(np.int64) % W
        d = flat[rowbase + f] * (1 - t) + flat[rowbase + (f + 1) % W] * t
        S[a0 : a0 + 16] = d.min(axis=1, keepdims=True).mean(axis=3) if min_warping else d.mean(axis=3)
    return S


def _pose_from_scores(S: np.ndarray, alphas: np.ndarray, shifts: np.ndarray, W: int, K: int,
                      temperature: float) -> tuple[float, float, float, float, float, float]:
    """(dtheta, bearing, sigma_dtheta, sigma_bearing, corr, contrast) of one
    pair from its warping scores ``S`` (A, N, n_shifts)."""
    A = len(alphas)
    n_s = len(shifts)
    smin = float(S.min())
    contrast = float(1.0 - smin / max(float(np.median(S)), 1e-300))
    tau = max(temperature * smin / (W * K), 1e-9 * float(np.median(S)), 1e-300)
    w = np.exp(-(S - smin) / (2 * tau))
    w /= w.sum()
    ka, _, ks = np.unravel_index(int(np.argmin(S)), S.shape)
    da, ds = 2 * np.pi / A, 2 * np.pi / W
    alpha = alphas[ka] + da * _parabola(S.min(axis=(1, 2)), ka)
    sprof = S.min(axis=(0, 1))
    frac = _parabola(sprof, ks) if n_s == W or 0 < ks < n_s - 1 else 0.0
    psi = ds * (shifts[ks] + frac)
    pa = w.sum(axis=1)  # (A, S) joint marginal of direction and heading
    ea = _wrap(alphas - alpha)[:, None]
    es = _wrap(ds * shifts - psi)[None, :]
    # spread about the estimate, floored by the grid's quantisation
    va = float((pa * ea**2).sum()) + da**2 / 12
    vs = float((pa * es**2).sum()) + ds**2 / 12
    cas = float((pa * ea * es).sum())
    # a spread near a uniform circle's (pi^2 / 3) means the images cannot tell
    sa = np.inf if va > 0.5 * np.pi**2 / 3 else np.sqrt(va)
    ss = np.inf if vs > 0.5 * np.pi**2 / 3 else np.sqrt(vs)
    corr = cas / np.sqrt(va * vs) if np.isfinite(sa) and np.isfinite(ss) else 0.0
    return float(_wrap(psi)), float(_wrap(alpha)), float(ss), float(sa), float(corr), contrast


_NO_CONTRAST = (0.0, 0.0, np.inf, np.inf, 0.0, 0.0)
_CHUNK = 64
"""Pairs scored per call of the core (bounds the images copied at once)."""


def _warp_pairs(R: np.ndarray, i: np.ndarray, j: np.ndarray, cols: np.ndarray, alphas: np.ndarray,
                temperature: float, window: int, methods: tuple[str, ...] = ("warping",)) -> dict[str, np.ndarray]:
    """(M, 6) rows of :func:`_pose_from_scores` per method for the pairs
    ``(i, j)`` of the row images ``R`` (n, K, W); the scores in the Rust
    core, in parallel (min-warping: each column's best ratio; both methods:
    one pass of the core for the two)."""
    from .. import _core

    _, K, W = R.shape
    A, N, _ = cols.shape
    flat_cols = np.ascontiguousarray(cols.reshape(A * N, W))
    out = {m: np.array([_NO_CONTRAST] * len(i), dtype=float).reshape(len(i), 6) for m in methods}
    for c0 in range(0, len(i), _CHUNK):
        setups = [(k, _pair_setup(R[i[k]], R[j[k]], window)) for k in range(c0, min(c0 + _CHUNK, len(i)))]
        setups = [(k, st) for k, st in setups if st is not None]
        if not setups:
            continue
        a = np.stack([st[0] for _, st in setups])
        b = np.stack([st[1] for _, st in setups])
        sh = np.stack([st[2] for _, st in setups])
        if len(methods) == 2:
            each, mins = _core.warp_and_min_warp_scores(a, b, flat_cols, sh, N)
            scores = {"warping": each, "min-warping": mins}
        else:
            scores = {methods[0]: _core.warp_scores(a, b, flat_cols, sh, N if methods[0] == "min-warping" else 1)}
        for m in methods:
            S = scores[m].reshape(len(setups), A, -1, sh.shape[1])
            for (k, st), Sk in zip(setups, S):
                out[m][k] = _pose_from_scores(Sk, alphas, st[2], W, K, temperature)
    return out


def gradient_offsets(features: Any, i_idx: Any, j_idx: Any, gradient: Any) -> tuple[np.ndarray, np.ndarray]:
    """Offsets ``p_j - p_i`` from the slow features' local gradient.

    Solves ``F_j - F_i = G (p_j - p_i)`` by least squares for every pair,
    with the covariance ``s^2 (G^T G)^-1`` (``s^2`` the residual's mean
    square over ``m - 2`` degrees of freedom; ``inf`` with 2 features).

    Parameters
    ----------
    features : array (N, m)
        The run's slow features.
    i_idx, j_idx : int arrays (M,)
        The pairs.
    gradient : array (m, 2) or (M, m, 2)
        ``dF/d(x, y)`` (per metre) near the pairs, one for all or one per
        pair, in the frame the offsets are wanted in (the map's).

    Returns
    -------
    offset : (M, 2) metres; covariance : (M, 2, 2).

    >>> G = np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])
    >>> F = np.array([[0.0, 0.0, 0.0], G @ [0.5, -0.25]])
    >>> gradient_offsets(F, [0], [1], G)[0].round(6).tolist()
    [[0.5, -0.25]]
    """
    F = as_matrix(features, "features")
    i, j = _pairs(i_idx, j_idx, len(F))
    G = as_real_array(gradient, "gradient").astype(np.float64)
    m = F.shape[1]
    if G.ndim == 2:
        G = np.broadcast_to(G, (len(i),) + G.shape)
    if G.shape != (len(i), m, 2):
        raise ValueError(f"gradient must have shape ({m}, 2) or ({len(i)}, {m}, 2) for {m} features and "
                         f"{len(i)} pairs, got {np.shape(gradient)}")
    if not np.isfinite(G).all():
        raise ValueError("gradient contains NaN or infinity")
    dF = F[j] - F[i]
    GtG = np.einsum("kmi,kmj->kij", G, G)
    det = GtG[:, 0, 0] * GtG[:, 1, 1] - GtG[:, 0, 1] ** 2
    if np.any(det <= 1e-12 * np.maximum(np.einsum("kii->k", GtG) ** 2, 1e-300)):
        raise ValueError("gradient is singular for some pair (its two columns are parallel or zero)")
    inv = np.linalg.inv(GtG)
    off = np.einsum("kij,kmj,km->ki", inv, G, dF)
    res = dF - np.einsum("kmi,ki->km", G, off)
    s2 = (res**2).sum(axis=1) / (m - 2) if m > 2 else np.full(len(i), np.inf)
    return off, s2[:, None, None] * inv


def _pairs(i_idx: Any, j_idx: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    out = []
    for name, v in (("i_idx", i_idx), ("j_idx", j_idx)):
        a = np.asarray(v)
        if a.ndim != 1 or (a.size and a.dtype.kind not in "iu"):
            raise TypeError(f"{name} must be a 1-D array of integer frame indices, got shape {a.shape}, "
                            f"dtype {a.dtype}")
        a = a.astype(np.int64)
        if a.size and (a.min() < 0 or a.max() >= n):
            raise ValueError(f"{name} must index the {n} frames (0..{n - 1}), got values in "
                             f"[{a.min()}, {a.max()}]")
        out.append(a)
    if len(out[0]) != len(out[1]):
        raise ValueError(f"i_idx has {len(out[0])} pairs but j_idx has {len(out[1])}; they must match")
    return out[0], out[1]


def _per_pair(v: Any, name: str, m: int, positive: bool) -> np.ndarray:
    a = as_real_array(v, name).astype(np.float64)
    a = np.broadcast_to(a, (m,)).copy() if a.ndim == 0 else a
    if a.shape != (m,):
        raise ValueError(f"{name} must be a number or have shape ({m},), got shape {a.shape}")
    if not np.isfinite(a).all() or np.any(a <= 0 if positive else a < 0):
        raise ValueError(f"{name} must be finite and {'> 0' if positive else '>= 0'}")
    return a


def relative_poses(images: Any, i_idx: Any, j_idx: Any, *, distance: Any = None, distance_sigma: Any = None,
                   features: Any = None, gradient: Any = None, rows: Any = None, n_bearings: int = 96,
                   ratios: Any = DEFAULT_RATIOS, temperature: float = DEFAULT_TEMPERATURE,
                   max_turn_deg: float | None = 30.0, method: str = "warping") -> RelativePoses:
    """Relative poses (heading, baseline direction, offset) of pairs of
    panoramas by the warping method, with a covariance.

    Parameters
    ----------
    images : array (N, H, W) or (N, H, W, C)
        360-degree panoramas; column ``c`` looks at bearing
        ``-2 pi (c + 0.5 - W / 2) / W`` from the heading (as
        :class:`sfanav.sim.PanoramicCamera`), channels count as rows.
    i_idx, j_idx : int arrays (M,)
        The pairs: the pose of ``j`` is given in the frame of ``i``.
    distance, distance_sigma : float or (M,), optional
        A distance prior (m) and its standard deviation (default
        ``DEFAULT_DISTANCE_FRACTION * distance``).
    features, gradient : optional
        The run's slow features (N, m) and their local gradient (m, 2) or
        (M, m, 2): the length of :func:`gradient_offsets` is a distance
        measurement, combined with a prior by inverse variance.
    rows : slice or int array, optional
        The image rows to compare (default all; e.g. leave out the ground
        near the robot, which the equal-distance assumption fits worst).
    n_bearings : int
        Baseline directions tried (a grid over 360 degrees; >= 8).
    ratios : sequence of float in (0, 1)
        ``d / R`` values tried (see the module's docs).
    temperature : float
        Inflation of the pseudo-posterior's temperature (see the module).
    max_turn_deg : float or None
        The relative headings tried: within this many degrees of the
        panorama compass's (the circular cross-correlation's best shift;
        parallax moves the true one by a few degrees), or every column
        shift with None (slower). The window also bounds ``sigma_dtheta``
        (a featureless scene then reports about ``max_turn_deg / sqrt(3)``
        rather than ``inf``; ``sigma_bearing`` still tells).
    method : "warping" or "min-warping"
        One landmark distance (ratio) per hypothesis, or each column's best
        ratio (min-warping; see the module's docs); about the same cost.

    Returns
    -------
    RelativePoses

    Raises
    ------
    TypeError, ValueError
        Images that are not a batch of panoramas, indices that are not
        1-D integers within the frames or of different lengths, a
        non-positive distance or sigma, ``features`` without ``gradient``
        (or the reverse), ratios outside (0, 1), an unknown method.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> pano = rng.random((2, 3, 48))
    >>> rp = relative_poses(pano, [0], [1], distance=1.0)
    >>> rp.covariance.shape
    (1, 3, 3)
    """
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    return relative_poses_by_method(images, i_idx, j_idx, distance=distance, distance_sigma=distance_sigma,
                                    features=features, gradient=gradient, rows=rows, n_bearings=n_bearings,
                                    ratios=ratios, temperature=temperature, max_turn_deg=max_turn_deg,
                                    methods=(method,))[method]


def relative_poses_by_method(images: Any, i_idx: Any, j_idx: Any, *, distance: Any = None,
                             distance_sigma: Any = None, features: Any = None, gradient: Any = None,
                             rows: Any = None, n_bearings: int = 96, ratios: Any = DEFAULT_RATIOS,
                             temperature: float = DEFAULT_TEMPERATURE, max_turn_deg: float | None = 30.0,
                             methods: Any = METHODS) -> dict[str, RelativePoses]:
    """:func:`relative_poses` by several methods at once: ``{method:
    RelativePoses}`` for each of ``methods`` (of :data:`METHODS`), the
    scores of both methods from one pass of the core (about 1.2x the cost
    of one). Parameters and errors as :func:`relative_poses`.

    >>> rng = np.random.default_rng(1)
    >>> pano = rng.random((2, 3, 48))
    >>> sorted(relative_poses_by_method(pano, [0], [1], distance=1.0))
    ['min-warping', 'warping']
    """
    X = as_images(images)
    R = panorama_rows(X).astype(np.float64)
    if rows is not None:
        R = R[:, rows, :] if isinstance(rows, slice) else R[:, _row_index(rows, R.shape[1]), :]
        if R.shape[1] == 0:
            raise ValueError("rows selects no image rows")
    n, _, W = R.shape
    if W < 8:
        raise ValueError(f"panoramas must be at least 8 columns wide, got {W}")
    i, j = _pairs(i_idx, j_idx, n)
    m = len(i)
    A = check_int(n_bearings, "n_bearings", minimum=8)
    nus = as_real_array(ratios, "ratios").astype(np.float64).ravel()
    if nus.size == 0 or not np.all((nus > 0) & (nus < 1)):
        raise ValueError(f"ratios must be numbers in (0, 1), got {ratios!r}")
    temp = check_positive_float(temperature, "temperature")
    given = methods
    methods = (methods,) if isinstance(methods, str) else tuple(methods)
    if not methods or len(set(methods)) != len(methods) or any(m not in METHODS for m in methods):
        raise ValueError(f"method must be one of {METHODS}, got {given!r}")
    if (features is None) != (gradient is None):
        raise ValueError("features and gradient go together: give both or neither")

    # distance sources (m, sigma), combined by inverse variance
    dist = np.full(m, np.nan)
    dsig = np.full(m, np.inf)
    if distance is not None:
        dist = _per_pair(distance, "distance", m, positive=True)
        dsig = (DEFAULT_DISTANCE_FRACTION * dist if distance_sigma is None
                else _per_pair(distance_sigma, "distance_sigma", m, positive=True))
    elif distance_sigma is not None:
        raise ValueError("distance_sigma needs a distance")
    if features is not None:
        F = as_matrix(features, "features")
        if len(F) != n:
            raise ValueError(f"features has {len(F)} rows for {n} images; they must match")
        off, cov = gradient_offsets(F, i, j, gradient)
        fd = np.hypot(off[:, 0], off[:, 1])
        u = off / np.maximum(fd, 1e-12)[:, None]
        fs = np.sqrt(np.maximum(np.einsum("ki,kij,kj->k", u, cov, u), 1e-12))
        have = np.isfinite(dist)
        wp, wf = np.where(have, 1 / dsig**2, 0.0), 1 / fs**2
        dist = np.where(have, dist, 0.0) * wp / (wp + wf) + fd * wf / (wp + wf)
        dsig = 1 / np.sqrt(wp + wf)

    alphas = 2 * np.pi * np.arange(A) / A - np.pi
    cols = _warp_columns(W, alphas, nus)
    win = W // 2 if max_turn_deg is None else int(np.ceil(check_positive_float(max_turn_deg, "max_turn_deg")
                                                          * W / 360.0))
    outs = _warp_pairs(R, i, j, cols, alphas, temp, win, methods)
    known = np.isfinite(dist) & np.isfinite(dsig)
    return {m: _relative_poses_of(i, j, outs[m], dist.copy(), dsig, known) for m in methods}


def _relative_poses_of(i: np.ndarray, j: np.ndarray, out: np.ndarray, dist: np.ndarray, dsig: np.ndarray,
                       known: np.ndarray) -> RelativePoses:
    """The :class:`RelativePoses` of the pairs from their warping rows
    (:func:`_warp_pairs`) and distances."""
    m = len(i)
    dth, brg, sth, sbr, corr, contrast = out.T
    c, s = np.cos(brg), np.sin(brg)
    dx, dy = dist * c, dist * s
    cov = np.zeros((m, 3, 3))
    cov[:, 2, 2] = sth**2
    for k in range(m):
        if not known[k] or not np.isfinite(sbr[k]):
            cov[k, 0, 0] = cov[k, 1, 1] = np.inf
            continue
        J = np.array([[c[k], -dist[k] * s[k], 0.0], [s[k], dist[k] * c[k], 0.0], [0.0, 0.0, 1.0]])
        cab = corr[k] * sbr[k] * sth[k] if np.isfinite(sth[k]) else 0.0
        Sin = np.array([[dsig[k] ** 2, 0.0, 0.0], [0.0, sbr[k] ** 2, cab], [0.0, cab, sth[k] ** 2]])
        cov[k] = J @ Sin @ J.T
    return RelativePoses(i, j, dth, brg, dist, dx, dy, sth, sbr, np.where(known, dsig, np.inf), cov, contrast)


def reference_warping(images: Any, i_idx: Any, j_idx: Any, *, n_bearings: int = 96, ratios: Any = DEFAULT_RATIOS,
                      temperature: float = DEFAULT_TEMPERATURE, max_turn_deg: float = 30.0,
                      method: str = "warping") -> np.ndarray:
    """The warping of :func:`relative_poses` pair by pair in numpy, without
    the Rust core: the independent reference its tests and
    ``benches/bench_relative_pose.py`` compare against (slow: about 0.1 s
    per pair of 350x40 panoramas).

    Returns an array (M, 6): relative heading, bearing (rad), their sigmas,
    their correlation and the scores' contrast per pair, as
    :class:`RelativePoses` holds them. Takes the images, pairs and grid
    options of :func:`relative_poses` (all rows, no distance)."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    R = panorama_rows(as_images(images)).astype(np.float64)
    n, K, W = R.shape
    i, j = _pairs(i_idx, j_idx, n)
    A = check_int(n_bearings, "n_bearings", minimum=8)
    alphas = 2 * np.pi * np.arange(A) / A - np.pi
    cols = _warp_columns(W, alphas, as_real_array(ratios, "ratios").astype(np.float64).ravel())
    win = int(np.ceil(check_positive_float(max_turn_deg, "max_turn_deg") * W / 360.0))
    out = np.array([_NO_CONTRAST] * len(i), dtype=float).reshape(len(i), 6)
    for k, (a, b) in enumerate(zip(i, j)):
        st = _pair_setup(R[a], R[b], win)
        if st is not None:
            S = _scores_reference(st[0], st[1], cols, st[2], min_warping=method == "min-warping")
            out[k] = _pose_from_scores(S, alphas, st[2], W, K, temperature)
    return out


def _row_index(rows: Any, H: int) -> np.ndarray:
    r = np.asarray(rows)
    if r.ndim != 1 or r.dtype.kind not in "iu":
        raise TypeError(f"rows must be a slice or a 1-D integer array, got shape {r.shape}, dtype {r.dtype}")
    if r.size and (r.min() < -H or r.max() >= H):
        raise ValueError(f"rows must index the {H} image rows (channels count as rows)")
    return r.astype(np.int64)
