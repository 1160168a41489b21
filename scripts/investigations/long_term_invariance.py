#!/usr/bin/env python3
"""Condition *and* orientation invariance in one long-term model (the open question of thesis 6.2.2's
discussion). Three ways to train the sfanav default on k recordings of the 6.2.2 loop in place-major order:

* "no rotation" (the thesis): the images as they come; the model may code the route's fixed heading;
* "rotation": simulated rotation (5 px); between-image transitions (the only place the condition changes) are one
  derivative pair per 70 rotation steps;
* "rotation + place feedback": simulated rotation, and every image's rotation interleaved with the aligned image of
  the same place in the previous condition (the loop-closure feedback of 6.2.1 with the place-major neighbours as
  closures), so every rotation step carries a change of condition.

Tested on the next recording as it was driven and with every test panorama turned to a random heading.

    PYTHONPATH=python python3 scripts/investigations/long_term_invariance.py DATA --sets 3 9 --out OUT.json
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

from sfanav.data.dataset import Dataset
from sfanav.data.sources import load_run
from sfanav.experiments.robustness import _config, recipe_for
from sfanav.localization import baselines
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.training import fit_localizer
from sfanav.loopclosure import LoopClosures, align
from sfanav.loopclosure.conditions import correspondences, place_major_order
from sfanav.sfa.network import Rotation

ap = argparse.ArgumentParser()
ap.add_argument("data", type=Path)
ap.add_argument("--config", default="sfanav default")
ap.add_argument("--modes", nargs="+", default=["none", "rotation", "feedback"])
ap.add_argument("--sets", nargs="+", type=int, default=[3, 9])
ap.add_argument("--permutations", nargs="+", type=int, default=[0])
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--out", type=Path, default=None)
a = ap.parse_args()

ds = Dataset(a.data)
conds = sorted(set(ds.conditions.tolist()), key=lambda c: (len(c), c))
make_net, prep, kw = _config(a.config, False)
sets = [load_run(ds.select(condition=c), prep) for c in conds]
places = [correspondences(sets[0][1], s[1]) for s in sets]
rows = None if a.config == "thesis config" else recipe_for().image_rows(
    tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0))))
width = sets[0][0].shape[2]
results = []
for p in a.permutations:
    perm = (np.random.default_rng(a.seed).permutation(len(conds)) if p == 0
            else np.random.default_rng([a.seed, p]).permutation(len(conds)))
    for k in a.sets:
        train, test = perm[:k], perm[k]
        order = place_major_order([places[s] for s in train])
        X = np.concatenate([sets[s][0] for s in train])[order]
        xy = np.concatenate([sets[s][1] for s in train])[order]
        place = np.concatenate([places[s] for s in train])[order]
        X_te, xy_te = sets[test]
        shifts = np.random.default_rng([a.seed, p, k]).integers(0, width, len(X_te))
        X_turn = np.stack([np.roll(x, s, axis=1) for x, s in zip(X_te, shifts)])
        pm = baselines.PerfectMemory().fit(X, xy)
        base = {"perm": p, "sets": k, "test": conds[test],
                "pm": localization_metrics(pm.predict(X_te), xy_te)["med"],
                "pm_turned": localization_metrics(pm.predict(X_turn), xy_te)["med"]}
        for mode in a.modes:
            kw2, closures = dict(kw), None
            if mode == "none":
                rotation = Rotation(width, 1.0)
                kw2["rotation_pooling"] = None
            else:
                rotation = Rotation(5, 1.0)
            if mode == "feedback":  # partner: the previous image in place-major order when it shows the same place
                cur = np.flatnonzero(place[1:] == place[:-1]) + 1
                past = cur - 1
                closures = LoopClosures(past, cur, align(X, past, cur), np.ones(len(cur)), np.zeros(len(cur)))
            t0 = time.perf_counter()
            loc = fit_localizer(make_net(), X, xy, rotation=rotation, rows=rows, progress=False,
                                loop_closures=closures, **kw2)
            t = time.perf_counter() - t0
            r = {**base, "mode": mode, "seconds": t, "closures": 0 if closures is None else len(closures),
                 "med": localization_metrics(loc.predict(X_te), xy_te)["med"],
                 "med_turned": localization_metrics(loc.predict(X_turn), xy_te)["med"]}
            results.append(r)
            print(json.dumps(r), flush=True)
if a.out:
    a.out.write_text(json.dumps(results, indent=1))
