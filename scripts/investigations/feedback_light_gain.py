#!/usr/bin/env python3
"""Feedback under changing light with the sfanav default (350x40) on panoramas divided by their mean brightness
(a global gain, not zero mean / unit variance): standard and with ground-truth closures (0.1 m); MED on the test walk
(docs/experiments.md, 6.2.1-light).

    PYTHONPATH=python python3 scripts/investigations/feedback_light_gain.py runs/621-gain  # after: sfanav simulate --preset thesis-6.2.1-gain --out runs/621-gain
"""
import sys
import time
from pathlib import Path

import numpy as np
from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.localization.training import fit_localizer
from sfanav.loopclosure import GroundTruthDetector
from sfanav.sfa import Rotation

root = Path(sys.argv[1]); ds = Dataset(root); recipe = recipe_for()
rows = recipe.image_rows(tuple(ds.metadata["camera"]["elevation_deg"]))
prep = Preprocessing(350, 40, False, False)
X, xy = load_run(ds.select(run="train"), prep, log=lambda m: None)
Xt, xyt = load_run(ds.select(run="test"), prep, log=lambda m: None)

def gain(A):
    A = A.astype(np.float32)
    m = A.reshape(len(A), -1).mean(axis=1)
    return A / m[:, None, None, None] * 100.0 if A.ndim == 4 else A / m[:, None, None] * 100.0
Xg, Xtg = gain(X), gain(Xt)
lc = GroundTruthDetector(0.1, 50).detect(Xg, positions=xy)
for name, c in (("gain standard", None), ("gain feedback", lc)):
    t0 = time.perf_counter()
    loc = fit_localizer(default_network(), Xg, xy, rotation=Rotation(5, 1.0), readout=recipe.readout, rows=rows,
                        signature=recipe.signature, progress=False, loop_closures=c)
    print(name, localization_metrics(loc.predict(Xtg), xyt)["med"], time.perf_counter() - t0, flush=True)
