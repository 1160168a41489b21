#!/usr/bin/env python3
"""Feedback training under changing light with the sfanav default (350x40): more closures (ground truth within
0.1 / 0.3 m), BoW closures, and per-image normalisation of the panoramas (thesis 5.2's preprocessing), each
standard and with feedback; MED on the test walk (docs/loop-closures.md).

    PYTHONPATH=python python3 scripts/investigations/feedback_light_variants.py runs/621-gain  # after: sfanav simulate --preset thesis-6.2.1-gain --out runs/621-gain
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
from sfanav.loopclosure import GroundTruthDetector, LoopClosures, align, make_detector
from sfanav.sfa import Rotation

root = Path(sys.argv[1])
ds = Dataset(root)
recipe = recipe_for()
rows = recipe.image_rows(tuple(ds.metadata["camera"]["elevation_deg"]))
out = {}
for normalize in (False, True):
    prep = Preprocessing(350, 40, False, normalize)
    X, xy = load_run(ds.select(run="train"), prep, log=lambda m: None)
    Xt, xyt = load_run(ds.select(run="test"), prep, log=lambda m: None)
    variants = {"standard": None,
                "gt 0.1 m": GroundTruthDetector(0.1, 50).detect(X, positions=xy),
                "gt 0.3 m": GroundTruthDetector(0.3, 50).detect(X, positions=xy)}
    for name, lc in variants.items():
        t0 = time.perf_counter()
        loc = fit_localizer(default_network(), X, xy, rotation=Rotation(5, 1.0), readout=recipe.readout, rows=rows,
                            signature=recipe.signature, progress=False, loop_closures=lc)
        med = localization_metrics(loc.predict(Xt), xyt)["med"]
        key = f"{'normalized, ' if normalize else ''}{name}"
        out[key] = {"MED (m)": med, "closures": 0 if lc is None else len(lc), "s": time.perf_counter() - t0}
        print(f"| {key} | {out[key]['closures']} | {med:.3f} | {out[key]['s']:.0f} |", flush=True)
(root.parent.parent / "feedback-light-variants.json").write_text(json.dumps(out, indent=1))
