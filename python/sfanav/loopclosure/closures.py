"""Loop closures of a training run: pairs of frames that show one place at
two times, each with the column shift that aligns the earlier panorama to
the later one."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_images


@dataclass
class LoopClosures:
    """Loop closures of one run: frame ``current[i]`` shows the place of the
    earlier frame ``past[i]``; ``np.roll(images[past[i]], shift[i], axis=2)``
    (along the panorama's width) aligns the earlier panorama to it.

    Attributes
    ----------
    past, current : int64 arrays (M,)
        Frame indices in the run, ``past < current``.
    shift : int64 array (M,)
        Column shift, pixels.
    score : float64 array (M,)
        Match confidence in [0, 1] (higher is surer).
    distance : float64 array (M,)
        The detector's dissimilarity (metres for ground truth, a signature
        or histogram distance otherwise).

    Raises ValueError for arrays of different lengths, non-integer indices,
    ``past >= current``, scores outside [0, 1] or non-finite values.
    """

    past: np.ndarray
    current: np.ndarray
    shift: np.ndarray
    score: np.ndarray
    distance: np.ndarray

    def __post_init__(self) -> None:
        for name in ("past", "current", "shift"):
            a = np.asarray(getattr(self, name))
            if a.ndim != 1 or (a.size and a.dtype.kind not in "iu"):
                raise ValueError(f"LoopClosures.{name} must be 1-D integers, got shape {a.shape}, dtype {a.dtype}")
            setattr(self, name, a.astype(np.int64))
        for name in ("score", "distance"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.ndim != 1 or not np.all(np.isfinite(a)):
                raise ValueError(f"LoopClosures.{name} must be 1-D and finite")
            setattr(self, name, a)
        m = len(self.past)
        if any(len(getattr(self, k)) != m for k in ("current", "shift", "score", "distance")):
            raise ValueError("LoopClosures: past, current, shift, score and distance must have one length")
        if m and (np.any(self.past < 0) or np.any(self.past >= self.current)):
            raise ValueError("LoopClosures: every past frame must come before its current frame (0 <= past < current)")
        if m and (self.score.min() < 0 or self.score.max() > 1):
            raise ValueError("LoopClosures: scores must be in [0, 1]")

    def __len__(self) -> int:
        return len(self.current)

    @classmethod
    def empty(cls) -> "LoopClosures":
        z = np.zeros(0, np.int64)
        return cls(z, z, z, np.zeros(0), np.zeros(0))

    def select(self, mask: Any) -> "LoopClosures":
        """The closures where ``mask`` (bool (M,) or indices) holds."""
        return LoopClosures(self.past[mask], self.current[mask], self.shift[mask], self.score[mask],
                            self.distance[mask])

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The closures as plain arrays (for ``np.savez``; no pickle)."""
        return {k: getattr(self, k) for k in ("past", "current", "shift", "score", "distance")}

    @classmethod
    def from_arrays(cls, arrays: Any) -> "LoopClosures":
        """Inverse of :meth:`to_arrays` (e.g. an ``np.load`` of a ``.npz``)."""
        missing = {"past", "current", "shift", "score", "distance"} - set(arrays)
        if missing:
            raise ValueError(f"loop-closure arrays lack {sorted(missing)}")
        return cls(*(np.asarray(arrays[k]) for k in ("past", "current", "shift", "score", "distance")))


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


def align(images: Any, past: Any, current: Any, *, chunk: int = 256) -> np.ndarray:
    """The column shift (pixels, ``0..W-1``) that aligns each past panorama
    to its current one: ``np.roll(images[past[i]], shift[i], axis=2)`` is
    nearest to ``images[current[i]]`` in the sum of squared differences
    (the circular cross-correlation over rows and channels is largest;
    computed with the FFT). ``images`` (N, H, W[, C]); ``past``,
    ``current`` index it.

    >>> rng = np.random.default_rng(0)
    >>> a = rng.random((1, 4, 30))
    >>> int(align(np.concatenate([a, np.roll(a, 7, axis=2)]), [0], [1])[0])
    7
    """
    R = panorama_rows(as_images(images))
    p, c = np.asarray(past, dtype=np.int64), np.asarray(current, dtype=np.int64)
    if p.shape != c.shape or p.ndim != 1:
        raise ValueError("past and current must be 1-D index arrays of one length")
    if p.size and (min(p.min(), c.min()) < 0 or max(p.max(), c.max()) >= len(R)):
        raise ValueError(f"past and current must index the {len(R)} images")
    W = R.shape[2]
    out = np.empty(len(p), np.int64)
    for s in range(0, len(p), chunk):
        a = np.fft.rfft(R[c[s : s + chunk]].astype(np.float64), axis=2)
        b = np.fft.rfft(R[p[s : s + chunk]].astype(np.float64), axis=2)
        corr = np.fft.irfft((a * np.conj(b)).sum(axis=1), n=W, axis=1)  # sum_w cur[w] past[w - d]
        out[s : s + chunk] = np.argmax(corr, axis=1)
    return out


def interleave(images: Any, closures: LoopClosures) -> np.ndarray:
    """A plain training sequence with loop closures appended: every image,
    then (if it has one) its earlier partner rolled into its orientation.
    (The thesis's feedback weaves the partner into the simulated rotation
    instead: ``Network.fit(..., loop_closures=...)``.)"""
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
