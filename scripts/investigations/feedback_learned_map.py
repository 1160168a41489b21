#!/usr/bin/env python3
"""The model without ground truth trained with and without the bag-of-words feedback (whatever the revisit ratio
says): the learned map's error against ground truth (the training positions moved into the world frame by the rigid
fit, for scoring only) beside the test MED, to tell whether feedback costs the map or the readout
(docs/loop-closures.md, "When feedback is used"; 5.2.3).

    sfanav simulate --preset thesis-5.2.3-outdoor --seed 0 --out runs/523
    PYTHONPATH=python python3 scripts/investigations/feedback_learned_map.py 5.2.3 runs/523 OUT.json

A third variant, "feedback, first map": the feedback network's readout fitted to the map the first (no feedback)
network's features learned. SKIP (environment, labels separated by ';') leaves variants out, e.g. SKIP=feedback,
or SKIP='no feedback;feedback, first map' for the second alone.

Adds OUT.json[NAME] = {"no feedback": {...}, "feedback": {...}, "feedback, first map": {...}}, each with the map's MED and 90th percentile (m),
the training run's estimates against ground truth, the test MED (m), the closures and the seconds.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from _feedback_scene import add_entry, feedback_scene
from sfanav.localization.error_metrics import align, localization_metrics
from sfanav.pipeline import train_localizer

# variants to leave out, from the environment, separated by ';' (e.g. SKIP='feedback' when the product rows
# measured it)
SKIP = set(filter(None, os.environ.get("SKIP", "").split(";")))


def main() -> None:
    name, out_path, train, test, elev, found = feedback_scene(__doc__)
    first_map = None  # the no-feedback training's learned positions
    variants = (("no feedback", None, False), ("feedback", found, False), ("feedback, first map", found, True))
    for label, closures, on_first_map in variants:
        if label in SKIP:
            continue
        if on_first_map and first_map is None:
            sys.exit(f"{label!r} needs the 'no feedback' variant's map: do not skip it")
        t0 = time.perf_counter()
        if on_first_map:  # the feedback network's readout fitted to the map the first network's features learned
            positions = first_map
            loc = train_localizer(train.images, xy=first_map, camera_elevation=elev, loop_closures=closures,
                                  feedback="none", filter_noise=False)
        else:
            loc = train_localizer(train.images, odometry=train.odometry, gyro=train.gyro, supervision="odometry",
                                  camera_elevation=elev, loop_closures=closures, feedback="none",
                                  filter_noise=False)
            positions = loc.learned_positions_.positions
            if closures is None:
                first_map = positions
        world = align(positions, train.xy)
        map_err = np.hypot(*(world.apply(positions) - train.xy[:, :2]).T)
        est = np.hypot(*(world.apply(loc.predict(train.images)) - train.xy[:, :2]).T)
        add_entry(out_path, name, {label: {
            "map MED (m)": float(np.median(map_err)), "map p90 (m)": float(np.quantile(map_err, 0.9)),
            "training-run estimates vs GT MED (m)": float(np.median(est)),
            "test MED (m)": localization_metrics(world.apply(loc.predict(test.images)), test.xy)["med"],
            "closures": 0 if closures is None else int(len(closures)), "seconds": time.perf_counter() - t0}},
            merge=True)

if __name__ == "__main__":
    main()
