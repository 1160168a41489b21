"""Loop-closure feedback for network training (thesis 6.2.1).

Where the training run comes back to a place, the earlier image of that
place, aligned to the current orientation, is woven into the current
image's simulated rotation: the network sees ``A'_0, C_0, A'_1, C_1, ...``
(``A'`` the aligned partner, ``C`` the current image, ``_k`` the rotated
views), so every rotation step also carries the change of condition
between the two visits, and the slowness objective asks for outputs that
ignore it. A closure's weight in ``[0, 1]`` mixes this interleaved sequence
with the plain rotation (1: the thesis; lower weights for less certain
matches). The Rust core trains on it with the same exact fast path as the
plain sequence (``Network.fit(..., loop_closures=...)``).

The closures' partners and weights come from
:func:`sfanav.loopclosure.partners.closure_partners`; here the network's
training checks explicit partners (the invariance training's corrupted
copies, or closures already turned into partners).
"""

from __future__ import annotations

from typing import Any

import numpy as np


def check_partners(partners: Any, n: int, image_shape: tuple[int, ...],
                   dtype: Any) -> tuple[list[int], list[float], np.ndarray]:
    """``(current, weights, partner images)`` as the core takes them, from
    explicit partners ``(current (M,), weights (M,), images (M, H, W[, C]))``
    of a training run of ``n`` images of ``image_shape`` (H, W[, C]) and
    ``dtype``: current indices into the run, unique; weights finite in
    [0, 1]; partner images of the run's image size and dtype. TypeError /
    ValueError naming what is wrong."""
    if not isinstance(partners, (tuple, list)) or len(partners) != 3:
        raise TypeError("partners must be a tuple (current, weights, images)")
    current = np.asarray(partners[0])
    if current.ndim != 1 or (current.size and current.dtype.kind not in "iu"):
        raise ValueError(f"partners: current must be a 1-D array of integers, got shape {current.shape} and dtype "
                         f"{current.dtype}")
    m = len(current)
    if m and (current.min() < 0 or current.max() >= n):
        raise ValueError(f"partners: current must index the {n} training images (0..{n - 1})")
    if len(np.unique(current)) != m:
        raise ValueError("partners: an image has more than one partner; keep one per current image")
    w = np.asarray(partners[1], dtype=np.float64)
    if w.shape != (m,) or not np.all(np.isfinite(w) & (w >= 0) & (w <= 1)):
        raise ValueError(f"partners: weights must be {m} finite values in [0, 1], got shape {w.shape}")
    imgs = np.asarray(partners[2])
    if imgs.shape != (m,) + tuple(image_shape) or imgs.dtype != np.dtype(dtype):
        raise ValueError(f"partners: the images must be {m} of the training images' size and dtype "
                         f"{tuple(image_shape)} {np.dtype(dtype)}, got {imgs.shape} {imgs.dtype}")
    return current.astype(np.int64).tolist(), w.tolist(), np.ascontiguousarray(imgs)
