#!/usr/bin/env python3
"""The revisit ratio (sfanav.loopclosure.revisits) of the sfanav default's network on a dataset's training run:
how much its code changes between two visits of one place against what their positions explain, with the
positions the readout is fitted to (ground truth, or ``--no-ground-truth``: the positions the recipe learns from
the run's images and odometry) and, for comparison, ground truth; and with the loop closures the bag of words finds
on the images as the revisits instead (``pairs=``), the positions scaling their distances. The recipe's ``feedback="auto"`` trains again
with loop-closure feedback above ``FEEDBACK_RATIO`` (``FEEDBACK_RATIO_LEARNED`` on learned positions); here the
model is trained without it (``feedback="none"``).

    sfanav simulate --preset thesis-6.2.1-light --seed 0 --out runs/light
    PYTHONPATH=python python3 scripts/investigations/revisit_ratio.py light runs/light OUT.json [--no-ground-truth]
    PYTHONPATH=python python3 scripts/investigations/revisit_ratio.py --redecide OUT.json [CLOSURES.json]

Adds one entry ``NAME|ground truth`` or ``NAME|no ground truth`` to OUT.json (created if missing). ``--redecide``
trains nothing: it sets every stored entry's threshold and feedback decision from its ratio by the present policy
(and, for entries without a count of the bag of words' closures, the count no_ground_truth_feedback.py stored in
CLOSURES.json).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from sfanav.data import Dataset
from sfanav.experiments.product_rows import product_runs
from sfanav.localization.recipe import default_network
from sfanav.loopclosure import make_detector
from sfanav.loopclosure.revisits import (FEEDBACK_RATIO, FEEDBACK_RATIO_LEARNED, MIN_REVISITS, revisit_change,
                                         revisit_pairs)
from sfanav.pipeline import train_localizer


def by_direction(F: np.ndarray, xy: np.ndarray) -> dict:
    """The revisit ratio on eight features with the revisits split by the angle between the two passes' directions
    of travel (from the positions): the same direction (< 30 deg), across, the reverse (> 150 deg)."""
    cur, past = revisit_pairs(xy)
    d = np.gradient(xy, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    turn = np.degrees(np.abs(np.angle(np.exp(1j * (h[cur] - h[past])))))
    out = {}
    for name, m in (("same", turn < 30), ("across", (turn >= 30) & (turn <= 150)), ("reverse", turn > 150)):
        rc = revisit_change(F, xy, n_features=8, pairs=(cur[m], past[m]))
        out[name] = {"revisits": int(m.sum()), "ratio": rc.to_dict()["ratio"]}
    return out


def decide(entry: dict) -> None:
    """The entry's threshold and feedback decision by the recipe's policy (pipeline.train_localizer): above the
    threshold, and at least MIN_REVISITS closures from the bag of words."""
    entry["threshold"] = FEEDBACK_RATIO if entry["positions"] == "ground truth" else FEEDBACK_RATIO_LEARNED
    ratio = entry["revisit change"]["ratio"]
    found = entry.get("bag-of-words pairs", {}).get("count")  # entries made before the pairs were counted: None
    entry["feedback"] = bool(ratio is not None and ratio > entry["threshold"]
                             and (found is None or found >= MIN_REVISITS))


def main() -> None:
    import sys

    if len(sys.argv) in (3, 4) and sys.argv[1] == "--redecide":
        out = Path(sys.argv[2])
        res = json.loads(out.read_text())
        # the closures no_ground_truth_feedback.py counted, for entries made before the pairs were counted
        counted = json.loads(Path(sys.argv[3]).read_text()) if len(sys.argv) == 4 else {}
        for entry in res.values():
            n = counted.get(entry["scene"], {}).get("closures")
            if entry["positions"] == "no ground truth" and n is not None and "bag-of-words pairs" not in entry:
                entry["bag-of-words pairs"] = {"count": int(n)}
            decide(entry)
        out.write_text(json.dumps(res, indent=1, sort_keys=True) + "\n")
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("name")
    ap.add_argument("dataset")
    ap.add_argument("out")
    ap.add_argument("--no-ground-truth", action="store_true")
    a = ap.parse_args()
    ds = Dataset(a.dataset)
    elev = tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))
    train, _ = product_runs(ds, default_network())
    t0 = time.perf_counter()
    if a.no_ground_truth:
        loc = train_localizer(train.images, odometry=train.odometry, gyro=train.gyro, supervision="odometry",
                              camera_elevation=elev, filter_noise=False, feedback="none")
    else:
        loc = train_localizer(train.images, xy=train.xy, supervision="ground-truth", camera_elevation=elev,
                              filter_noise=False, feedback="none")
    F = loc.features(train.images)
    sup = "no ground truth" if a.no_ground_truth else "ground truth"
    entry = {"scene": a.name, "positions": sup, "frames": int(len(F)), "training (s)": time.perf_counter() - t0,
             "revisit change": revisit_change(F, loc.training_positions_).to_dict(),
             "with ground-truth positions": revisit_change(F, train.xy).to_dict()}
    entry["by number of features"] = {k: revisit_change(F, loc.training_positions_, n_features=k).ratio
                                      for k in range(1, min(8, F.shape[1]) + 1)}
    entry["eight features, by direction of travel"] = by_direction(F, loc.training_positions_)
    bow = make_detector("bow").detect(train.images)
    entry["bag-of-words pairs"] = {"count": int(len(bow)), **revisit_change(
        F, loc.training_positions_, pairs=(bow.current, bow.past)).to_dict()}
    decide(entry)
    out = Path(a.out)
    res = json.loads(out.read_text()) if out.exists() else {}
    res[f"{a.name}|{sup}"] = entry
    out.write_text(json.dumps(res, indent=1, sort_keys=True) + "\n")
    print(json.dumps(entry), flush=True)


if __name__ == "__main__":
    main()
