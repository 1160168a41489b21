#!/usr/bin/env python3
"""The camera-gamma guard in suite-inner (docs/robustness.md, "The corruption suite"): the corruption suite's
supervised default of that garden (seed 0, trained as ``sfanav experiment corruptions`` trains it), its test walk
clean and through gamma 0.7 / 1.4 (the suite's draw), localized as ``sfanav localize`` does: the tracker's median
log ratio, factor, novelty gain over the window (``CameraGamma.keeps``: above 0 keeps the correction), the images
it localized as they came, and the MED (m), also as they came and corrected without the guard.

    PYTHONPATH=python python3 scripts/investigations/camera_gamma_guard_suite.py DATA docs/results/investigations/camera-gamma-guard-suite.json

DATA: the suite's simulated garden (``sfanav experiment corruptions --out OUT`` writes OUT/data/suite-inner-seed0).
About 1 min.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from sfanav.data import Dataset
from sfanav.data.camera_gamma import CameraGamma, apply_gamma, predict_corrected
from sfanav.data.corruptions import corrupt
from sfanav.data.preprocessing import Preprocessing, Preprocessor
from sfanav.data.sources import load_run
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.pipeline import train_localizer


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    ds, path = Dataset(sys.argv[1]), Path(sys.argv[2])
    cam = ds.metadata["camera"]
    native = Preprocessing(int(cam["width"]), int(cam["height"]), False)
    X, xy = load_run(ds.select(run="train-grid"), native)
    T, xyt = load_run(ds.select(run="test-walk"), native)
    conform = Preprocessor(Preprocessing.for_network(default_network()), log=lambda *a, **k: None)
    loc = train_localizer(conform(X), xy=xy, network=default_network(), recipe=recipe_for(),
                          camera_elevation=tuple(cam.get("elevation_deg", (-30.0, 20.0))), seed=0)
    res = {}
    for c in ("clean", "gamma-0.7", "gamma-1.4"):
        N = T if c == "clean" else corrupt(T, c, seed=1)  # the suite's test-run draw (seed + 1)
        X_te = conform(N)
        tracker = CameraGamma.for_localizer(loc)
        est = predict_corrected(loc, tracker, X_te, source=N, conform=conform)
        f = CameraGamma.for_localizer(loc).factors(X_te, loc.predict(X_te))  # the correction without the guard
        forced = loc.predict(conform(apply_gamma(N, f))) if np.any(f != 1.0) else loc.predict(X_te)
        res[c] = {"log ratio": tracker.log_ratio_, "factor": tracker.factor_, "novelty gain": tracker.novelty_gain_,
                  "localized as they came": tracker.n_reverted_,
                  "MED (m)": float(np.linalg.norm(est - xyt, axis=1).mean()),
                  "MED (m) as they came": float(np.linalg.norm(loc.predict(X_te) - xyt, axis=1).mean()),
                  "MED (m) corrected, without the guard": float(np.linalg.norm(forced - xyt, axis=1).mean())}
        print(c, res[c], flush=True)
    path.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
