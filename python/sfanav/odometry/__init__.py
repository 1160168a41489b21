"""Stage 4: metric space and filtering with wheel odometry.

* :mod:`~sfanav.odometry.dead_reckoning` and :mod:`~sfanav.odometry.lines`:
  pose increments, dead reckoning, straight-line segmentation;
* :class:`MetricLearner`: the map from slow features to metric (x, y)
  learned from odometry alone (thesis 5.3.1), with its cost in
  :mod:`~sfanav.odometry.metric_cost`;
* :class:`OdometryEKF`: fusion of position estimates with odometry (5.3.2);
  :mod:`~sfanav.odometry.fusion`: its noise from the training run and the
  start pose from the first estimates (no ground truth);
* :class:`MapTracker`: a robust rigid fit of odometry to recent estimates;
* :func:`fit_pose_graph`: odometry whose heading drift is corrected by
  loop closures (places found by the slow features, relative headings read
  off the panoramas);
* :func:`learn_positions`, :func:`fit_localizer_from_odometry`: training
  without ground truth, on the positions the pose graph or the metric map
  learns;
* plots of the learned lines and the fused track.
"""

from __future__ import annotations

from .dead_reckoning import arc_factor, as_poses, dead_reckon, increments, wrap_angle
from .ekf import GridSearchResult, OdometryEKF, ctrv_jacobians, ctrv_motion, grid_search
from .fusion import (fuse, fuse_images, noise_for_localizer, noise_from_run, novelty_exponent, novelty_scale,
                     start_pose_from_estimates)
from .lines import Lines, lines_from_labels, lines_from_odometry, segment_lines
from .metric_cost import DEFAULT_ODOMETRY_NOISE, metric_cost, odometry_variances
from .metric_learning import MetricLearner
from .plots import plot_fusion, plot_metric_lines
from .pose_graph import PlacePairs, PoseGraph, fit_pose_graph, place_pairs, relative_headings
from .self_supervision import (
    LearnedPositions,
    OdometryMapWarning,
    fit_localizer_from_odometry,
    learn_positions,
)
from .tracker import MapTracker

__all__ = ["PlacePairs", "PoseGraph", "fit_pose_graph", "place_pairs", "relative_headings", "fuse", "fuse_images", "novelty_exponent", "novelty_scale", "noise_for_localizer", "noise_from_run", "start_pose_from_estimates", "LearnedPositions", "OdometryMapWarning", "fit_localizer_from_odometry", "learn_positions", "DEFAULT_ODOMETRY_NOISE", "GridSearchResult", "Lines", "MapTracker", "MetricLearner", "OdometryEKF", "arc_factor", "as_poses", "ctrv_jacobians", "ctrv_motion", "dead_reckon", "grid_search", "increments", "lines_from_labels", "lines_from_odometry", "metric_cost", "odometry_variances", "plot_fusion", "plot_metric_lines", "segment_lines", "wrap_angle"]
