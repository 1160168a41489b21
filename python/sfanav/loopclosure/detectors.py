"""Loop-closure detectors behind one interface.

Every detector answers :meth:`LoopClosureDetector.candidates` (for every
frame with earlier frames far enough back in the run, its best earlier
match and a score, unthresholded: what precision-recall curves rank) and
:meth:`LoopClosureDetector.detect` (the candidates it accepts, optionally
one per stretch of ``suppress`` frames), both returning
:class:`LoopClosures` with the shift that aligns the earlier panorama.

* :class:`GroundTruthDetector`: the nearest earlier position within
  ``max_distance`` metres (the thesis's closures for its simulator runs);
* :class:`FourierDetector`: the rotation-invariant Fourier signature of
  each panorama, nearest earlier one by L1 distance, accepted when it is at
  most as far as the frame's own temporal neighbours;
* :class:`~sfanav.loopclosure.bow.BagOfWordsDetector`: visual words
  (its own module; :func:`~sfanav.loopclosure.factory.make_detector` names
  all three).

Image-based detectors take an optional odometry gate (earlier frames within
``max_odometry_distance`` metres by dead reckoning).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import as_images, as_matrix, check_int, check_nonneg_float, check_positive_float
from .closures import LoopClosures, align, panorama_rows


class LoopClosureDetector:
    """Base of the detectors: subclasses implement ``_best`` (for every
    frame, the best allowed earlier frame, its dissimilarity, score and
    whether it is accepted). After :meth:`candidates` or :meth:`detect`,
    ``accepted_`` (bool, one per candidate) says which candidates the
    detector accepts."""

    min_gap: int
    suppress: int

    def candidates(self, images: Any, *, positions: Any = None, odometry: Any = None) -> LoopClosures:
        """For every frame that has allowed earlier frames, its best match
        (unthresholded), as :class:`LoopClosures`. ``images`` (N, H, W[, C])
        in temporal order; ``positions`` (N, 2) metres (ground truth);
        ``odometry`` (N, 2 or 3) metres (dead reckoning)."""
        X = as_images(images)
        n = len(X)
        pos = None if positions is None else as_matrix(positions, "positions", n_cols=2)
        odo = None if odometry is None else as_matrix(odometry, "odometry")[:, :2]
        for name, a in (("positions", pos), ("odometry", odo)):
            if a is not None and len(a) != n:
                raise ValueError(f"{name} has {len(a)} rows for {n} images; they must match")
        cur, past, dist, score, ok = self._best(X, pos, odo)
        self.accepted_ = ok
        shift = align(X, past, cur) if len(cur) else np.zeros(0, np.int64)
        return LoopClosures(past, cur, shift, score, dist)

    def detect(self, images: Any, *, positions: Any = None, odometry: Any = None) -> LoopClosures:
        """The accepted loop closures (see :meth:`candidates` for the
        arguments); with ``suppress > 0`` only the best-scoring closure
        within ``suppress`` frames of each other is kept."""
        cand = self.candidates(images, positions=positions, odometry=odometry)
        lc = cand.select(self.accepted_)
        return suppress(lc, self.suppress) if self.suppress else lc

    def _gate(self, n: int, q: np.ndarray, odo: np.ndarray | None, max_odo: float) -> np.ndarray:
        allowed = np.arange(n)[None, :] <= (q[:, None] - self.min_gap)
        if odo is not None:
            allowed &= np.hypot(*(odo[q][:, None, :] - odo[None, :, :]).transpose(2, 0, 1)) <= max_odo
        return allowed

    def _best(self, X: np.ndarray, pos: np.ndarray | None, odo: np.ndarray | None) -> tuple[np.ndarray, ...]:
        raise NotImplementedError


def suppress(lc: LoopClosures, frames: int) -> LoopClosures:
    """Keeps a closure only if no closure with a higher score (ties: the
    earlier) has its current frame within ``frames`` frames: one closure
    per pass over a place."""
    frames = check_int(frames, "suppress", minimum=0)
    if not len(lc) or frames == 0:
        return lc
    order = np.lexsort((lc.current, -lc.score))
    taken = np.zeros(len(lc), bool)
    kept_frames: list[int] = []
    for i in order:
        c = lc.current[i]
        if all(abs(c - k) > frames for k in kept_frames):
            taken[i] = True
            kept_frames.append(int(c))
    return lc.select(taken)


class GroundTruthDetector(LoopClosureDetector):
    """Closures from ground-truth positions: for every frame, the nearest
    frame at least ``min_gap`` frames earlier, accepted when it is within
    ``max_distance`` metres. Score ``1 / (1 + d / max_distance)``.

    >>> xy = np.array([[0, 0], [1, 0], [2, 0], [1, 1], [1.02, 0.05]], float)
    >>> lc = GroundTruthDetector(max_distance=0.1, min_gap=2).detect(np.zeros((5, 2, 8)), positions=xy)
    >>> lc.past.tolist(), lc.current.tolist()
    ([1], [4])
    """

    def __init__(self, max_distance: float = 0.1, min_gap: int = 50, suppress: int = 0) -> None:
        self.max_distance = max_distance
        self.min_gap = min_gap
        self.suppress = suppress

    def _best(self, X, pos, odo):
        if pos is None:
            raise ValueError("GroundTruthDetector needs positions (N, 2): the ground truth of the run")
        max_d = check_positive_float(self.max_distance, "max_distance")
        self.min_gap = check_int(self.min_gap, "min_gap", minimum=1)
        check_int(self.suppress, "suppress", minimum=0)
        c, p, d = nearest_earlier_position(pos, self.min_gap)
        return c, p, d, 1.0 / (1.0 + d / max_d), d <= max_d


def nearest_earlier_position(positions: np.ndarray, min_gap: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(current, past, distance)``: for every frame at least ``min_gap``
    frames into a run, the frame at least ``min_gap`` earlier nearest to it
    by ``positions`` (N, 2) metres (ties: the earliest), and their distance
    (m); computed in blocks of 512 frames. What :class:`GroundTruthDetector`
    ranks and :func:`~sfanav.loopclosure.revisits.revisit_pairs` keeps."""
    n = len(positions)
    cur, past, dist = [], [], []
    for s in range(min_gap, n, 512):
        q = np.arange(s, min(n, s + 512))
        D = np.hypot(*(positions[q][:, None, :] - positions[None, : q[-1] - min_gap + 1, :]).transpose(2, 0, 1))
        D[np.arange(D.shape[1])[None, :] > (q[:, None] - min_gap)] = np.inf
        j = np.argmin(D, axis=1)
        cur.append(q)
        past.append(j)
        dist.append(D[np.arange(len(q)), j])
    if not cur:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(cur).astype(np.int64), np.concatenate(past).astype(np.int64), np.concatenate(dist)


