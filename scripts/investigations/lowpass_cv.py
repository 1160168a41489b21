#!/usr/bin/env python3
"""Can the training run choose the photometric low-pass width? The sfanav default (ground truth, no feedback)
trained with each width of lowpass_log_contrast (sfanav.data.photometric; the recipe's lowpass_for replaced), on
an experiment's scene: the readout's blocked cross-validation MED on the training run (what a robot can measure)
beside the test run's MED (what it cannot); docs/robustness.md, "A 1 px low-pass in the omnidirectional
experiments" and "The low-pass in degrees of elevation".

    sfanav simulate --preset thesis-6.2.1-dynamic --seed 0 --out runs/dynamic
    PYTHONPATH=python python3 scripts/investigations/lowpass_cv.py 6.2.1-dynamic runs/dynamic OUT.json \\
        [--sigmas 2,1,1.33x2] [--seed 1] [--corruptions jpeg-90,jpeg-50,defocus-2,exposure-1.5,gamma-1.4,vignetting]

Adds OUT.json[NAME][width] = {"cv MED (m)", "test MED (m)", "seconds"[, "corrupted test MED (m)"]} (5 folds of
20-frame blocks, the readout's spec refitted per fold on the clean training features, as the EKF noise's held-out
estimates are made).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import sfanav.data.photometric as photometric
import sfanav.localization.recipe as recipe
from sfanav.data import Dataset
from sfanav.data.corruptions import corrupt
from sfanav.experiments.product_rows import product_runs
from sfanav.localization import cross_val_predict
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.recipe import CAMERA_ELEVATION, default_network
from sfanav.pipeline import train_localizer


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("name")
    ap.add_argument("dataset")
    ap.add_argument("out")
    ap.add_argument("--sigmas", default="2,1", help="widths in pixels, each one number or ROWSxCOLUMNS")
    ap.add_argument("--corruptions", default="",
                    help="comma-separated sfanav.data.corruptions names applied to the (unwarped) test run: the test "
                         "MED under each too, as docs/robustness.md's omnidirectional table measures them")
    ap.add_argument("--seed", type=int, default=0, help="the robustness's draw (train_localizer(seed=)); entries "
                                                        "of seeds other than 0 are keyed WIDTH@SEED")
    a = ap.parse_args()
    ds = Dataset(a.dataset)
    elev = tuple(ds.metadata.get("camera", {}).get("elevation_deg", CAMERA_ELEVATION))
    train, (test,) = product_runs(ds, default_network())
    out_path = Path(a.out)
    for key in a.sigmas.split(","):
        rows, _, cols = key.partition("x")
        sigma = (float(rows), float(cols)) if cols else float(rows)
        recipe.lowpass_for = lambda elevation, height, pair=photometric.lowpass_widths(sigma): pair  # the recipe's
        t0 = time.perf_counter()
        loc = train_localizer(train.images, xy=train.xy, odometry=train.odometry, supervision="ground-truth",
                              camera_elevation=elev, feedback="none", filter_noise=False, seed=a.seed)
        F = loc.features(train.images)
        feats = loc.readout_features(F, loc.signatures(train.images) if loc.n_signature_ else None)
        held = cross_val_predict(loc.readout_spec_, feats, train.xy, n_folds=5, block=20)
        cv = float(np.median(np.hypot(*(held - np.asarray(train.xy)[:, :2]).T)))
        med = localization_metrics(loc.predict(test.images), test.xy)["med"]
        entry = {"cv MED (m)": cv, "test MED (m)": med, "seconds": time.perf_counter() - t0}
        for name in filter(None, a.corruptions.split(",")):
            bad = corrupt(test.images, name, seed=0)
            entry.setdefault("corrupted test MED (m)", {})[name] = localization_metrics(loc.predict(bad),
                                                                                        test.xy)["med"]
        res = json.loads(out_path.read_text()) if out_path.exists() else {}
        res.setdefault(a.name, {})[key if a.seed == 0 else f"{key}@{a.seed}"] = entry
        out_path.write_text(json.dumps(res, indent=1, sort_keys=True) + "\n")
        print(a.name, sigma, json.dumps(entry), flush=True)


if __name__ == "__main__":
    main()
