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
* :mod:`~sfanav.data.image_rows`: the horizon band and row normalisation.
"""

from __future__ import annotations

from .dataset import Dataset, write_dataset
from .image_rows import ImageRows, band_rows, horizon_band, row_normalize
from .images import read_image, write_image
from .preprocessing import Preprocessing, Preprocessor
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

__all__ = ["COLUMNS", "Dataset", "DatasetWriter", "FLOAT_COLUMNS", "FORMAT", "INSECT_ENTRIES", "INSECT_METADATA", "ImageRows", "ImageSource", "Mirror", "Preprocessing", "Preprocessor", "STR_COLUMNS", "UNITS", "Unwarper", "VERSION", "band_rows", "estimate_mirror", "horizon_band", "load_run", "open_images", "read_image", "row_normalize", "write_dataset", "write_image"]
