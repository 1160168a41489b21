"""Local visual features over the seasons (thesis 6.1).

* :mod:`~sfanav.features.detectors`: detection and description on
  panoramas (FAST + BRIEF, ORB, SIFT, upright SIFT; OpenCV's free build),
  matching with the mutual consistency check or the ratio test.
* :mod:`~sfanav.features.descriptor`: the 77-dimensional texture (uniform
  LBP) and colour (hue) statistics around a keypoint.
* :mod:`~sfanav.features.robustness`: stable / unstable labels over the
  seasons, an RBF SVM that predicts a keypoint's long-term robustness, its
  JSON file, and top-k selection by detector response and predicted
  robustness.
"""

from .descriptor import DIM, robustness_vectors
from .detectors import (
    DETECTORS,
    Features,
    descriptor_distances,
    detect,
    match,
    match_distances,
    pixel_distance,
    true_match,
)
from .robustness import CANDIDATES, METHODS, RobustnessPredictor, balanced, select_ranked, stability_labels, training_samples

__all__ = ["CANDIDATES", "DETECTORS", "DIM", "METHODS", "Features", "RobustnessPredictor", "balanced", "descriptor_distances", "detect", "match",
           "match_distances", "pixel_distance",
           "robustness_vectors", "select_ranked", "stability_labels", "training_samples", "true_match"]
