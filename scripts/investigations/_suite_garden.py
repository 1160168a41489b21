"""A garden of the corruption suite as the product investigations read it (the suite's runs, seed 0)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from sfanav.data import Dataset
from sfanav.data.preprocessing import Preprocessing, Preprocessor
from sfanav.data.sources import load_run
from sfanav.experiments.corruptions import GARDENS
from sfanav.localization.recipe import Recipe, default_network, recipe_for
from sfanav.pipeline import train_localizer


class _Part(Recipe):
    """The default's recipe with one part of robustness "light": the photometric normalisation only
    ("photometric-only") or the readout's corrupted copies only ("copies-only")."""

    def robust_kwargs(self, model=None):
        kw = super().robust_kwargs() if model is None else super().robust_kwargs(model)
        part = getattr(self, "_part", "")
        if part == "photometric-only":
            kw["readout_augmentation"] = None
        elif part == "copies-only":
            kw["photometric"] = None
        return kw


PARTS = ("photometric-only", "copies-only")
"""Robustness levels of :meth:`Garden.product` beyond the library's: a part of ``"light"`` alone."""


def recipe(robustness: str) -> Recipe:
    """The default's recipe at a library robustness level or one of :data:`PARTS`."""
    if robustness not in PARTS:
        return recipe_for(robustness=robustness)
    base = recipe_for(robustness="light")
    r = _Part(**{f.name: getattr(base, f.name) for f in fields(base)})
    object.__setattr__(r, "_part", robustness)
    return r


@dataclass
class Garden:
    train: Any  # the training run (Dataset)
    test: Any  # the test run (Dataset)
    native: tuple[np.ndarray, np.ndarray]  # the camera's training and test images
    xy: np.ndarray  # the training run's true positions (scoring only)
    xyt: np.ndarray  # the test run's
    conform: Preprocessor  # camera images -> the default network's input
    elevation: tuple[float, float]

    def product(self, robustness: str):
        """The ground-truth-free default with ``robustness`` (a library level or one of :data:`PARTS`), seed 0,
        trained on the conformed training run."""
        return train_localizer(self.conform(self.native[0]), odometry=self.train.odometry, supervision="odometry",
                               network=default_network(), recipe=recipe(robustness),
                               camera_elevation=self.elevation, seed=0)


def load_garden(out: Path, preset: str) -> Garden:
    """The suite's garden ``preset`` from ``out/data/PRESET-seed0`` (``sfanav experiment corruptions --out OUT``)."""
    tr, te = {p: (a, b) for p, a, b in GARDENS}[preset]
    ds = Dataset(out / "data" / f"{preset}-seed0")
    cam = ds.metadata["camera"]
    native = Preprocessing(int(cam["width"]), int(cam["height"]), False)
    train, test = ds.select(run=tr), ds.select(run=te)
    X0, xy = load_run(train, native)
    T0, xyt = load_run(test, native)
    return Garden(train, test, (X0, T0), xy, xyt,
                  Preprocessor(Preprocessing.for_network(default_network()), log=lambda *a, **k: None),
                  tuple(cam.get("elevation_deg", (-30.0, 20.0))))
