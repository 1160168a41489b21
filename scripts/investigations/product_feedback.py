#!/usr/bin/env python3
"""The product with loop-closure feedback from the images alone (issue 44, 6.2.1-light): what ``sfanav train
--loop-closures bow`` makes of a run beside ``sfanav train`` without it, with ground truth and (``--no-ground-truth``)
without (positions learned from the run's images and odometry), tested on the dataset's test run beside the peers.

The closures are found as the CLI finds them (``make_detector("bow").detect(images)`` on the network's input images,
no odometry gate); each closure's image is trained with its earlier visit interleaved (thesis 6.2.1), on top of the
default's robustness (its invariance partners are corrupted copies of the earlier visit there).

    sfanav simulate --preset thesis-6.2.1-light --out runs/light      # or the dataset an experiment simulated
    PYTHONPATH=python python3 scripts/investigations/product_feedback.py runs/light OUT.json [--tag T]

Writes one JSON entry per dataset (keyed by its folder name and --tag): the MEDs (m), the closures' count and their
true distance (evaluation only), training times.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from sfanav.data import Dataset
from sfanav.experiments.product_rows import product_runs
from sfanav.localization import baselines
from sfanav.localization.error_metrics import align, localization_metrics
from sfanav.localization.recipe import default_network
from sfanav.loopclosure import make_detector
from sfanav.odometry.fusion import fuse_images
from sfanav.pipeline import train_localizer


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset")
    ap.add_argument("out")
    ap.add_argument("--train", default="train")
    ap.add_argument("--test", default="test")
    ap.add_argument("--tag", default="")
    ap.add_argument("--no-ground-truth", action="store_true", help="also the models without ground truth")
    a = ap.parse_args()
    ds = Dataset(a.dataset)
    elev = tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))
    train, (test,) = product_runs(ds, default_network(), train=a.train, tests=(a.test,))
    out_path = Path(a.out)
    res = json.loads(out_path.read_text()) if out_path.exists() else {}
    key = Path(a.dataset).name + a.tag
    entry: dict = {"MED (m)": {}, "training (s)": {}}

    t0 = time.perf_counter()
    closures = make_detector("bow").detect(train.images)
    entry["closure detection (s)"] = time.perf_counter() - t0
    d = np.hypot(*(train.xy[closures.current] - train.xy[closures.past]).T) if len(closures.past) else np.zeros(0)
    entry["closures"] = {"count": int(len(closures.past)),
                         "mean true distance (m)": float(d.mean()) if len(d) else None,
                         "within 0.3 m": float((d <= 0.3).mean()) if len(d) else None}
    print(f"{key}: {entry['closures']}", flush=True)

    for name, peer in (("perfect memory", baselines.PerfectMemory()), ("Fourier signature", baselines.FourierSignature(
            min(baselines.FourierSignature().n_coefficients, train.images.shape[2] // 2 + 1)))):
        entry["MED (m)"]["peer " + name] = localization_metrics(
            peer.fit(train.images, train.xy).predict(test.images), test.xy)["med"]
    print(f"{key}: peers {entry['MED (m)']}", flush=True)
    sups = ["ground truth"] + (["no ground truth"] if a.no_ground_truth and train.has_odometry else [])
    for sup in sups:
        for fb in ("", " + BoW feedback"):
            t0 = time.perf_counter()
            kw = {"loop_closures": closures} if fb else {}
            if sup == "ground truth":
                loc = train_localizer(train.images, xy=train.xy, odometry=train.odometry, supervision="ground-truth",
                                      camera_elevation=elev, **kw)
                world = None
            else:
                loc = train_localizer(train.images, odometry=train.odometry, gyro=train.gyro, supervision="odometry",
                                      camera_elevation=elev, **kw)
                world = align(loc.predict(train.images), train.xy)  # scoring only
            name = f"sfanav default{fb} [{sup}]"
            entry["training (s)"][name] = time.perf_counter() - t0
            fused = test.has_odometry and "ekf_noise" in loc.info
            if fused:  # the product's path: the measurement noise scaled by each image's novelty
                est, f = fuse_images(loc, test.images, test.odometry)
            else:
                est = loc.predict(test.images)
            scored = world.apply(est) if world is not None else est
            entry["MED (m)"][name] = localization_metrics(scored, test.xy)["med"]
            if fused:
                f = world.apply(f[:, :2]) if world is not None else f[:, :2]
                entry["MED (m)"][f"sfanav default{fb} [{sup}, fused]"] = localization_metrics(f, test.xy)["med"]
            print(f"{key}: {name} {entry['MED (m)'][name]:.3f} m ({entry['training (s)'][name]:.0f} s)", flush=True)
            res[key] = entry
            out_path.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
