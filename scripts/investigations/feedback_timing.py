#!/usr/bin/env python3
"""Training time with loop-closure feedback against without, paired and alternating in one process
(docs/loop-closures.md): the sfanav default's network (350x40) or the thesis configuration's (600x60) on the
6.2.1 changing-light training run with its ground-truth closures (0.1 m, gap 50).

    PYTHONPATH=python python3 scripts/investigations/feedback_timing.py runs/621-gain --pairs 3  # after: sfanav simulate --preset thesis-6.2.1-gain --out runs/621-gain
"""
import argparse
import time

import numpy as np

from sfanav import Network, Rotation
from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.loopclosure import GroundTruthDetector

ap = argparse.ArgumentParser()
ap.add_argument("dataset")
ap.add_argument("--pairs", type=int, default=3)
ap.add_argument("--thesis", action="store_true", help="the thesis configuration's network on 600x60")
a = ap.parse_args()
ds = Dataset(a.dataset).select(run="train")
if a.thesis:
    X, xy = load_run(ds, Preprocessing(600, 60, False), log=lambda m: None)
    make = lambda: Network.from_preset("thesis-5.2", precision="mixed")  # noqa: E731
else:
    X, xy = load_run(ds, Preprocessing(350, 40, False), log=lambda m: None)
    X = recipe_for().image_rows(tuple(Dataset(a.dataset).metadata["camera"]["elevation_deg"]))(X)
    make = default_network
lc = GroundTruthDetector(0.1, 50).detect(X, positions=xy)
print(f"{len(X)} images, {len(lc)} closures")
ratios = []
for i in range(a.pairs):
    t = {}
    for name, kw in (("standard", {}), ("feedback", {"loop_closures": lc})) if i % 2 == 0 else \
            (("feedback", {"loop_closures": lc}), ("standard", {})):
        t0 = time.perf_counter()
        make().fit(X, Rotation(5, 1.0), progress=False, **kw)
        t[name] = time.perf_counter() - t0
    ratios.append(t["feedback"] / t["standard"])
    print(f"pair {i}: standard {t['standard']:.1f} s, feedback {t['feedback']:.1f} s, ratio {ratios[-1]:.3f}", flush=True)
print(f"median ratio feedback / standard: {np.median(ratios):.3f}")
