#!/usr/bin/env python3
"""Why the product is 2.0x the peers in 6.2.2 (issue 44): its GP readout keeps at most ``max_train`` (3000) training
samples, and it is fitted on each image and its corrupted copy (9 x 279 recordings -> 5022 samples, 60 % kept). The
product of the experiment's first permutation (nine recordings in place-major order, the tenth as test), trained
as ``sfanav train`` trains it; its readout (since 2026-12-07 the DTC posterior over every sample, 3000 inducing samples
chosen farthest-first) against the same kernel's DTC with evenly spaced inducing samples, its exact GP on the 3000
evenly spaced samples alone (the readout before: the rest thinned away) and on all samples.

    sfanav simulate --preset thesis-6.2.2-conditions --out DATA      # or an experiment's data/ folder
    PYTHONPATH=python python3 scripts/investigations/readout_thinning_622.py DATA OUT.json
"""
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _split622 import trained_split  # noqa: E402
import sfanav.localization.signature_readout as sr  # noqa: E402
from sfanav.localization.error_metrics import localization_metrics  # noqa: E402
from sfanav.localization.signature_readout import SignatureGPReadout  # noqa: E402

# the product as before 2026-12-07's choice by recordings: one run, the GP readout
split = trained_split(sys.argv[1], groups=False)
loc, X, Y, Xr_te, xy_te = split["loc"], split["X"], split["Y"], split["X_te"], split["xy_te"]
print("trained", split["seconds"], "s; readout", loc.info.get("readout"), flush=True)
reg = loc.regression_
n, q = reg.n_outputs, reg.n_signature
keep = np.unique(np.linspace(0, len(X) - 1, min(len(X), reg.max_train)).round().astype(int))
res = {"samples": len(X), "kept": len(keep), "readout": loc.info.get("readout"),
       "MED (m)": {"DTC over every sample (the default)": localization_metrics(reg.predict(Xr_te), xy_te)["med"]}}
for name, rows, mt in (("DTC, evenly spaced inducing samples", np.arange(len(X)), reg.max_train),
                       ("kept samples only (the thinning before)", keep, reg.max_train),
                       ("exact GP on every sample", np.arange(len(X)), 10**6)):
    t = time.perf_counter()
    sr._DISTANCE_CACHE_BYTES = 0 if name.startswith("DTC, evenly") else 2**29  # no table: evenly spaced samples
    r = SignatureGPReadout(n, q, max_train=mt, **reg.hyperparameters()).fit(X[rows], Y[rows])
    res["MED (m)"][name] = localization_metrics(r.predict(Xr_te), xy_te)["med"]
    print(name, res["MED (m)"][name], round(time.perf_counter() - t, 1), "s", flush=True)
# the product's own signature (after its photometric normalisation) by the nearest training original: what the
# GP does not exploit here; and the GP with its signature scale fixed smaller than learned
from scipy.spatial.distance import cdist
q0 = X.shape[1] - q
nn = np.argmin(cdist(Xr_te[:, q0:], X[0::2, q0:], "cityblock"), axis=1)
res["MED (m)"]["nearest training original by the signature"] = localization_metrics(Y[0::2][nn], xy_te)["med"]
sr._DISTANCE_CACHE_BYTES = 2**29
for lg in (1.0, 3.0):
    hp = {**reg.hyperparameters(), "signature_scale": lg}
    r = SignatureGPReadout(n, q, **hp).fit(X, Y)
    res["MED (m)"][f"signature scale fixed at {lg:g}"] = localization_metrics(r.predict(Xr_te), xy_te)["med"]
res["signature scale learned"] = float(reg.signature_scale_)
print(res, flush=True)
json.dump(res, open(sys.argv[2], "w"), indent=1)
