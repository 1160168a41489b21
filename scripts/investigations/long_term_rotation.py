#!/usr/bin/env python3
"""6.2.2 with and without simulated rotation: the thesis trained its long-term model on the loop's images as
they come (one view per image, no rotation invariance: its 6.2.2 discussion names condition *and* orientation
invariance as future work). Trains on k = SETS recordings of permutation P in place-major order and tests on the
next one.

    PYTHONPATH=python python3 scripts/investigations/long_term_rotation.py DATA_DIR --configs "sfanav default" \
        --rotation none 5 --sets 1 3 5 9
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

from sfanav.data.sources import load_run
from sfanav.data.dataset import Dataset
from sfanav.experiments.robustness import _config, recipe_for
from sfanav.localization import baselines
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.training import fit_localizer
from sfanav.loopclosure.conditions import correspondences, place_major_order
from sfanav.sfa.network import Rotation

ap = argparse.ArgumentParser()
ap.add_argument("data", type=Path)
ap.add_argument("--configs", nargs="+", default=["sfanav default"])
ap.add_argument("--rotation", nargs="+", default=["none", "5"])
ap.add_argument("--sets", nargs="+", type=int, default=[1, 3, 5, 9])
ap.add_argument("--permutations", nargs="+", type=int, default=[0])
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--out", type=Path, default=None)
a = ap.parse_args()

ds = Dataset(a.data)
conds = sorted(set(ds.conditions.tolist()), key=lambda c: int(c.lstrip("c")))
results = []
for config in a.configs:
    make_net, prep, kw = _config(config, False)
    sets = [load_run(ds.select(condition=c), prep) for c in conds]
    places = [correspondences(sets[0][1], s[1]) for s in sets]
    rows = None if config == "thesis config" else recipe_for().image_rows(
        tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0))))
    width = sets[0][0].shape[2]
    for p in a.permutations:
        rng = np.random.default_rng(a.seed)
        perm = rng.permutation(len(conds)) if p == 0 else np.random.default_rng([a.seed, p]).permutation(len(conds))
        for k in a.sets:
            train, test = perm[:k], perm[k]
            order = place_major_order([places[s] for s in train])
            X = np.concatenate([sets[s][0] for s in train])[order]
            xy = np.concatenate([sets[s][1] for s in train])[order]
            X_te, xy_te = sets[test]
            pm = localization_metrics(baselines.PerfectMemory().fit(X, xy).predict(X_te), xy_te)["med"]
            for rot in a.rotation:
                kw2 = dict(kw)
                if rot == "none":
                    rotation = Rotation(width, 1.0)
                    kw2["rotation_pooling"] = None
                else:
                    rotation = Rotation(int(rot), 1.0)
                t0 = time.perf_counter()
                loc = fit_localizer(make_net(), X, xy, rotation=rotation, rows=rows, progress=False, **kw2)
                t = time.perf_counter() - t0
                m = localization_metrics(loc.predict(X_te), xy_te)
                m_tr = localization_metrics(loc.predict(X[::7]), xy[::7])
                r = {"config": config, "perm": p, "sets": k, "rotation": rot, "med": m["med"], "train_med": m_tr["med"],
                     "pm": pm, "seconds": t, "test": conds[test]}
                results.append(r)
                print(json.dumps(r), flush=True)
if a.out:
    a.out.write_text(json.dumps(results, indent=1))
