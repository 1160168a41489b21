#!/usr/bin/env python3
"""Why the fused track gains less than the single images from the camera-gamma correction (docs/robustness.md,
"The robot's path from bags"): the test walk of ``scripts/robot_bag_path.py --gamma 1.4`` through the streaming
localizer with its odometry (what ``sfanav localize --odometry`` runs, batches of 64), the raw model of that run,
four ways: the raw test run; through gamma 1.4 as it came (``--no-camera-gamma``); the same with the camera's gamma
taken out over the stream (the default); and through the exact inverse gamma, the tracker off (the best any
estimate of the gamma could do). Per way: the single images' and the fused track's MED, the first 30 images'
single MED (the filter's start pose comes from them) and the mean over 15-frame stretches of the single
estimates' mean error vector's length (a bias along a stretch of the walk, which the filter does not average out).

    PYTHONPATH=python python3 scripts/investigations/camera_gamma_fused.py BAGPATH docs/results/investigations/camera-gamma-fused.json

BAGPATH: the --out of ``python3 scripts/robot_bag_path.py --out BAGPATH --seeds 0 --gamma 1.4`` (its sim/,
raw/model.sfa, raw/train.csv, raw/dataset, raw-gamma-1.4/dataset). About 1 min.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from _bagpath import raw_recording

from sfanav.data.camera_gamma import apply_gamma
from sfanav.data.sources import open_images
from sfanav.odometry.streaming import StreamingLocalizer

STRETCH = 15


def stream(loc, images, src, camera_gamma) -> tuple[np.ndarray, np.ndarray]:
    live = StreamingLocalizer(loc, loc.info["ekf_noise"], camera_gamma=camera_gamma, max_pending=100)
    stamps, out = src.stamps_ns, []
    for i in range(0, len(images), 64):
        out += live.push_images(stamps[i:i + 64], images[i:i + 64])
        for j in range(i, min(i + 64, len(images))):
            out += live.push_odometry(stamps[j], src.odometry[j])
    out += live.flush()
    return np.array([e.estimate for e in out]), np.array([e.pose for e in out])[:, :2]


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    root, path = Path(sys.argv[1]), Path(sys.argv[2])
    loc, frame, truth = raw_recording(root)

    def images(d: Path, run: str | None) -> tuple[np.ndarray, object]:
        src = open_images(d, run=run)
        return np.concatenate(list(src.batches(64))), src

    raw, src_raw = images(root / "raw" / "dataset", "test")
    gam, src_gam = images(root / "raw-gamma-1.4" / "dataset", None)
    inverse = np.clip(np.round(apply_gamma(gam, 1 / 1.4)), 0, 255).astype(np.uint8)
    ways = {"raw test run": (raw, src_raw, False), "gamma 1.4, as it came": (gam, src_gam, False),
            "gamma 1.4, the camera's gamma taken out (default)": (gam, src_gam, None),
            "gamma 1.4, the exact inverse gamma": (inverse, src_gam, False)}
    res: dict = {"stretch (frames)": STRETCH, "ways": {}}
    for name, (x, src, cg) in ways.items():
        xy, fused = stream(loc, x, src, cg)
        err = frame.apply(xy) - truth
        n = len(err) // STRETCH * STRETCH
        bias = np.linalg.norm(err[:n].reshape(-1, STRETCH, 2).mean(axis=1), axis=1)
        r = {"MED (m) single images": float(np.linalg.norm(err, axis=1).mean()),
             "MED (m) fused": float(np.linalg.norm(frame.apply(fused) - truth, axis=1).mean()),
             "MED (m) single images, first 30": float(np.linalg.norm(err[:30], axis=1).mean()),
             "stretch bias (m)": float(bias.mean())}
        r["fused over single"] = r["MED (m) fused"] / r["MED (m) single images"]
        res["ways"][name] = r
        print(name, ", ".join(f"{k} {v:.3f}" for k, v in r.items()), flush=True)
    path.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
