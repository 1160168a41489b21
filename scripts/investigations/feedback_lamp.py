#!/usr/bin/env python3
"""Feedback when the direct sunlight (the thesis's lamp) rises through training while the sky stays
(preset thesis-6.2.1-light): the sfanav default (350x40) on raw and on normalised panoramas, standard and with
ground-truth closures (0.1 m, 50 frames apart); MED on the test walk, beside the peers (docs/experiments.md, 6.2.1).

    sfanav simulate --preset thesis-6.2.1-light --out runs/lamp/data
    PYTHONPATH=python python3 scripts/investigations/feedback_lamp.py runs/lamp/data [--configs raw,normalised]
"""
import argparse
import json
import time
from pathlib import Path

from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.localization import baselines
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.localization.training import fit_localizer
from sfanav.loopclosure import GroundTruthDetector
from sfanav.sfa import Rotation

ap = argparse.ArgumentParser()
ap.add_argument("dataset")
ap.add_argument("--configs", default="raw,normalised")
ap.add_argument("--json")
a = ap.parse_args()
ds = Dataset(Path(a.dataset)); recipe = recipe_for()
rows_step = recipe.image_rows(tuple(ds.metadata["camera"]["elevation_deg"]))
out = {}
for config in a.configs.split(","):
    prep = Preprocessing(350, 40, False, config == "normalised")
    X, xy = load_run(ds.select(run="train"), prep, log=lambda m: None)
    Xt, xyt = load_run(ds.select(run="test"), prep, log=lambda m: None)
    lc = GroundTruthDetector(0.1, 50).detect(X, positions=xy)
    res = {"closures": len(lc)}
    for peer, model in (("perfect memory", baselines.PerfectMemory()), ("Fourier signature", baselines.FourierSignature())):
        model.fit(X, xy)
        res[peer] = localization_metrics(model.predict(Xt), xyt)["med"]
        print(config, peer, round(res[peer], 3), flush=True)
    for name, c in (("standard", None), ("feedback", lc)):
        t0 = time.perf_counter()
        loc = fit_localizer(default_network(), X, xy, rotation=Rotation(5, 1.0), readout=recipe.readout,
                            rows=rows_step, signature=recipe.signature, progress=False, loop_closures=c)
        res[name] = localization_metrics(loc.predict(Xt), xyt)["med"]
        res[name + " s"] = time.perf_counter() - t0
        print(config, name, round(res[name], 3), f"{res[name + ' s']:.0f} s", flush=True)
    res["ratio"] = res["standard"] / res["feedback"]
    print(config, "standard / feedback", round(res["ratio"], 2), flush=True)
    out[config] = res
if a.json:
    Path(a.json).write_text(json.dumps(out, indent=1))
