#!/usr/bin/env python3
"""A linear (or quadratic) trend in the slow features under the default GP readout (GP on the
residuals), on the suite's grid runs: does it stop the GP shrinking inwards at the border?

    PYTHONPATH=python python3 scripts/investigations/suite_readout_trend.py small-dense control dusk inner-sparse
"""
import sys, json, numpy as np
from pathlib import Path
from sfanav.data import Preprocessing, load_run
from sfanav.experiments import gardens_suite as gs
from sfanav.experiments.localization import simulated
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.pipeline import train_localizer
from sfanav.localization.signature_readout import SignatureGPReadout
from sfanav.localization.evaluation import coordinate_range
from sklearn.linear_model import RidgeCV
out = Path("runs/suite")
def met(p, xy):
    r = coordinate_range(xy); mae = np.abs(p - xy).mean(0) / r * 100
    return [round(float(mae[0]),2), round(float(mae[1]),2), round(float(np.hypot(*(p-xy).T).mean()),3)]
for g in sys.argv[1:]:
    ds = simulated(out, f"suite-{g}", gs.gardens().index(g), quick=False, progress=False)
    cam = ds.metadata["camera"]; elev = tuple(cam.get("elevation_deg", (-30.0, 20.0)))
    prep = Preprocessing(int(cam["width"]), int(cam["height"]), False, False)
    tests = {t: load_run(ds.select(run=t), prep) for t in gs.TEST_RUNS}
    X, xy = load_run(ds.select(run="train-grid"), prep)
    loc = train_localizer(X, xy=xy, camera_elevation=elev)
    F, G = loc.features(X), loc.signatures(X)
    m = 12; q = G.shape[1]
    Z = np.hstack([F[:, :m], G])
    feats = {t: np.hstack([loc.features(Xt)[:, :m], loc.signatures(Xt)]) for t, (Xt, _) in tests.items()}
    row = {"default": {t: met(loc.predict(Xt), xyt) for t, (Xt, xyt) in tests.items()}}
    for deg in (1, 2):
        S = F[:, :m]
        B = S if deg == 1 else np.hstack([S, S**2])
        lin = RidgeCV(alphas=np.logspace(-3, 3, 13)).fit(B, xy)
        res = xy - lin.predict(B)
        gp = SignatureGPReadout(m, q).fit(Z, res)
        row[f"trend{deg}"] = {}
        for t, (Xt, xyt) in tests.items():
            St = feats[t][:, :m]; Bt = St if deg == 1 else np.hstack([St, St**2])
            row[f"trend{deg}"][t] = met(lin.predict(Bt) + gp.predict(feats[t]), xyt)
    print(g, json.dumps(row), flush=True)
