"""Loop closures against ground truth: precision, recall and average
precision at a distance threshold (thesis 6.2.1: BoW closures at 0.1 m)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_matrix, check_int, check_positive_float
from .closures import LoopClosures


@dataclass
class ClosureQuality:
    """How good a set of loop closures is against ground truth.

    ``precision``: share of the closures whose frames are within
    ``max_distance`` metres; ``recall``: true closures over the frames that
    have a true partner (an earlier frame within ``max_distance``, at least
    ``min_gap`` frames back); ``average_precision``: the area under the
    precision-recall curve of the closures ranked by score (with every
    frame's candidate given, the detector's mAP); ``n``, ``mean_distance``
    (m): the closures and their mean true distance."""

    precision: float
    recall: float
    average_precision: float
    n: int
    mean_distance: float
    n_possible: int


def closure_precision_recall(closures: LoopClosures, positions: Any, *, max_distance: float = 0.1,
                             min_gap: int = 50) -> ClosureQuality:
    """Scores ``closures`` (indices into a run with ground-truth
    ``positions`` (N, 2) m). Raises ValueError for closures beyond the run."""
    P = as_matrix(positions, "positions", n_cols=2)
    max_distance = check_positive_float(max_distance, "max_distance")
    min_gap = check_int(min_gap, "min_gap", minimum=1)
    n = len(P)
    if len(closures) and max(closures.current.max(), closures.past.max()) >= n:
        raise ValueError(f"the closures name frames beyond the {n} positions")
    from scipy.spatial import cKDTree

    # frames with a true partner at least min_gap frames earlier
    tree = cKDTree(P)
    possible = 0
    for i, nbrs in enumerate(tree.query_ball_point(P, max_distance)):
        if any(j <= i - min_gap for j in nbrs):
            possible += 1
    d = np.hypot(*(P[closures.current] - P[closures.past]).T) if len(closures) else np.zeros(0)
    true = d <= max_distance
    order = np.argsort(-closures.score, kind="stable")
    hits = true[order]
    tp = np.cumsum(hits)
    prec_at = tp / np.arange(1, len(hits) + 1) if len(hits) else np.zeros(0)
    ap = float((prec_at * hits).sum() / possible) if possible else 0.0
    return ClosureQuality(
        precision=float(true.mean()) if len(true) else 0.0,
        recall=float(true.sum() / possible) if possible else 0.0,
        average_precision=ap,
        n=len(closures),
        mean_distance=float(d.mean()) if len(d) else float("nan"),
        n_possible=possible,
    )
