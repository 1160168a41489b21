"""Long-term training on several recordings of one route (thesis 6.2.2).

A robot that drives the same route in different conditions (daytime,
weather, season) sees every place several times. Ordering the training
images *place-major* (every recording's image of one place, then the next
place: Fig. 6.16) makes the condition change faster than the position, so
the slowness objective learns features that ignore it. That needs
position correspondences between the recordings: ground truth where there
is some, else each frame's fraction of the loop's arc length by odometry
(a closed route driven from a base station, as the thesis's robot did).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .._checks import as_matrix


def arc_fraction(odometry: Any) -> np.ndarray:
    """Each frame's fraction of the route's length, in [0, 1], from odometry
    poses (N, 2 or 3) in metres (the route's start is 0, its end 1).
    Raises ValueError for fewer than 2 poses, non-finite values or a route
    of length 0."""
    P = as_matrix(odometry, "odometry")
    if P.shape[1] < 2 or len(P) < 2:
        raise ValueError(f"odometry must be (N >= 2, 2 or 3) poses, got shape {P.shape}")
    if not np.all(np.isfinite(P[:, :2])):
        raise ValueError("odometry holds non-finite values")
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(P[:, :2], axis=0).T))]
    if s[-1] <= 0:
        raise ValueError("the odometry does not move: no arc length to align recordings by")
    return s / s[-1]


def correspondences(reference: Any, other: Any) -> np.ndarray:
    """For every frame of ``other``, the index of the corresponding
    frame of ``reference``: the nearest by position (arrays (N, 2) in
    metres) or by arc fraction (1-D arrays from :func:`arc_fraction`).
    Raises ValueError for arrays of different kinds or non-finite values."""
    R, O = np.asarray(reference, dtype=np.float64), np.asarray(other, dtype=np.float64)
    if R.ndim != O.ndim or R.ndim not in (1, 2) or (R.ndim == 2 and R.shape[1] != O.shape[1]):
        raise ValueError("reference and other must both be positions (N, 2) or both arc fractions (N,), got "
                         f"shapes {R.shape} and {O.shape}")
    if len(R) == 0 or not (np.all(np.isfinite(R)) and np.all(np.isfinite(O))):
        raise ValueError("correspondences need non-empty, finite positions")
    from scipy.spatial import cKDTree

    tree = cKDTree(R.reshape(len(R), -1))
    return tree.query(O.reshape(len(O), -1))[1].astype(np.int64)


def place_major_order(places: Sequence[Any]) -> np.ndarray:
    """The place-major training order of several recordings (Fig. 6.16):
    ``places[r][i]`` is the reference place of frame ``i`` of recording
    ``r`` (from :func:`correspondences`). Returns indices into the
    recordings concatenated in the given order: all frames of the first
    place (recording 0's, then 1's, ...), then of the next place; frames of
    one recording and place keep their order.

    Example
    -------
    >>> place_major_order([np.array([0, 1, 2]), np.array([0, 1, 2])]).tolist()
    [0, 3, 1, 4, 2, 5]
    """
    if len(places) == 0:
        raise ValueError("place_major_order needs at least one recording")
    arrs = [np.asarray(p) for p in places]
    for r, p in enumerate(arrs):
        if p.ndim != 1 or (p.size and p.dtype.kind not in "iu"):
            raise ValueError(f"places[{r}] must be 1-D integer place indices, got shape {p.shape}, dtype {p.dtype}")
    place = np.concatenate(arrs).astype(np.int64)
    rec = np.concatenate([np.full(len(p), r) for r, p in enumerate(arrs)])
    frame = np.concatenate([np.arange(len(p)) for p in arrs])
    return np.lexsort((frame, rec, place)).astype(np.int64)
