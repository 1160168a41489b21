"""The raw recording of ``scripts/robot_bag_path.py --out BAGPATH`` as the camera-gamma investigations read it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sfanav import load
from sfanav.data import Dataset
from sfanav.localization.error_metrics import align


def raw_recording(root: Path) -> tuple[Any, Any, np.ndarray]:
    """(the raw bags' model, the rigid transform from its frame into the world's fitted on its training run, for
    scoring only, the test run's true positions (N, 2))."""
    loc = load(root / "raw" / "model.sfa")
    sim = Dataset(root / "sim")
    train_csv = np.genfromtxt(root / "raw" / "train.csv", delimiter=",", names=True)
    frame = align(np.c_[train_csv["x"], train_csv["y"]], sim.select(run="train").poses[:, :2])
    return loc, frame, sim.select(run="test").poses[:, :2]
