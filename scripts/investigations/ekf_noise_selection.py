#!/usr/bin/env python3
"""How the EKF noise of a model trained without ground truth should be
chosen: fused MED of test walks under several selection rules, beside the
single images (docs/odometry.md, "Choosing the filter's noise").

For each garden: the sfanav default trained without ground truth
(sfanav.pipeline.train_localizer on the training run's images and
odometry; cached under --cache), its single-image estimates of each test
run with odometry, and the fused track with the noise chosen by

* ``current``: the library's rule (grid search on the training run's
  held-out estimates, the fused track nearest the learned map);
* ``floor``: the same grid without the smallest odometry noises;
* ``nll``: the innovations' likelihood on the training run (no reference);
* ``oracle``: the best noise for the test run itself, from its ground truth
  (a bound, not a rule).

    PYTHONPATH=python python3 scripts/investigations/ekf_noise_selection.py /work/runs/cand \\
        --cache /work/runs/ekfsel --json docs/results/investigations/ekf-noise-selection.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from sfanav.data import Dataset
from sfanav.data.preprocessing import Preprocessing
from sfanav.data.sources import load_run
from sfanav.localization.error_metrics import align
from sfanav.localization.readout_selection import cross_val_predict
from sfanav.localization.recipe import CAMERA_ELEVATION, default_network
from sfanav.odometry.fusion import TURN_NOISE, fuse, noise_from_run
from sfanav.pipeline import train_localizer
from sfanav.sfa import modelfile

GARDENS = {"demo": ("train", ["test"]), "suite-inner": ("train-grid", ["test-walk"]),
           "suite-control": ("train-grid", ["test-walk"]), "suite-dense-trees": ("train-grid", ["test-walk"])}
FLOOR = {"distance_noise": (0.01, 0.03, 0.1), "heading_noise": (0.01, 0.03, 0.1)}
quiet = lambda *a, **k: None  # noqa: E731


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", type=Path)
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--gardens", default=",".join(GARDENS))
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    prep = Preprocessing.for_network(default_network())
    out = []
    for g in args.gardens.split(","):
        train_run, tests = GARDENS[g]
        ds = Dataset(args.root / g)
        tr = ds.select(run=train_run)
        X, xy = load_run(tr, prep, log=quiet)
        model = args.cache / f"{g}.sfa"
        if model.exists():
            loc = modelfile.load(model)
        else:
            t0 = time.time()
            elev = tuple(ds.metadata.get("camera", {}).get("elevation_deg", CAMERA_ELEVATION))
            loc = train_localizer(X, odometry=tr.odometry, supervision="odometry", camera_elevation=elev, prep=prep)
            loc.save(model)
            print(f"{g}: trained in {time.time() - t0:.0f} s")
        world = align(loc.predict(X), xy)
        feats = loc.readout_features(loc.features(X), loc.signatures(X) if loc.n_signature_ else None)
        n = len(X)
        block = max(1, min(20, n // 10))
        held = cross_val_predict(loc.readout_spec_, feats, loc.training_positions_, n_folds=5, block=block)
        rules = {"current": noise_from_run(tr.odometry, held, reference=loc.training_positions_),  # the library's rule
                 "floor": noise_from_run(tr.odometry, held, reference=loc.training_positions_, **FLOOR),
                 "nll": noise_from_run(tr.odometry, held)}
        for t in tests:
            te = ds.select(run=t)
            Xt, xyt = load_run(te, prep, log=quiet)
            Z = loc.predict(Xt)
            err = lambda P: float(np.median(np.hypot(*(world.apply(P[:, :2]) - xyt).T)))  # noqa: E731
            row = {"garden": g, "train": train_run, "test": t, "single": err(Z)}
            for name, noise in rules.items():
                row[name] = err(fuse(te.odometry, Z, noise))
                row[name + " noise"] = noise
            # oracle: the best of a wider grid for this test run, scored against its truth (a bound)
            best = None
            for dn in (0.003, 0.01, 0.03, 0.1):
                for hn in (0.003, 0.01, 0.03, 0.1):
                    for mn in (0.05, 0.1, 0.2, 0.4):
                        v = err(fuse(te.odometry, Z, {"distance_noise": dn, "heading_noise": hn,
                                                      "measurement_noise": mn, "turn_noise": TURN_NOISE}))
                        if best is None or v < best[0]:
                            best = (v, {"distance_noise": dn, "heading_noise": hn, "measurement_noise": mn})
            row["oracle"], row["oracle noise"] = best
            print(json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()
                              if "noise" not in k}), flush=True)
            out.append(row)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"command": "scripts/investigations/ekf_noise_selection.py", "rows": out},
                                        indent=1) + "\n")


if __name__ == "__main__":
    main()
