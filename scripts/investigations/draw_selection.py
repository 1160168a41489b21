#!/usr/bin/env python3
"""Can the training run tell a good draw of the invariance partners from a poor one? (docs/robustness.md, "The
partners' draw makes the clean precision a lottery".) The sfanav default (robustness "standard") trained on a
garden's clean exploration run at several seeds of the robustness's draw; for each, the readout's blocked
cross-validation MED on the training run (5 folds of 20-frame blocks, the held-out estimates the EKF noise is chosen
on) beside the test walk's MED, clean and under a few corruptions. If the cross-validation ranks the draws as the
test walk does, training several draws and keeping the best by it would take the lottery out at a few trainings'
cost.

    PYTHONPATH=python python3 scripts/investigations/draw_selection.py ROOT OUT.json [--gardens G,..] [--seeds 0,1,2,3]

ROOT holds the gardens as robustness_candidates.py's docstring simulates them (folder per garden). About 30 s a
model on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.data.corruptions import corrupt
from sfanav.data.preprocessing import Preprocessor
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.readout_selection import cross_val_predict
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.localization.training import fit_localizer
from sfanav.sfa import Rotation

GARDENS = {"suite-inner": ("train-grid", "test-walk"), "demo": ("train", "test"),
           "suite-control": ("train-grid", "test-walk"), "suite-dense-trees": ("train-grid", "test-walk")}
CORRUPTIONS = ("jpeg-50", "defocus-2", "exposure-1.5")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--gardens", default=",".join(GARDENS))
    ap.add_argument("--seeds", default="0,1,2,3")
    a = ap.parse_args()
    res = json.loads(a.out.read_text()) if a.out.exists() else {}
    prep = Preprocessing.for_network(default_network())
    for g in a.gardens.split(","):
        conform = Preprocessor(prep, log=lambda *m, **k: None)  # one per garden: it keeps the first images' size
        ds = Dataset(a.root / g)
        cam = ds.metadata["camera"]
        native = Preprocessing(int(cam["width"]), int(cam["height"]), False)
        tr, te = GARDENS[g]
        X0, xy = load_run(ds.select(run=tr), native, log=lambda m: None)
        T0, xyt = load_run(ds.select(run=te), native, log=lambda m: None)
        X = conform(X0)
        tests = {"clean": conform(T0), **{c: conform(corrupt(T0, c, seed=1)) for c in CORRUPTIONS}}
        elev = tuple(cam["elevation_deg"])
        for seed in (int(s) for s in a.seeds.split(",")):
            t0 = time.perf_counter()
            kw = recipe_for(robustness="standard").fit_kwargs(elev)
            loc = fit_localizer(default_network(), X, xy, rotation=Rotation(5, 1.0), progress=False, seed=seed, **kw)
            F = loc.readout_features(loc.features(X), loc.signatures(X) if loc.n_signature_ else None)
            held = cross_val_predict(loc.readout_spec_, F, xy, n_folds=5, block=20)
            cv = float(np.mean(np.linalg.norm(held - xy, axis=1)))
            med = {c: localization_metrics(loc.predict(T), xyt)["med"] for c, T in tests.items()}
            res[f"{g}|{seed}"] = {"cv MED (m)": cv, "MED (m)": med, "seconds": time.perf_counter() - t0}
            print(f"{g:18s} seed {seed}: cv {cv:.3f} test {med['clean']:.3f} "
                  + " ".join(f"{c} {v:.3f}" for c, v in med.items() if c != "clean"), flush=True)
            tmp = a.out.with_name(a.out.name + ".tmp")
            tmp.write_text(json.dumps(res, indent=1) + "\n")
            tmp.replace(a.out)


if __name__ == "__main__":
    main()