def fourier_signatures(images: Any, n_coefficients: int = 15, normalize: bool = False) -> np.ndarray:
    """Rotation-invariant signatures (N, rows x k) float32: the magnitudes of
    the first ``k`` azimuthal DFT coefficients of every image row (and
    channel), scaled by their median magnitude over the batch (Menegatti et
    al. 2004); with ``normalize`` each signature divided by its own sum
    (a global change of brightness then leaves it unchanged)."""
    R = panorama_rows(as_images(images)).astype(np.float32, copy=False)
    spec = np.fft.rfft(R, axis=2)
    k = min(check_int(n_coefficients, "n_coefficients"), spec.shape[2])
    sig = np.abs(spec[:, :, :k]).reshape(len(R), -1).astype(np.float32)
    if normalize:
        sig = sig / np.maximum(sig.sum(axis=1, keepdims=True), 1e-12) * sig.shape[1]
    return sig / max(float(np.median(np.abs(sig))), 1e-12)


class FourierDetector(LoopClosureDetector):
    """Closures from the Fourier signature: for every frame, the earlier
    frame (at least ``min_gap`` frames back; with odometry, within
    ``max_odometry_distance`` metres by dead reckoning) of nearest signature
    (L1), accepted when that distance is at most ``accept`` times the
    frame's distance to its temporal neighbours ``neighbor_lag`` frames
    away (a match must look about as alike as a nearby frame). Score
    ``1 / (1 + r)``, ``r`` that ratio. ``normalize``: signatures divided by
    their own sum, robust to a change of light between the passes."""

    def __init__(self, min_gap: int = 40, max_odometry_distance: float = 3.0, accept: float = 1.0,
                 neighbor_lag: int = 2, n_coefficients: int = 15, suppress: int = 0, normalize: bool = False) -> None:
        self.min_gap = min_gap
        self.max_odometry_distance = max_odometry_distance
        self.accept = accept
        self.neighbor_lag = neighbor_lag
        self.n_coefficients = n_coefficients
        self.suppress = suppress
        self.normalize = normalize

    def _best(self, X, pos, odo):
        self.min_gap = check_int(self.min_gap, "min_gap", minimum=1)
        accept = check_nonneg_float(self.accept, "accept")
        max_odo = check_positive_float(self.max_odometry_distance, "max_odometry_distance")
        lag = check_int(self.neighbor_lag, "neighbor_lag")
        check_int(self.suppress, "suppress", minimum=0)
        sig = fourier_signatures(X, self.n_coefficients, bool(self.normalize))
        return nearest_earlier(sig.astype(np.float64), l1_matrix, self, odo, max_odo, lag, accept)


