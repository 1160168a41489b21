"""What the feedback and learned-map studies (closure_weights.py, feedback_learned_map.py, learned_map_scale.py,
no_ground_truth_feedback.py) start from: a scene's name, dataset and
output JSON from the command line, the dataset's training and test runs in the sfanav default network's format,
the camera's elevation span and the bag-of-words closures the recipe's feedback finds on the training run."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from sfanav.data import Dataset
from sfanav.experiments.product_rows import product_runs
from sfanav.localization.recipe import CAMERA_ELEVATION, default_network
from sfanav.loopclosure import make_detector
from sfanav.pipeline import FEEDBACK_DETECTOR


def scene(doc: str) -> tuple[str, Path, Any, Any, tuple[float, float]]:
    """``(name, out_path, train, test, elevation)`` from ``sys.argv`` (NAME DATASET OUT; else exits with ``doc``):
    the dataset's training and test runs in the sfanav default network's format and its camera's elevation span."""
    if len(sys.argv) != 4:
        sys.exit(doc)
    name, root, out_path = sys.argv[1], sys.argv[2], Path(sys.argv[3])
    ds = Dataset(root)
    elev = tuple(ds.metadata.get("camera", {}).get("elevation_deg", CAMERA_ELEVATION))
    train, (test,) = product_runs(ds, default_network())
    return name, out_path, train, test, elev


def feedback_scene(doc: str) -> tuple[str, Path, Any, Any, tuple[float, float], Any]:
    """:func:`scene` and the bag-of-words closures the recipe's feedback finds on the training run."""
    name, out_path, train, test, elev = scene(doc)
    return name, out_path, train, test, elev, make_detector(FEEDBACK_DETECTOR).detect(train.images)


def add_entry(out_path: Path, name: str, entry: dict[str, Any], *, merge: bool = False) -> None:
    """``OUT.json[name] = entry`` (the file created or its other entries kept; ``merge``: ``entry``'s keys added to
    what ``OUT.json[name]`` holds), and the entry printed."""
    res = json.loads(out_path.read_text()) if out_path.exists() else {}
    res[name] = {**res.get(name, {}), **entry} if merge else entry
    out_path.write_text(json.dumps(res, indent=1, sort_keys=True) + "\n")
    print(name, json.dumps(entry), flush=True)
