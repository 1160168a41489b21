"""What the feedback studies (closure_weights.py, feedback_learned_map.py) start from: a scene's name, dataset and
output JSON from the command line, the dataset's training and test runs in the sfanav default network's format,
the camera's elevation span and the bag-of-words closures the recipe's feedback finds on the training run."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from sfanav.data import Dataset
from sfanav.experiments.product_rows import product_runs
from sfanav.localization.recipe import CAMERA_ELEVATION, default_network
from sfanav.loopclosure import make_detector
from sfanav.pipeline import FEEDBACK_DETECTOR


def feedback_scene(doc: str) -> tuple[str, Path, Any, Any, tuple[float, float], Any]:
    """``(name, out_path, train, test, elevation, closures)`` from ``sys.argv`` (NAME DATASET OUT; else exits with
    ``doc``)."""
    if len(sys.argv) != 4:
        sys.exit(doc)
    name, root, out_path = sys.argv[1], sys.argv[2], Path(sys.argv[3])
    ds = Dataset(root)
    elev = tuple(ds.metadata.get("camera", {}).get("elevation_deg", CAMERA_ELEVATION))
    train, (test,) = product_runs(ds, default_network())
    return name, out_path, train, test, elev, make_detector(FEEDBACK_DETECTOR).detect(train.images)
