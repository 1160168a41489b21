"""How much a trained network's code changes between two visits of one
place: the test that decides whether a training run needs loop-closure
feedback (thesis 6.2.1).

A network that codes position only gives two visits of a place features as
close as their positions are: over the run, its features change by about
``g`` (standardised units) per metre driven. A network that also codes what
changed over the run (a light rising through it, an object moving) gives the
visits of one place features further apart than that. :func:`revisit_change`
measures the ratio

    ratio = median |f_i - f_j| over revisits (i, j)
            / (g * max(median |x_i - x_j| over revisits, step / 4)),
    g = median |f_k - f_k+1| / |x_k - x_k+1| over moving consecutive frames,

with ``f`` the slowest ``n_features`` slow features (each standardised over
the run: a change that runs through the whole run, such as a rising light,
is the slowest signal there is and lands in the slowest features, while the
next ones may code the direction of travel, which differs between the passes
of a crossing: in the closely walled rooms of 5.2 the fifth to eighth tell a
pass from its reverse), ``x`` the training positions (ground truth, or the
positions learned without it, which read lower: the pose graph pairs the
passes of a place by these same features, hence
:data:`FEEDBACK_RATIO_LEARNED`) and a revisit the nearest frame at least ``min_gap``
frames earlier within ``max_distance`` metres; ``step`` is the median
distance between consecutive moving frames (a floor for revisits closer
than a quarter step). About 1 means the position code explains the
revisits (``g`` is measured along the path, the revisits' offsets lie in
any direction: a code that changes much faster across the path than along
it reads above 1 too; on grids with crossings the directions mix); above
:data:`FEEDBACK_RATIO` something else changes the code, and the recipe (:func:`sfanav.pipeline.train_localizer`,
``feedback="auto"``) then trains again with loop-closure feedback.
Measurements (6.2.1's static, dynamic and changing-light gardens and the
other scenes): docs/loop-closures.md, "When feedback is used".

>>> import numpy as np
>>> t = np.linspace(0, 4 * np.pi, 400)
>>> xy = np.c_[np.cos(t), np.sin(t)] * 3                    # the same circle driven twice
>>> place = np.c_[xy, xy ** 2]                               # features that code position only
>>> round(revisit_change(place, xy).ratio, 1)
1.0
>>> light = np.c_[np.linspace(0, 30, 400), place]            # the slowest codes the time
>>> revisit_change(light, xy).ratio > FEEDBACK_RATIO
True
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .._checks import as_matrix, check_int, check_positive_float
from .detectors import nearest_earlier_position

FEEDBACK_RATIO = 1.25
"""The revisit ratio on ground-truth positions above which ``feedback="auto"`` trains with loop-closure feedback
(chosen between the static and the changing scenes measured: docs/loop-closures.md, "When feedback is used")."""
FEEDBACK_RATIO_LEARNED = 1.0
"""The same threshold on positions learned without ground truth. The pose graph pairs the passes of a place by the
slow features themselves, so a learned map puts frames whose codes agree together and reads the ratio lower (in
6.2.1's gardens 0.58-0.69x the ground truth's); every scene measured between 1.0 and 1.25 on its learned map trained
a more precise model with feedback (docs/loop-closures.md)."""
MIN_REVISITS = 10
"""Fewer revisits than this decide nothing (``RevisitChange.ratio`` is NaN, no feedback); the recipe also trains
with no fewer closures."""


@dataclass(frozen=True)
class RevisitChange:
    """What :func:`revisit_change` measured.

    Attributes
    ----------
    ratio : float
        The revisits' feature distance over what the position code explains
        (see the module docstring); NaN with fewer than :data:`MIN_REVISITS`
        revisits or no moving frames.
    n_revisits : int
        Frames with an earlier visit of their place.
    revisit_distance : float
        Median distance (m) of the revisits' positions.
    step : float
        Median distance (m) between consecutive moving frames.
    features_per_metre : float
        ``g``: the median feature change per metre between consecutive frames.
    """

    ratio: float
    n_revisits: int
    revisit_distance: float
    step: float
    features_per_metre: float

    def needs_feedback(self, threshold: float = FEEDBACK_RATIO) -> bool:
        """Whether the ratio exceeds ``threshold`` (False when undecided)."""
        return bool(np.isfinite(self.ratio) and self.ratio > threshold)

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain Python numbers (NaN as None), for a model's ``info``."""
        return {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in asdict(self).items()}


