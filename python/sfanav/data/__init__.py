"""Stage 0: the images a robot records, and what becomes of them before the
network sees them.

* :class:`Dataset` (an sfanav dataset folder or an insect-navigation image
  database), :class:`DatasetWriter` / :func:`write_dataset`,
  :func:`read_image` / :func:`write_image`;
* :mod:`~sfanav.data.sources`: image folders, videos and datasets as one
  :class:`ImageSource`; :func:`load_run`;
* :mod:`~sfanav.data.unwarp`: omnidirectional (mirror) images to panoramas
  (thesis 4.2.1);
* :mod:`~sfanav.data.preprocessing`: :class:`Preprocessing` (what a model
  expects) and :class:`Preprocessor` (makes any input match it);
* :mod:`~sfanav.data.image_rows`: the horizon band and row normalisation;
* :mod:`~sfanav.data.corruptions`: what a robot's camera and image transport
  do to its images (JPEG, sensor noise, blur, exposure, ...), for measuring
  robustness;
* :mod:`~sfanav.data.rosbag`: a robot's ROS bag as a dataset
  (:meth:`Dataset.from_bag`, :func:`bag_info`);
  :mod:`~sfanav.data.rosbag_writer`: :class:`BagWriter` (images, poses and
  odometry as a ROS 1 or ROS 2 bag); :mod:`~sfanav.data.ros_messages`: the
  messages in between (optional dependency ``rosbags``:
  ``pip install "sfanav[ros]"``).
"""

from __future__ import annotations

from .dataset import Dataset, write_dataset
from .image_rows import ImageRows, band_rows, horizon_band, row_normalize
from .images import read_image, write_image
from .preprocessing import Preprocessing, Preprocessor
from .rosbag import BagInfo, BagTopic, bag_info
from .rosbag_writer import BagWriter, write_estimates
from .schema import (
    COLUMNS,
    FLOAT_COLUMNS,
    FORMAT,
    INSECT_ENTRIES,
    INSECT_METADATA,
    STR_COLUMNS,
    UNITS,
    VERSION,
)
from .sources import ImageSource, load_run, open_images
from .unwarp import Mirror, Unwarper, estimate_mirror
from .writer import DatasetWriter

__all__ = ["BagInfo", "BagTopic", "BagWriter", "COLUMNS", "Dataset", "DatasetWriter", "FLOAT_COLUMNS", "FORMAT", "INSECT_ENTRIES", "INSECT_METADATA", "ImageRows", "ImageSource", "Mirror", "Preprocessing", "Preprocessor", "STR_COLUMNS", "UNITS", "Unwarper", "VERSION", "bag_info", "band_rows", "estimate_mirror", "horizon_band", "load_run", "open_images", "read_image", "row_normalize", "write_dataset", "write_estimates", "write_image"]
