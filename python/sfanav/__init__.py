"""sfanav: localization and navigation from a panoramic camera with
hierarchical Slow Feature Analysis.

The package follows the pipeline, one subpackage per stage::

    data          images, datasets, unwarping, preprocessing
    loopclosure   places seen again: loop-closure detectors, long-term training order
    sfa           SFA nodes and the receptive-field network -> slow features
    localization  slow features -> metric position (readouts, evaluation)
    landmarks     landmark views -> one network per marker -> stacked position readout
    odometry      metric learning from odometry, EKF fusion, loop closures
    navigation    cost, gradient and descents along slow features
    sim           the built-in simulated garden
    groundtruth   ground truth for real recordings: markers filmed by a calibrated camera

with the ``sfanav`` command line and the demo on top (``sfanav.app``) and the
thesis's experiments beside them (``sfanav.experiments``); neither is
imported by ``import sfanav``. The numerics run in a Rust core
(``sfanav._core``); this package is the NumPy / scikit-learn-style front.
"""

from __future__ import annotations

from . import data, groundtruth, landmarks, localization, loopclosure, navigation, odometry, sfa, sim
from ._core import __version__
from ._resources import get_memory_limit, get_num_threads, set_memory_limit, set_num_threads
from .data import Dataset, DatasetWriter, Unwarper, estimate_mirror, write_dataset
from .landmarks import LandmarkLocalizer
from .localization import Localizer, QuadraticRegression
from .loopclosure import BagOfWordsDetector, FourierDetector, GroundTruthDetector, LoopClosures, make_detector
from .navigation import (
    Navigator,
    PlaneGradient,
    RobustDescent,
    SlowFeatureCost,
    ThesisDescent,
)
from .odometry import MetricLearner, OdometryEKF
from .sfa import (
    SFA,
    Network,
    NotFittedError,
    Rotation,
    Statistics,
    beta_values,
    expand,
    expanded_dim,
    load,
    spatial_pairs,
)

__all__ = [
    "SFA",
    "BagOfWordsDetector",
    "FourierDetector",
    "GroundTruthDetector",
    "LoopClosures",
    "Dataset",
    "DatasetWriter",
    "LandmarkLocalizer",
    "Localizer",
    "MetricLearner",
    "Navigator",
    "Network",
    "NotFittedError",
    "OdometryEKF",
    "PlaneGradient",
    "QuadraticRegression",
    "RobustDescent",
    "Rotation",
    "SlowFeatureCost",
    "Statistics",
    "ThesisDescent",
    "Unwarper",
    "__version__",
    "beta_values",
    "data",
    "estimate_mirror",
    "expand",
    "expanded_dim",
    "get_memory_limit",
    "get_num_threads",
    "groundtruth",
    "landmarks",
    "load",
    "make_detector",
    "localization",
    "loopclosure",
    "navigation",
    "odometry",
    "set_memory_limit",
    "set_num_threads",
    "sfa",
    "sim",
    "spatial_pairs",
    "write_dataset",
]

