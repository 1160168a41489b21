"""sfanav: localization and navigation from a panoramic camera with
hierarchical Slow Feature Analysis.

The numerics run in a Rust core (``sfanav._core``); this package is the
NumPy / scikit-learn-style front.
"""

from . import sim
from ._core import __version__, get_num_threads, set_num_threads
from .dataset import Dataset, DatasetWriter, write_dataset
from .modelfile import load
from .network import Network, Rotation, spatial_pairs
from .sfa import SFA, NotFittedError, Statistics, beta_values, expand, expanded_dim

__all__ = [
    "SFA",
    "Network",
    "Dataset",
    "DatasetWriter",
    "write_dataset",
    "sim",
    "Rotation",
    "spatial_pairs",
    "Statistics",
    "NotFittedError",
    "beta_values",
    "expand",
    "expanded_dim",
    "load",
    "set_num_threads",
    "get_num_threads",
    "__version__",
]

# Localization building blocks (issue 6): unwarping, regression, metrics, analysis, baselines.
from . import analysis, baselines, metrics, regression, unwarp  # noqa: E402
from . import workflow  # noqa: E402  (issue 6: the pipeline behind the sfanav command)
from .localizer import Localizer  # noqa: E402
from .regression import QuadraticRegression  # noqa: E402
from .unwarp import Unwarper, estimate_mirror  # noqa: E402

__all__ += ["Localizer", "QuadraticRegression", "Unwarper", "estimate_mirror"]
__all__ += ["analysis", "baselines", "metrics", "regression", "unwarp", "workflow"]

# The sfanav default (issue 7): network preset, horizon band, auto readout; readouts beyond the thesis's.
from . import defaults, readout  # noqa: E402

__all__ += ["defaults", "readout"]

# Odometry integration (issue 8): line segmentation, unsupervised metric learning, EKF fusion.
from . import ekf, experiments_odometry, metric, odometry  # noqa: E402
from .ekf import OdometryEKF  # noqa: E402
from .metric import MetricLearner  # noqa: E402

__all__ += ["MetricLearner", "OdometryEKF", "ekf", "experiments_odometry", "metric", "odometry"]

# Navigation along slow-feature gradients (issue 9): cost, plane-fit gradient, descents, closed loop, A*.
from . import navigation  # noqa: E402
from .navigation import Navigator, PlaneGradient, RobustDescent, SlowFeatureCost, ThesisDescent  # noqa: E402

__all__ += ["navigation", "Navigator", "PlaneGradient", "RobustDescent", "SlowFeatureCost", "ThesisDescent"]
