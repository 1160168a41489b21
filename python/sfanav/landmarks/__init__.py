"""Landmark-based SFA localization (thesis 5.4): one SFA network per marker,
trained on that marker's views cut from omnidirectional images and aligned by
the marker's polar angle, and one readout on the stacked slowest outputs of
all markers (zeros and a "missing" flag for a marker not seen).

* :mod:`~sfanav.landmarks.views`: :class:`ViewExtractor` (ArUco detection in
  the donut image, aligned ``size x size`` views), :class:`MarkerViews`.
* :mod:`~sfanav.landmarks.model`: :class:`LandmarkLocalizer` (networks,
  per-marker readouts, the stacked readout; one model file).

How it works and what it measures: docs/landmarks.md.
"""

from .model import N_OUTPUTS, NETWORK_PRESET, LandmarkLocalizer
from .views import MARGIN, VIEW_SIZE, MarkerViews, ViewExtractor, marker_view, polar_angle

__all__ = ["MARGIN", "N_OUTPUTS", "NETWORK_PRESET", "VIEW_SIZE", "LandmarkLocalizer", "MarkerViews", "ViewExtractor",
           "marker_view", "polar_angle"]