def l1_matrix(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """L1 distances between the rows of ``A`` and ``B``."""
    from scipy.spatial.distance import cdist

    return cdist(A, B, "cityblock")


def nearest_earlier(feats: np.ndarray, matrix: Any, det: LoopClosureDetector, odo: np.ndarray | None,
                    max_odo: float, lag: int, accept: float, chunk: int = 256) -> tuple[np.ndarray, ...]:
    """For every frame with allowed earlier frames (``det``'s gap, the
    odometry gate): the nearest by ``matrix`` (rows, rows -> distances), its
    distance, the score ``1 / (1 + r)`` with ``r`` the ratio to the frame's
    distance to its temporal neighbours ``lag`` frames away, and whether
    ``r <= accept``."""
    n = len(feats)
    nb = np.full(n, np.inf)
    for d in (-lag, lag):
        i = np.arange(max(0, -d), min(n, n - d))
        for s in range(0, len(i), chunk):
            a = i[s : s + chunk]
            nb[a] = np.minimum(nb[a], np.diagonal(matrix(feats[a], feats[a + d])))
    cur, past, dd = [], [], []
    for s in range(det.min_gap, n, chunk):
        q = np.arange(s, min(n, s + chunk))
        D = np.where(det._gate(n, q, odo, max_odo), matrix(feats[q], feats), np.inf)
        j = np.argmin(D, axis=1)
        dj = D[np.arange(len(q)), j]
        ok = np.isfinite(dj)
        cur.append(q[ok])
        past.append(j[ok])
        dd.append(dj[ok])
    if not cur or not sum(len(c) for c in cur):
        z = np.zeros(0, np.int64)
        return z, z, np.zeros(0), np.zeros(0), np.zeros(0, bool)
    c, p, d = np.concatenate(cur), np.concatenate(past), np.concatenate(dd)
    ratio = d / np.maximum(nb[c], 1e-12)
    return c, p, d, 1.0 / (1.0 + ratio), ratio <= accept


def find_loop_closures(images: Any, odometry: Any = None, *, min_gap: int = 40, max_odometry_distance: float = 3.0,
                       accept: float = 1.0, neighbor_lag: int = 2, n_coefficients: int = 15) -> LoopClosures:
    """The accepted closures of :class:`FourierDetector` with these
    parameters, on panoramas (N, H, W[, C]) in temporal order, gated by
    ``odometry`` (N, 2) metres when given."""
    return FourierDetector(min_gap=min_gap, max_odometry_distance=max_odometry_distance, accept=accept,
                           neighbor_lag=neighbor_lag, n_coefficients=n_coefficients).detect(images, odometry=odometry)
