#!/usr/bin/env python3
"""Why the product's fused track pays for the robustness on flawless images (docs/robustness.md, "The corruption
suite"; product_clean_cost.py measures the price): in a garden of the corruption suite, the ground-truth-free
default trained with robustness "standard" and "none" (seed 0), the clean test walk's single-image estimates of
each fused with the test odometry under each model's filter noise (with and without the novelty scaling), and the
estimates' error structure: the mean error, the mean over 15-frame stretches of the mean error vector's length
(a bias the filter cannot average out) and the errors' autocorrelation at lags 1, 5 and 15 frames. MED (m) in the
world frame by the rigid transform fitted on the training run (scoring only).

    PYTHONPATH=python python3 scripts/investigations/product_clean_cost_why.py OUT docs/results/investigations/product-clean-cost-why.json demo suite-inner

OUT: the suite's --out (OUT/data holds its gardens). About 2.5 min a garden.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from _suite_garden import load_garden

from sfanav.localization.error_metrics import align
from sfanav.odometry.fusion import fuse

STRETCH = 15
LAGS = (1, 5, 15)


def main() -> None:
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    out, path = Path(sys.argv[1]), Path(sys.argv[2])
    res: dict = json.loads(path.read_text()) if path.exists() else {}
    for g in sys.argv[3:]:
        garden = load_garden(out, g)
        T, xyt, test = garden.conform(garden.native[1]), garden.xyt, garden.test
        X, xy = garden.conform(garden.native[0]), garden.xy
        models = {rb: garden.product(rb) for rb in ("standard", "none")}
        models = {rb: (loc, align(loc.predict(X), xy)) for rb, loc in models.items()}
        r: dict = {}
        for rb, (loc, frame) in models.items():
            est, nov = loc.predict_with_novelty(T)
            err = frame.apply(est) - xyt
            n = len(err) // STRETCH * STRETCH
            e = err - err.mean(axis=0)
            r[rb] = {"MED (m) single images": float(np.linalg.norm(err, axis=1).mean()),
                     "stretch bias (m)": float(np.linalg.norm(err[:n].reshape(-1, STRETCH, 2).mean(axis=1),
                                                              axis=1).mean()),
                     "autocorrelation": {str(k): float((e[:-k] * e[k:]).sum() / (e * e).sum()) for k in LAGS},
                     "median novelty": float(np.median(nov)), "filter noise": models[rb][0].info["ekf_noise"]}
            for nrb in models:
                noise = models[nrb][0].info["ekf_noise"]
                for tag, kw in (("", {"novelty": nov}), (", no novelty scaling", {})):
                    fused = fuse(test.odometry, est, noise, **kw)
                    r[rb][f"MED (m) fused, {nrb}'s noise{tag}"] = float(
                        np.linalg.norm(frame.apply(fused[:, :2]) - xyt, axis=1).mean())
            print(g, rb, json.dumps(r[rb]), flush=True)
        res[g] = r
        path.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
