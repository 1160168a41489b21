#!/usr/bin/env python3
"""BoW closures under the lamp light (6.2.1-bow): how many candidates the image verification accepts, and what
feedback with them gives the sfanav default, for several acceptance ratios (``BagOfWordsDetector(accept=...)``:
a match is accepted when its aligned, normalised image distance is at most ``accept`` times the frame's distance
to its temporal neighbours). Candidates are detected once, as the experiment does (on the 600x60 panoramas), and
thresholded again; precision against ground truth is for evaluation only.

    PYTHONPATH=python python3 scripts/investigations/feedback_bow_accept.py runs/exp62L/data/thesis-6.2.1-light-seed0 \
        --accept 0.5 0.7 1.0 --json docs/results/investigations/6.2.1-bow-accept.json
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np
from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.localization.training import fit_localizer
from sfanav.loopclosure import LoopClosures, align, closure_precision_recall, make_detector
from sfanav.sfa import Rotation

ap = argparse.ArgumentParser()
ap.add_argument("dataset", type=Path)
ap.add_argument("--accept", type=float, nargs="+", default=[0.5, 0.7, 1.0])
ap.add_argument("--train", type=float, nargs="*", default=None, help="accept values to train with (default all)")
ap.add_argument("--normalize", action="store_true", help="train the default on normalised panoramas")
ap.add_argument("--json", type=Path)
a = ap.parse_args()
ds = Dataset(a.dataset)
recipe = recipe_for()
rows_step = recipe.image_rows(tuple(ds.metadata["camera"]["elevation_deg"]))
X6, xy = load_run(ds.select(run="train"), Preprocessing(600, 60, False), log=lambda m: None)
t0 = time.perf_counter()
det = make_detector("bow", min_gap=50)
cand = det.candidates(X6, positions=xy)
print(f"{len(cand)} candidates in {time.perf_counter() - t0:.0f} s", flush=True)
del X6
X, _ = load_run(ds.select(run="train"), Preprocessing(350, 40, False, a.normalize), log=lambda m: None)
Xt, xyt = load_run(ds.select(run="test"), Preprocessing(350, 40, False, a.normalize), log=lambda m: None)
ratio = 1.0 / np.asarray(cand.score) - 1.0
out = {}
for acc in a.accept:
    lc = cand.select(ratio <= acc)
    pr = closure_precision_recall(lc, xy, max_distance=0.1, min_gap=50)
    res = {"closures": len(lc), "precision": pr.precision, "mean distance (m)": pr.mean_distance,
           "within 0.3 m": float(np.mean(np.linalg.norm(xy[lc.past] - xy[lc.current], axis=1) <= 0.3))
           if len(lc) else None}
    print(acc, res, flush=True)
    if a.train is None or acc in a.train:
        lc = LoopClosures(lc.past, lc.current, align(X, lc.past, lc.current), lc.score, lc.distance)
        t0 = time.perf_counter()
        loc = fit_localizer(default_network(), X, xy, rotation=Rotation(5, 1.0), readout=recipe.readout,
                            rows=rows_step, signature=recipe.signature, progress=False, loop_closures=lc)
        res["MED (m)"] = localization_metrics(loc.predict(Xt), xyt)["med"]
        print(acc, "feedback MED", round(res["MED (m)"], 3), f"{time.perf_counter() - t0:.0f} s", flush=True)
    out[str(acc)] = res
if a.json:
    a.json.write_text(json.dumps({"dataset": str(a.dataset), "normalize": a.normalize, "rows": out}, indent=1))
