"""Spatial pairs of training images for graph-based SFA (Escalante &
Wiskott 2013): extra derivative pairs between images of nearby places,
which :meth:`sfanav.Network.fit` adds at every simulated rotation.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def check_pairs(pairs: Any, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validates ``(idx_a, idx_b, weights[, shifts])`` against ``n`` images:
    int64 indices, float64 weights, int64 shifts (zeros when absent)."""
    if not (isinstance(pairs, (tuple, list)) and len(pairs) in (3, 4)):
        raise TypeError("pairs must be a tuple (idx_a, idx_b, weights[, shifts])")
    a, b, w = (np.asarray(x) for x in pairs[:3])
    sh = np.asarray(pairs[3]) if len(pairs) == 4 else np.zeros(len(a), dtype=np.int64)
    if sh.ndim != 1 or len(sh) != len(a) or (len(sh) and sh.dtype.kind not in "iu"):
        raise ValueError("pairs: shifts must be 1-D integers (pixels), one per pair")
    if not (a.ndim == b.ndim == w.ndim == 1 and len(a) == len(b) == len(w)):
        raise ValueError(
            f"pairs: idx_a, idx_b and weights must be 1-D of one length, got shapes {a.shape}, {b.shape}, {w.shape}"
        )
    for name, idx in (("idx_a", a), ("idx_b", b)):
        if len(idx) and idx.dtype.kind not in "iu":
            raise TypeError(f"pairs: {name} must hold integer image indices, got dtype {idx.dtype}")
        if len(idx) and (idx.min() < 0 or idx.max() >= n):
            raise ValueError(f"pairs: {name} must index the {n} training images (0..{n - 1})")
    if w.dtype.kind not in "iuf" and len(w):
        raise TypeError(f"pairs: weights must be numbers, got dtype {w.dtype}")
    w = w.astype(np.float64)
    if not np.all(np.isfinite(w) & (w >= 0)):
        raise ValueError("pairs: weights must be finite and >= 0")
    return a.astype(np.int64), b.astype(np.int64), w, sh.astype(np.int64)


def spatial_pairs(xy: Any, radius: float, k: int | None = None, *, min_gap: int = 0, weights: str = "uniform",
                  scale: float | None = None, shifts: int | None = None, shift_step: int = 1,
                  seed: int = 0) -> tuple[np.ndarray, ...]:
    """Spatial-neighbour pairs of training positions for
    :meth:`Network.fit` ``(pairs=...)`` (graph-based SFA, Escalante &
    Wiskott 2013).

    Parameters
    ----------
    xy : array (N, 2)
        Training positions (ground truth or odometry), in any unit.
    radius : float
        Pairs join positions closer than ``radius`` (same unit).
    k : int or None
        Each image keeps at most its ``k`` nearest neighbours within the
        radius (None: all). A pair is kept if either end selects it.
    min_gap : int
        Leave out pairs of images fewer than ``min_gap`` frames apart in
        the run (e.g. neighbours along the same lane, which the sequence
        already links), so ``k`` goes to other passes and crossings.
    weights : "uniform" or "gaussian"
        1 per pair, or ``exp(-d^2 / (2 scale^2))`` (``scale`` default
        ``radius / 2``).
    shifts : int or None
        The panorama width W: also return, per pair, a column shift drawn
        uniformly from ``0..W-1`` (``seed``), for :meth:`Network.fit` to
        compare the two images at a random relative orientation.
    shift_step : int
        Draw the shifts as multiples of this (e.g. the rotation step, so
        that training can read them from the field cache).

    Returns
    -------
    (idx_a, idx_b, weights[, shifts]) : int64 (P,), int64 (P,), float64 (P,)[, int64 (P,)]
        Each unordered pair once, ``idx_a < idx_b``, sorted.
    """
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"xy must have shape (N, 2), got {xy.shape}")
    if not np.all(np.isfinite(xy)):
        raise ValueError("xy contains NaN or infinity")
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive number, got {radius!r}")
    if k is not None and (isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1):
        raise ValueError(f"k must be a positive integer or None, got {k!r}")
    if isinstance(min_gap, bool) or not isinstance(min_gap, (int, np.integer)) or min_gap < 0:
        raise ValueError(f"min_gap must be a non-negative integer, got {min_gap!r}")
    if weights not in ("uniform", "gaussian"):
        raise ValueError(f'weights must be "uniform" or "gaussian", got {weights!r}')
    from scipy.spatial import cKDTree

    tree = cKDTree(xy)
    found: set[tuple[int, int]] = set()
    for i, nb in enumerate(tree.query_ball_point(xy, r=radius)):
        nb = [j for j in nb if abs(j - i) >= max(min_gap, 1)]
        if k is not None and len(nb) > k:
            d = np.hypot(*(xy[nb] - xy[i]).T)
            nb = [nb[j] for j in np.argsort(d, kind="stable")[:k]]
        found.update((min(i, j), max(i, j)) for j in nb)
    if not found:
        e = np.zeros(0, dtype=np.int64)
        return (e, e.copy(), np.zeros(0)) + ((e.copy(),) if shifts else ())
    ab = np.array(sorted(found), dtype=np.int64)
    d = np.hypot(*(xy[ab[:, 0]] - xy[ab[:, 1]]).T)
    if weights == "uniform":
        w = np.ones(len(ab))
    else:
        s = radius / 2 if scale is None else float(scale)
        w = np.exp(-(d**2) / (2 * s**2))
    if shifts:
        q = max(1, int(shift_step))
        sh = q * np.random.default_rng(seed).integers(0, -(-int(shifts) // q), len(ab))
        return ab[:, 0].copy(), ab[:, 1].copy(), w, sh.astype(np.int64)
    return ab[:, 0].copy(), ab[:, 1].copy(), w
