#!/usr/bin/env python3
"""Why the product was 1.8x the peers in 6.2.2 after the DTC readout (issue 44), and what choosing its readout by
recordings does. The product of the experiment's first permutation (nine recordings in light of their own, place-
major, the tenth as test) trained as the experiment trains it, told which recording each image comes from: its
readout is then chosen by leave-one-recording-out CV between the GP of slow features and signature (kernel learned
on all nine, posterior refitted per fold) and the nearest training views by the signature alone
(docs/localization.md, "Several recordings"). Reports the choice, both readouts on the test recording, the CV of
all nine folds, and the nearest-view readout storing the corrupted copies too.

    sfanav simulate --preset thesis-6.2.2-conditions --out DATA      # or an experiment's data/ folder
    PYTHONPATH=python python3 scripts/investigations/readout_recordings_622.py DATA OUT.json   # ~10 min
"""
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _split622 import trained_split  # noqa: E402
from sfanav.localization.error_metrics import localization_metrics  # noqa: E402
from sfanav.localization.readout_selection import group_folds, select_signature_readout  # noqa: E402
from sfanav.localization.signature_knn import SignatureKNNReadout  # noqa: E402
from sfanav.localization.signature_readout import SignatureGPReadout  # noqa: E402

s = trained_split(sys.argv[1])
loc, X, Y, g, X_te, xy_te = s["loc"], s["X"], s["Y"], s["groups"], s["X_te"], s["xy_te"]
q = loc.n_signature_
orig = np.arange(0, len(X), 2)
med = lambda r: localization_metrics(r.predict(X_te), xy_te)["med"]  # noqa: E731
sel = loc.selection_
res = {"samples": len(X), "recordings": len(set(g.tolist())), "training (s)": s["seconds"],
       "readout": loc.describe_readout(), "rule": sel.rule,
       "CV (m)": {str(c.get("kind")) + (f" k={c['k']}" if "k" in c else ""): float(v)
                  for c, v in zip(sel.candidates, sel.scores)},
       "MED (m)": {"the chosen readout": med(loc.regression_)}}
print(res, flush=True)
t = time.perf_counter()
gp_sel = select_signature_readout(X, Y, q, n_outputs=sel.candidates[0]["n_outputs"])  # no recordings: the GP as before
gp = gp_sel.readout
res["MED (m)"]["GP of slow features and signature (the readout before)"] = med(gp)
res["GP fit (s)"] = time.perf_counter() - t
for k in (1, 3):
    res["MED (m)"][f"nearest views by signature, k={k}, originals"] = med(SignatureKNNReadout(q, k).fit(
        X, Y, views=orig))
    res["MED (m)"][f"nearest views by signature, k={k}, originals and copies"] = med(SignatureKNNReadout(q, k).fit(
        X, Y))
print(res, flush=True)
cv = {"GP": [], "nearest view (k=1)": [], "nearest views (k=3)": []}
for tr, te in group_folds(g):
    fold = SignatureGPReadout(gp.n_outputs, q).fit(X[tr], Y[tr], hyperparameters_from=gp)
    local = np.flatnonzero(np.isin(tr, orig))
    for name, r in (("GP", fold), ("nearest view (k=1)", SignatureKNNReadout(q, 1).fit(X[tr], Y[tr], views=local)),
                    ("nearest views (k=3)", SignatureKNNReadout(q, 3).fit(X[tr], Y[tr], views=local))):
        cv[name].append(localization_metrics(r.predict(X[te]), Y[te])["med"])
    print({k: round(v[-1], 4) for k, v in cv.items()}, flush=True)
res["CV, all nine recordings held out in turn: MED (m)"] = cv
res["CV, all nine: mean MED (m)"] = {k: float(np.mean(v)) for k, v in cv.items()}
print(res, flush=True)
Path(sys.argv[2]).write_text(json.dumps(res, indent=1, default=float))
