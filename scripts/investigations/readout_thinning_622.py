#!/usr/bin/env python3
"""Why the product is 2.0x the peers in 6.2.2 (issue 44): its GP readout keeps at most ``max_train`` (3000) training
samples, and it is fitted on each image and its corrupted copy (9 x 279 recordings -> 5022 samples, 60 % kept). The
product of the experiment's first permutation (nine recordings in place-major order, the tenth as test), trained
as ``sfanav train`` trains it, then its readout refitted on the same features with max_train 3000, 6000, 10000.

    sfanav experiment 6.2.2 --out runs/exp622      # or any run that simulated the preset (its data/ folder)
    PYTHONPATH=python python3 scripts/investigations/readout_thinning_622.py runs/exp622/data/thesis-6.2.2-conditions-seed0 OUT.json
"""
import json
import sys
import time
import numpy as np
from sfanav.data import Dataset
from sfanav.data.preprocessing import Preprocessing
from sfanav.data.sources import load_run
from sfanav.experiments.product_rows import configuration as product_configuration
from sfanav.loopclosure.conditions import correspondences, place_major_order
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.localizer import Localizer
import sfanav.localization.signature_readout as sr
from sfanav.pipeline import train_localizer

ds = Dataset(sys.argv[1])
conds = sorted(set(ds.conditions.tolist()), key=lambda c: int(c.lstrip("c")) if c.lstrip("c").isdigit() else c)
perm = np.random.default_rng(0).permutation(len(conds))
train, test = perm[:9], perm[9]
make_net, recipe = product_configuration(False)
prep = Preprocessing.for_network(make_net())
recs = [load_run(ds.select(condition=c), prep) for c in conds]
places = [correspondences(recs[0][1], r[1]) for r in recs]
order = place_major_order([places[s] for s in train])
X = np.concatenate([recs[s][0] for s in train])[order]
xy = np.concatenate([recs[s][1] for s in train])[order]
X_te, xy_te = recs[test]
elev = tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))
seen = {}
orig = Localizer.fit_features
def spy(self, *a, **k):
    seen["args"], seen["kw"] = a, k
    return orig(self, *a, **k)
Localizer.fit_features = spy
t = time.perf_counter()
loc = train_localizer(X, xy=xy, supervision="ground-truth", network=make_net(), recipe=recipe, camera_elevation=elev, seed=0)
Localizer.fit_features = orig
print("trained", time.perf_counter() - t, "s; readout", loc.info.get("readout"), flush=True)
res = {"default": localization_metrics(loc.predict(X_te), xy_te)["med"]}
print(res, flush=True)
d = list(sr.SignatureGPReadout.__init__.__defaults__)
for mt in (3000, 6000, 10000):
    d[3] = mt
    sr.SignatureGPReadout.__init__.__defaults__ = tuple(d)
    t = time.perf_counter()
    loc.fit_features(*seen["args"], **seen["kw"])
    res[f"max_train {mt}"] = localization_metrics(loc.predict(X_te), xy_te)["med"]
    print(mt, res[f"max_train {mt}"], time.perf_counter() - t, "s", flush=True)
json.dump(res, open(sys.argv[2], "w"), indent=1)
