"""Places seen again: loop closures of a training run, and the training
order of several recordings of one route (thesis 6.2).

* :class:`LoopClosures` (``closures``): matched (past, current) frames with
  the column shift that aligns the past panorama, a score and a distance;
  :func:`align`;
* detectors behind one interface (``detectors``, ``bow``):
  :class:`GroundTruthDetector`, :class:`FourierDetector`,
  :class:`BagOfWordsDetector`, :func:`make_detector`;
* :func:`closure_precision_recall` (``evaluation``): precision, recall and
  average precision against ground truth;
* :func:`plot_closures` (``plots``): closures on the trajectory;
* :func:`relative_poses` (``relative_pose``): the relative heading, the
  baseline's direction and (given a distance) the offset of two panoramas
  with a covariance (:class:`RelativePoses`), :func:`gradient_offsets`;
* :func:`revisit_change` (``revisits``): how much a network's code changes
  between two visits of one place against what their positions explain,
  the test behind the training recipe's ``feedback="auto"``;
* ``conditions``: position correspondences between recordings and the
  place-major order of long-term training.

Closures feed :meth:`sfanav.Network.fit` (``loop_closures=...``), which
interleaves each earlier image in the current one's simulated rotation;
``partners`` turns them into what it trains on (:func:`closure_partners`).

>>> import numpy as np
>>> xy = np.c_[np.r_[np.arange(10.0), np.arange(10.0)[::-1]], np.zeros(20)]
>>> lc = GroundTruthDetector(max_distance=0.1, min_gap=5).detect(np.zeros((20, 4, 16)), positions=xy)
>>> lc.current.tolist()[:3], lc.past.tolist()[:3]
([10, 11, 12], [9, 8, 7])
"""

from __future__ import annotations

from .bow import BagOfWordsDetector
from .closures import LoopClosures, align, interleave, panorama_rows
from .conditions import arc_fraction, correspondences, place_major_order
from .detectors import (
    FourierDetector,
    GroundTruthDetector,
    LoopClosureDetector,
    find_loop_closures,
    fourier_signatures,
    suppress,
)
from .evaluation import ClosureQuality, closure_precision_recall
from .factory import DETECTORS, make_detector
from .partners import closure_partners
from .plots import plot_closures, plot_precision_recall
from .relative_pose import RelativePoses, gradient_offsets, relative_poses
from .revisits import RevisitChange, revisit_change, revisit_pairs

__all__ = ["BagOfWordsDetector", "ClosureQuality", "DETECTORS", "FourierDetector", "GroundTruthDetector", "LoopClosureDetector",
           "LoopClosures", "RelativePoses", "RevisitChange", "align", "arc_fraction", "closure_partners", "closure_precision_recall", "correspondences",
           "find_loop_closures", "fourier_signatures", "gradient_offsets", "interleave", "make_detector", "panorama_rows", "place_major_order", "plot_closures",
           "plot_precision_recall", "relative_poses", "revisit_change", "revisit_pairs", "suppress"]
