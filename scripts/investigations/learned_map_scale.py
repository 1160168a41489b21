#!/usr/bin/env python3
"""How much of the learned map's error (the model without ground truth) is a scale: the sfanav default trained
without ground truth and without feedback on an experiment's scene, its learned training positions and its test
estimates scored against ground truth after a rigid fit (what the experiments do) and after a similarity fit (the
scale left free), beside the odometry's own scale (its path length over the true path's) and the supervised test
MED (docs/odometry.md, "The learned map's scale").

    sfanav simulate --preset thesis-5.2-indoor-II --seed 0 --out runs/indoor2
    PYTHONPATH=python python3 scripts/investigations/learned_map_scale.py 5.2-indoor-II runs/indoor2 OUT.json

Adds OUT.json[NAME] = {"odometry path over true path", "map MED rigid (m)", "map MED similarity (m)",
"similarity scale", "test MED rigid (m)", "test MED similarity (m)", "map MED affine (m)", "map MED quadratic warp
(m)", "step error median (m)" (consecutive frames' learned step against the true one), "seconds"} (both fits on the training run, for
scoring only).
"""

from __future__ import annotations

import time

import numpy as np

from _feedback_scene import add_entry, scene
from sfanav.localization.error_metrics import align, localization_metrics
from sfanav.pipeline import train_localizer


def main() -> None:
    name, out_path, train, test, elev = scene(__doc__)
    t0 = time.perf_counter()
    loc = train_localizer(train.images, odometry=train.odometry, gyro=train.gyro, supervision="odometry",
                          camera_elevation=elev, feedback="none", filter_noise=False)
    positions = loc.learned_positions_.positions
    est = loc.predict(test.images)
    entry = {"seconds": time.perf_counter() - t0,
             "odometry path over true path": float(np.hypot(*np.diff(train.odometry[:, :2], axis=0).T).sum()
                                                / np.hypot(*np.diff(train.xy[:, :2], axis=0).T).sum())}
    for label, scale in (("rigid", False), ("similarity", True)):
        fit = align(positions, train.xy[:, :2], scale=scale)
        entry[f"map MED {label} (m)"] = float(np.median(np.hypot(*(fit.apply(positions) - train.xy[:, :2]).T)))
        entry[f"test MED {label} (m)"] = localization_metrics(fit.apply(est), test.xy)["med"]
        if scale:
            entry["similarity scale"] = float(fit.scale)
    # smooth distortions beyond a similarity: the map's residual after an affine and a quadratic warp to the truth
    # (least squares on the training run), and how far the consecutive frames' steps disagree (local noise)
    x, y = positions[:, 0] - positions[:, 0].mean(), positions[:, 1] - positions[:, 1].mean()
    for label, cols in (("affine", [np.ones_like(x), x, y]),
                        ("quadratic warp", [np.ones_like(x), x, y, x * x, x * y, y * y])):
        A = np.stack(cols, axis=1)
        coef, *_ = np.linalg.lstsq(A, train.xy[:, :2], rcond=None)
        entry[f"map MED {label} (m)"] = float(np.median(np.hypot(*(A @ coef - train.xy[:, :2]).T)))
    steps = np.diff(positions, axis=0) - np.diff(train.xy[:, :2], axis=0)
    entry["step error median (m)"] = float(np.median(np.hypot(*steps.T)))
    add_entry(out_path, name, entry)


if __name__ == "__main__":
    main()
