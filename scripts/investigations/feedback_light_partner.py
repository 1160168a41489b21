#!/usr/bin/env python3
"""Feedback under changing light with the sfanav default (350x40, unnormalised): which earlier visit to pair a
frame with. Ground-truth closures within 0.1 m and at least 50 frames earlier, one per frame, with the partner
chosen as (a) the nearest in position (GroundTruthDetector, the experiment's choice), (b) the earliest visit,
(c) the visit whose mean brightness differs most from the frame's. MED on the test walk (docs/experiments.md).

    PYTHONPATH=python python3 scripts/investigations/feedback_light_partner.py runs/621-gain  # after: sfanav simulate --preset thesis-6.2.1-gain --out runs/621-gain
"""
import json
import sys
import time
from pathlib import Path

import numpy as np
from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.localization.training import fit_localizer
from sfanav.loopclosure import GroundTruthDetector, LoopClosures, align
from sfanav.sfa import Rotation

MAX_DISTANCE, MIN_GAP = 0.1, 50

root = Path(sys.argv[1])
ds = Dataset(root)
recipe = recipe_for()
rows = recipe.image_rows(tuple(ds.metadata["camera"]["elevation_deg"]))
prep = Preprocessing(350, 40, False, False)
X, xy = load_run(ds.select(run="train"), prep, log=lambda m: None)
Xt, xyt = load_run(ds.select(run="test"), prep, log=lambda m: None)
brightness = X.reshape(len(X), -1).mean(axis=1)


def closures(choose):
    past, cur = [], []
    for i in range(MIN_GAP, len(X)):
        d = np.hypot(*(xy[: i - MIN_GAP + 1] - xy[i]).T)
        cand = np.flatnonzero(d <= MAX_DISTANCE)
        if cand.size:
            past.append(int(choose(i, cand, d)))
            cur.append(i)
    past, cur = np.array(past, np.int64), np.array(cur, np.int64)
    dist = np.hypot(*(xy[past] - xy[cur]).T)
    return LoopClosures(past, cur, align(X, past, cur), np.ones(len(past)), dist)


variants = {
    "nearest (GroundTruthDetector)": GroundTruthDetector(MAX_DISTANCE, MIN_GAP).detect(X, positions=xy),
    "earliest visit": closures(lambda i, cand, d: cand.min()),
    "most different brightness": closures(lambda i, cand, d: cand[np.argmax(np.abs(brightness[cand] - brightness[i]))]),
}
out = {}
for name, lc in variants.items():
    t0 = time.perf_counter()
    loc = fit_localizer(default_network(), X, xy, rotation=Rotation(5, 1.0), readout=recipe.readout, rows=rows,
                        signature=recipe.signature, progress=False, loop_closures=lc)
    med = localization_metrics(loc.predict(Xt), xyt)["med"]
    gap = float(np.abs(brightness[lc.past] - brightness[lc.current]).mean())
    out[name] = {"MED (m)": med, "closures": len(lc), "mean distance (m)": float(lc.distance.mean()),
                 "mean brightness gap": gap, "s": time.perf_counter() - t0}
    print(f"| {name} | {len(lc)} | {lc.distance.mean():.3f} | {gap:.4f} | {med:.3f} |", flush=True)
(root.parent.parent / "feedback-light-partner.json").write_text(json.dumps(out, indent=1))
