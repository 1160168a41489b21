#!/usr/bin/env python3
"""Would the camera-gamma tracker fire on the experiments' flawless test runs? (docs/robustness.md, "The camera's
gamma by default"). For each scene, the tracker (:class:`sfanav.data.camera_gamma.CameraGamma`, the defaults) with
the training run's reference, fed the test run in its order at its ground-truth positions (a proxy for the
localizer's estimates, which place the images in the product): the final median log ratio against the dead zone
(0.2; a gamma of 0.7 or 1.4 reads 0.29-0.36). Scenes split into runs take their ``train`` run (else the first) as
the training run and every other as a test run, in the
default network's input format (omnidirectional images unwarped; gray images as they are); scenes of recordings
in several conditions (6.2.2's conditions and seasons) take the first condition as the training run and every
other as a test run (panoramas resized to 350x40).

    PYTHONPATH=python python3 scripts/investigations/camera_gamma_scenes.py OUT.json DATASET...

DATASET: a dataset directory (``sfanav experiment NAME`` writes its scene to OUT/data/NAME-seed0). About 3 min
for the 15 scenes the docs list.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from sfanav.data import Dataset
from sfanav.data.camera_gamma import DEAD_ZONE, CameraGamma, reference_spread
from sfanav.data.preprocessing import Preprocessing, Preprocessor
from sfanav.data.sources import open_images
from sfanav.localization.recipe import default_network


def log_ratio(train: np.ndarray, train_xy: np.ndarray, test: np.ndarray, test_xy: np.ndarray) -> float:
    ok = np.isfinite(test_xy).all(axis=1)
    ref = reference_spread(train, train_xy)
    tracker = CameraGamma(ref["spreads"], ref["positions"])
    tracker.correct(test[ok], test_xy[ok])
    return tracker.log_ratio_


def run_split(path: Path, runs: list[str]) -> dict[str, float]:
    conform = Preprocessor(Preprocessing.for_network(default_network()), log=lambda *a, **k: None)

    def load(run: str) -> tuple[np.ndarray, np.ndarray]:
        src = open_images(path, run=run)
        batches = list(src.batches(64))
        gray = batches[0].ndim == 3  # the RGB network does not take gray images: their own format
        return np.concatenate(batches if gray else [conform(b) for b in batches]), src.xy

    train = "train" if "train" in runs else runs[0]
    ref = load(train)
    return {f"{train} -> {r}": log_ratio(*ref, *load(r)) for r in runs if r != train}


def run_conditions(ds: Dataset) -> dict[str, float]:
    conds = list(dict.fromkeys(ds.conditions.tolist()))

    def load(c: str) -> tuple[np.ndarray, np.ndarray]:
        sub = ds.select(condition=c)
        return sub.load_images(size=(350, 40)), sub.poses[:, :2]

    train = load(conds[0])
    return {f"{conds[0]} -> {c}": log_ratio(*train, *load(c)) for c in conds[1:]}


def main() -> None:
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out = Path(sys.argv[1])
    res: dict = {"dead zone": DEAD_ZONE, "scenes": {}}
    for d in map(Path, sys.argv[2:]):
        ds = Dataset(d)
        runs = list(dict.fromkeys(ds.runs.tolist()))
        r = run_split(d, runs) if len(runs) > 1 else run_conditions(ds)
        res["scenes"][d.name] = r
        print(d.name, ", ".join(f"{k} {v:+.3f}" for k, v in r.items()), flush=True)
    res["largest |log ratio| per scene"] = {n: max(abs(v) for v in r.values()) for n, r in res["scenes"].items()}
    every = [abs(v) for r in res["scenes"].values() for v in r.values()]
    res["largest |log ratio|"] = max(every)
    res["any factor applied"] = bool(max(every) > DEAD_ZONE)
    out.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
