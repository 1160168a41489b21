#!/usr/bin/env python3
"""The camera-gamma tracker's guard (docs/robustness.md, "The camera's gamma by default"): a correction is kept
only while it brings the images nearer the training views (``CameraGamma.keeps``: the median over the window of
each corrected image's novelty as it came minus corrected). The demo garden's test walk (the raw model of
``scripts/robot_bag_path.py --gamma 1.4``), its 600x60 images as they are and through gamma 0.7 / 1.4, localized
in one batch by ``predict_corrected`` with the camera's images (what ``sfanav localize`` runs): the factor, the
median novelty of the images as they came and corrected, whether the correction was kept, and the MED (m; the
estimates moved into the world frame by the rigid transform fitted on the training run, scoring only).

    PYTHONPATH=python python3 scripts/investigations/camera_gamma_guard.py BAGPATH docs/results/investigations/camera-gamma-guard.json

About 30 s.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from _bagpath import raw_recording

from sfanav.data.camera_gamma import CameraGamma, apply_gamma, predict_corrected
from sfanav.data.corruptions import corrupt
from sfanav.data.preprocessing import Preprocessing, Preprocessor
from sfanav.data.sources import open_images


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    root, path = Path(sys.argv[1]), Path(sys.argv[2])
    loc, frame, truth = raw_recording(root)
    native = np.concatenate(list(open_images(root / "raw" / "dataset", run="test").batches(64)))
    res: dict = {}
    for name in ("clean", "gamma-0.7", "gamma-1.4"):
        cam = native if name == "clean" else corrupt(native, name, seed=1)
        conform = Preprocessor(Preprocessing.of_model(loc), log=lambda *a: None)
        X = conform(cam)
        xy0, nov0 = loc.predict_with_novelty(X)
        probe = CameraGamma.for_localizer(loc)  # the factors and the novelty once corrected, for the table
        f = probe.factors(X, xy0)
        nov1 = loc.predict_with_novelty(conform(apply_gamma(cam, f)))[1] if np.any(f != 1) else nov0
        tracker = CameraGamma.for_localizer(loc)
        xy = predict_corrected(loc, tracker, X, source=cam, conform=conform)
        med = lambda a: float(np.linalg.norm(frame.apply(a) - truth, axis=1).mean())  # noqa: E731
        res[name] = {"factor": tracker.factor_, "median novelty as it came": float(np.median(nov0)),
                     "median novelty corrected": float(np.median(nov1)), "novelty gain": tracker.novelty_gain_,
                     "kept": tracker.n_reverted_ == 0, "MED (m) as it came": med(xy0), "MED (m)": med(xy)}
        print(name, ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in res[name].items()),
              flush=True)
    path.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
