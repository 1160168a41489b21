"""Loop-closure feedback training (thesis 6.2.1), image-based.

SFA learns what changes slowly in the *order* the training images come.
Where the training run passes a place twice (the crossings of a grid), the
thesis re-inserted the earlier image of that place, aligned to the current
orientation, right after the current one in the training sequence: a
feedback signal that the two must give similar outputs, i.e. more pairs of
images of the same place at different times (thesis 6.2.1). The thesis
found the loop closures from ground truth and, for real runs, with a visual
bag of words; here they come from the images and (optionally) odometry:

1. every training panorama's Fourier signature (row-wise azimuthal DFT
   magnitudes: rotation invariant; Menegatti et al. 2004);
2. for each image, the nearest earlier image by signature distance among
   those at least ``min_gap`` frames earlier (another pass) and, with
   odometry, within ``max_odometry_distance`` metres by odometry (a loose
   gate: odometry drifts);
3. accepted if that distance is at most ``accept`` times the image's
   distance to its own temporal neighbours ``neighbor_lag`` frames away (a
   match must look at least about as alike as a nearby frame);
4. the earlier image is aligned to the current orientation by the column
   shift that maximises the circular cross-correlation of the two.

:func:`interleave` builds the training sequence: each image, followed by
its aligned loop-closure partner if it has one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class LoopClosures:
    """Accepted loop closures: ``current[i]`` (index in the run) is paired
    with the earlier ``past[i]``, which ``np.roll(image, shift[i], axis=1)``
    aligns to it; ``distance[i]`` is their signature distance."""

    current: np.ndarray
    past: np.ndarray
    shift: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.current)


def panorama_rows(images: Any) -> np.ndarray:
    """Panoramas (N, H, W) or (N, H, W, C) as rows (N, H * C, W) of columns
    around the robot, in their own dtype (channels become rows). Raises
    ValueError for any other shape."""
    a = np.asarray(images)
    if a.ndim == 4:  # (N, H, W, C) -> (N, H * C, W)
        a = a.transpose(0, 1, 3, 2).reshape(a.shape[0], -1, a.shape[2])
    if a.ndim != 3:
        raise ValueError(f"images must be panoramas (N, H, W) or (N, H, W, C), got shape {a.shape}")
    return a


def find_loop_closures(images: Any, odometry: Any = None, *, min_gap: int = 40, max_odometry_distance: float = 3.0,
                       accept: float = 1.0, neighbor_lag: int = 2, n_coefficients: int = 15,
                       chunk: int = 256) -> LoopClosures:
    """Loop closures within one training run of panoramas (N, H, W[, C]) in
    temporal order; ``odometry`` (N, 2) metres, optional. See the module
    docstring."""
    R = panorama_rows(images).astype(np.float32, copy=False)
    n, _, W = R.shape
    spec = np.fft.rfft(R, axis=2)
    k = min(n_coefficients, spec.shape[2])
    sig = np.abs(spec[:, :, :k]).reshape(n, -1).astype(np.float32)
    sig /= max(float(np.median(np.abs(sig))), 1e-12)
    # each image's distance to its temporal neighbours: how alike "the same place" looks
    lag = max(1, int(neighbor_lag))
    nb = np.full(n, np.inf)
    for d in (-lag, lag):
        i = np.arange(max(0, -d), min(n, n - d))
        nb[i] = np.minimum(nb[i], np.abs(sig[i] - sig[i + d]).sum(axis=1))
    odo = None if odometry is None else np.asarray(odometry, float)[:, :2]
    cur, past, dist = [], [], []
    for s in range(0, n, chunk):
        q = np.arange(s, min(n, s + chunk))
        D = np.abs(sig[q][:, None, :] - sig[None, :, :]).sum(axis=2)  # L1, (m, n)
        allowed = np.arange(n)[None, :] <= (q[:, None] - int(min_gap))
        if odo is not None:
            allowed &= np.hypot(*(odo[q][:, None, :] - odo[None, :, :]).transpose(2, 0, 1)) <= max_odometry_distance
        D = np.where(allowed, D, np.inf)
        j = np.argmin(D, axis=1)
        dj = D[np.arange(len(q)), j]
        ok = np.isfinite(dj) & (dj <= accept * nb[q])
        cur.append(q[ok])
        past.append(j[ok])
        dist.append(dj[ok])
    cur_a, past_a = np.concatenate(cur).astype(np.int64), np.concatenate(past).astype(np.int64)
    # alignment: the shift of the past image that best matches the current one
    shifts = np.empty(len(cur_a), np.int64)
    for t in range(0, len(cur_a), chunk):
        a, b = spec[cur_a[t : t + chunk]], spec[past_a[t : t + chunk]]
        corr = np.fft.irfft((a * np.conj(b)).sum(axis=1), n=W, axis=1)  # sum_w a[w] b[w - d]
        shifts[t : t + chunk] = np.argmax(corr, axis=1)
    return LoopClosures(cur_a, past_a, shifts, np.concatenate(dist))


def interleave(images: Any, closures: LoopClosures) -> np.ndarray:
    """The training sequence with loop-closure feedback: every image, then
    (if it has one) its earlier partner rolled into its orientation."""
    a = np.asarray(images)
    partner = {int(c): (int(p), int(s)) for c, p, s in zip(closures.current, closures.past, closures.shift)}
    out = np.empty((len(a) + len(partner),) + a.shape[1:], a.dtype)
    k = 0
    for i in range(len(a)):
        out[k] = a[i]
        k += 1
        if i in partner:
            p, s = partner[i]
            out[k] = np.roll(a[p], s, axis=1)
            k += 1
    return out
