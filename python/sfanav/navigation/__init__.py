"""Stage 5: navigation along slow-feature gradients (thesis chapter 7).

* cost (:class:`SlowFeatureCost`, :class:`ScaledCost`), gradient
  (:class:`PlaneGradient`) and descents (:class:`ThesisDescent`,
  :class:`RobustDescent`, :class:`MetricDescent`) with one interface;
* feature sources for the closed loop (:class:`ImageFeatures`,
  :class:`MetricFeatures`, :class:`CoordinateFeatures`,
  :class:`RunGraphFeatures`);
* the peer: homing by perfect memory (:class:`PanoramaFeatures`,
  :func:`image_difference_cost`: descent of the rotational image difference
  to the target's view);
* :class:`GeodesicField`: shortest paths through the space an exploration
  run covered;
* :class:`Navigator` (the closed loop on a simulated robot), trials and their
  evaluation, planning baselines (A*, velocity regions) and plots;
* :func:`navigate`: one mission to a goal (a position in the localizer's map
  or an image) with a trained localizer and the exploration run's geodesic
  field (what ``sfanav navigate`` runs).
"""

from __future__ import annotations

from ..odometry.tracker import MapTracker
from ..sim.point import PointSimulator
from .cost import ScaledCost, SlowFeatureCost, beta_weights, run_spread
from .descent import Descent, MetricDescent, RobustDescent, StepInfo, ThesisDescent
from .features import (
    CoordinateFeatures,
    ImageFeatures,
    MetricFeatures,
    RunGraphFeatures,
    fit_coordinate_sfa,
)
from .geodesic import GeodesicField
from .homing import PanoramaFeatures, RotationalImageDifferenceCost, image_difference_cost, rotational_image_difference
from .gradient import PlaneGradient, difference_quotient, plane_gradient
from .mission import Mission, check_goal_in_map, image_goal, navigate
from .navigator import NavigationResult, Navigator
from .planning import (
    GridMap,
    astar,
    halfplane_optimal,
    occupancy_grid,
    path_length,
    shortest_path,
    travel_time,
)
from .plots import plot_cost_surface, plot_trajectories
from .trials import TrialSummary, evaluate_trials, sample_trials

__all__ = ["PanoramaFeatures", "RotationalImageDifferenceCost", "image_difference_cost",
           "rotational_image_difference", "Mission", "check_goal_in_map", "image_goal", "navigate", "GridMap", "CoordinateFeatures", "Descent", "GeodesicField", "ImageFeatures", "MapTracker", "MetricDescent", "MetricFeatures", "NavigationResult", "Navigator", "PlaneGradient", "PointSimulator", "RobustDescent", "RunGraphFeatures", "ScaledCost", "SlowFeatureCost", "StepInfo", "ThesisDescent", "TrialSummary", "astar", "beta_weights", "difference_quotient", "evaluate_trials", "fit_coordinate_sfa", "halfplane_optimal", "occupancy_grid", "path_length", "plane_gradient", "plot_cost_surface", "plot_trajectories", "run_spread", "sample_trials", "shortest_path", "travel_time"]
