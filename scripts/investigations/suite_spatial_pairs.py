#!/usr/bin/env python3
"""Does training-side help the along-lane axis of grid runs? The sfanav
default against the same with spatial GSFA pairs (built from the training
run's positions) in the top layer, on the suite's grid runs, beside the
peers; MAE per axis (% of the test range), MED (mean error, m) (docs/gardens-suite.md).

    PYTHONPATH=python python3 scripts/investigations/suite_spatial_pairs.py OUT small-dense control ...
"""
import json
import sys
import time
from pathlib import Path

import numpy as np

from sfanav.localization import baselines
from sfanav.data import Preprocessing, load_run
from sfanav.experiments import gardens_suite as gs
from sfanav.experiments.localization import simulated
from sfanav.localization import Localizer
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.localization.evaluation import coordinate_range
from sfanav.sfa import Rotation, spatial_pairs


def metrics(pred, xy):
    r = coordinate_range(xy)
    mae = np.abs(pred - xy).mean(axis=0) / r * 100
    return [round(float(mae[0]), 2), round(float(mae[1]), 2), round(float(np.mean(np.hypot(*(pred - xy).T))), 3)]


def train(X, xy, elev, pairs_spec):
    recipe = recipe_for()
    rows = recipe.image_rows(elev)
    net = default_network()
    Xr = rows(X)
    kw = {}
    if pairs_spec:
        parts = [spatial_pairs(xy, 1.2, 4, min_gap=4, shifts=X.shape[2], shift_step=5, seed=0),
                 spatial_pairs(xy, 0.6, 4, shifts=X.shape[2], shift_step=5, seed=0)]
        kw = {"pairs": tuple(np.concatenate(z) for z in zip(*parts)), "pair_layers": [pairs_spec]}
    t0 = time.perf_counter()
    net.fit(Xr, Rotation(5, 1.0), progress=False, **kw)
    t_net = time.perf_counter() - t0
    loc = Localizer(net, readout=recipe.readout, rows=rows, signature=recipe.signature)
    loc.fit_features(loc.transform_rows(Xr), xy, signatures=loc.signatures(X))
    return loc, t_net, time.perf_counter() - t0


def main(out, names):
    res = {}
    for g in names:
        seed = gs.gardens().index(g)
        ds = simulated(out, f"suite-{g}", seed, quick=False, progress=False)
        cam = ds.metadata["camera"]
        elev = tuple(cam.get("elevation_deg", (-30.0, 20.0)))
        prep = Preprocessing(int(cam["width"]), int(cam["height"]), False, False)
        tests = {t: load_run(ds.select(run=t), prep) for t in gs.TEST_RUNS}
        X, xy = load_run(ds.select(run="train-grid"), prep)
        row = {}
        pm = baselines.PerfectMemory().fit(X, xy)
        fs = baselines.FourierSignature(min(15, X.shape[2] // 2 + 1)).fit(X, xy)
        for name, spec in [("default", None), ("pairs top", len(default_network().config["layers"]))]:
            loc, t_net, t_all = train(X, xy, elev, spec)
            row[name] = {t: metrics(loc.predict(Xt), xyt) for t, (Xt, xyt) in tests.items()}
            row[name]["network s"] = round(t_net, 1)
            row[name]["total s"] = round(t_all, 1)
        row["perfect memory"] = {t: metrics(pm.predict(Xt), xyt) for t, (Xt, xyt) in tests.items()}
        row["Fourier"] = {t: metrics(fs.predict(Xt), xyt) for t, (Xt, xyt) in tests.items()}
        res[g] = row
        print(g, json.dumps(row), flush=True)
        (out / "suite-spatial-pairs.json").write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main(Path(sys.argv[1]), sys.argv[2:])