def revisit_pairs(positions: Any, *, max_distance: float = 0.1, min_gap: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """``(current, past)`` frame indices of a run's revisits: for every frame
    with one, the nearest frame at least ``min_gap`` frames earlier whose
    position (N, 2) metres is within ``max_distance`` metres (the thesis's
    ground-truth closures, :class:`~sfanav.loopclosure.GroundTruthDetector`,
    from positions alone)."""
    xy = as_matrix(positions, "positions", n_cols=2)
    max_d = check_positive_float(max_distance, "max_distance")
    cur, past, dist = nearest_earlier_position(xy, check_int(min_gap, "min_gap", minimum=1))
    ok = dist <= max_d
    return cur[ok], past[ok]


def revisit_change(features: Any, positions: Any, *, n_features: int = 4, max_distance: float = 0.1,
                   min_gap: int = 50, pairs: Any = None) -> RevisitChange:
    """The revisit ratio of a training run (module docstring).

    Parameters
    ----------
    features : array (N, m)
        Slow features of the run's frames in temporal order, slowest first.
    positions : array (N, 2)
        The frames' positions (m): ground truth or learned.
    n_features : int
        Slowest features compared (fewer if ``m`` is smaller).
    max_distance, min_gap
        What counts as a revisit (:func:`revisit_pairs`).
    pairs : (current, past) or None
        The revisits given instead (frame indices, e.g. the ``current`` and
        ``past`` of loop closures found from the images): for positions
        learned from the same features, whose own revisits are biased
        towards frames whose features agree (the pose graph pairs places by
        them). The positions then only scale the pairs' distances.

    Raises
    ------
    ValueError
        Non-finite features or positions, row counts that differ, or pairs
        that are not frame indices of equal length.
    """
    F = as_matrix(features, "features")
    xy = as_matrix(positions, "positions", n_cols=2)
    if len(F) != len(xy):
        raise ValueError(f"features has {len(F)} rows but positions has {len(xy)}; they must match")
    k = min(check_int(n_features, "n_features", minimum=1), F.shape[1])
    F = F[:, :k]
    sd = F.std(axis=0)
    F = F[:, sd > 0] / sd[sd > 0]
    if pairs is None:
        cur, past = revisit_pairs(xy, max_distance=max_distance, min_gap=min_gap)
    else:
        cur, past = (np.asarray(a) for a in pairs)
        if (cur.ndim != 1 or cur.shape != past.shape or (cur.size and (cur.dtype.kind not in "iu"
                                                                      or past.dtype.kind not in "iu"))):
            raise ValueError(f"pairs must be two 1-D integer arrays of one length, got shapes {cur.shape} and "
                             f"{past.shape}")
        if cur.size and (min(cur.min(), past.min()) < 0 or max(cur.max(), past.max()) >= len(xy)):
            raise ValueError(f"pairs must index the run's {len(xy)} frames")
    s = np.hypot(*np.diff(xy, axis=0).T)
    moving = s > 1e-9
    nan = float("nan")
    s_rev = float(np.median(np.hypot(*(xy[cur] - xy[past]).T))) if len(cur) else nan
    step = float(np.median(s[moving])) if moving.any() else nan
    if len(cur) < MIN_REVISITS or moving.sum() < 2 or F.shape[1] == 0:
        return RevisitChange(nan, int(len(cur)), s_rev, step, nan)
    g = float(np.median(np.linalg.norm(np.diff(F, axis=0), axis=1)[moving] / s[moving]))
    d_rev = float(np.median(np.linalg.norm(F[cur] - F[past], axis=1)))
    ratio = d_rev / (g * max(s_rev, step / 4)) if g > 0 else nan
    return RevisitChange(float(ratio), int(len(cur)), s_rev, step, g)
