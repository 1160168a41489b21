"""Loop closures as the network's feedback partners (thesis 6.2.1): which
training image gets which earlier image of its place, turned to its
orientation, and with what weight (:func:`closure_partners`); what
:meth:`sfanav.Network.fit` (``loop_closures=...``), the distributed trainer
and the invariance training of :func:`sfanav.localization.fit_localizer`
interleave with the current image's simulated rotation
(:mod:`sfanav.sfa.feedback`).

>>> import numpy as np
>>> imgs = np.arange(2 * 2 * 4).reshape(2, 2, 4)
>>> current, weights, partners = closure_partners(imgs, ([0], [1], [1]))
>>> current, weights, partners[0, 0].tolist()
([1], [1.0], [3, 0, 1, 2])
"""

from __future__ import annotations

from typing import Any

import numpy as np


def _closure_arrays(loop_closures: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """(past, current, shift, score or None) of a loop-closure object (with
    attributes ``past``, ``current``, ``shift`` and optionally ``score``) or
    a tuple ``(past, current, shift)``."""
    if all(hasattr(loop_closures, a) for a in ("past", "current", "shift")):
        score = getattr(loop_closures, "score", None)
        arrays = (loop_closures.past, loop_closures.current, loop_closures.shift)
    elif isinstance(loop_closures, (tuple, list)) and len(loop_closures) == 3:
        arrays, score = tuple(loop_closures), None
    else:
        raise TypeError("loop_closures must be a LoopClosures (from sfanav.loopclosure) or a tuple "
                        f"(past, current, shift), got {type(loop_closures).__name__}")
    out = []
    for name, x in zip(("past", "current", "shift"), arrays):
        a = np.asarray(x)
        if a.ndim != 1 or (a.size and a.dtype.kind not in "iu"):
            raise ValueError(f"loop_closures: {name} must be a 1-D array of integers, got shape {a.shape} "
                             f"and dtype {a.dtype}")
        out.append(a.astype(np.int64))
    if not len(out[0]) == len(out[1]) == len(out[2]):
        raise ValueError("loop_closures: past, current and shift must have one length, got "
                         f"{len(out[0])}, {len(out[1])} and {len(out[2])}")
    return out[0], out[1], out[2], None if score is None else np.asarray(score, dtype=np.float64)


def check_closures(loop_closures: Any, n: int,
                   weights: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(past, current, shift, weight)`` arrays (M,) of ``loop_closures``
    of a training run of ``n`` images, checked as in
    :func:`closure_partners` (which see for ``weights``)."""
    past, current, shift, score = _closure_arrays(loop_closures)
    m = len(current)
    for name, idx in (("past", past), ("current", current)):
        if m and (idx.min() < 0 or idx.max() >= n):
            raise ValueError(f"loop_closures: {name} must index the {n} training images (0..{n - 1})")
    if np.any(past == current):
        raise ValueError("loop_closures: an image cannot close a loop with itself (past == current)")
    if len(np.unique(current)) != m:
        raise ValueError("loop_closures: an image has more than one closure; keep one per current image")
    if weights is None:
        w = np.ones(m)
    elif isinstance(weights, str):
        if weights != "score":
            raise ValueError(f'closure_weights must be None, "score" or an array, got {weights!r}')
        if score is None:
            raise ValueError('closure_weights="score" needs loop closures with a score (sfanav.loopclosure)')
        if score.shape != (m,) or not np.all(np.isfinite(score)):
            raise ValueError("loop_closures: score must be finite, one per closure")
        w = np.clip(score, 0.0, 1.0)
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (m,):
            raise ValueError(f"closure_weights must have one value per closure ({m}), got shape {w.shape}")
        if not np.all(np.isfinite(w) & (w >= 0) & (w <= 1)):
            raise ValueError("closure_weights must be finite and in [0, 1]")
    return past, current, shift, w


def aligned_partners(frames: np.ndarray, shift: Any) -> np.ndarray:
    """``np.roll(frames[i], shift[i], axis=1)`` for every frame (M, H, W[,
    C]): the earlier visits turned to the current images' orientation."""
    width = frames.shape[2]
    out = np.empty_like(frames)
    for i, s in enumerate(np.asarray(shift, dtype=np.int64)):
        out[i] = np.roll(frames[i], int(s) % width, axis=1)
    return out


def closure_partners(images: np.ndarray, loop_closures: Any,
                     weights: Any = None) -> tuple[list[int], list[float], np.ndarray]:
    """What the core trains on for ``loop_closures`` of the training run
    ``images`` (N, H, W[, C]): the current images' indices, the closures'
    weights and the aligned partner images ``np.roll(images[past], shift,
    axis=2)`` (M, H, W[, C]) in the images' dtype.

    ``weights``: None (1 per closure: the thesis), ``"score"`` (each
    closure's match confidence ``loop_closures.score``, clipped to [0, 1])
    or an array (M,) in [0, 1].

    Raises TypeError / ValueError for closures that are not index arrays of
    one length, indices outside the run, a closure of an image with itself,
    two closures of one current image, or weights outside [0, 1].
    """
    past, current, shift, w = check_closures(loop_closures, len(images), weights)
    partners = aligned_partners(np.asarray(images[past]), shift)
    return current.tolist(), w.tolist(), partners
