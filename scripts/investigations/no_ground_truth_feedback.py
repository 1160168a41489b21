#!/usr/bin/env python3
"""The model without ground truth trained with bag-of-words loop-closure feedback whatever its revisit ratio says
(``train_localizer(loop_closures=...)``), on a dataset's test run: what the recipe's ``feedback="auto"`` leaves
out where the learned map reads the revisits' change too low (docs/loop-closures.md, "When feedback is used").

    sfanav simulate --preset thesis-6.2.1-gain --seed 0 --out runs/gain
    PYTHONPATH=python python3 scripts/investigations/no_ground_truth_feedback.py gain runs/gain OUT.json

Adds one entry NAME to OUT.json: the closures' count, the single-image test MED (m; the estimates moved into the
world frame by the rigid fit on the training run, for scoring only) and the seconds.
"""

from __future__ import annotations

import time

from _feedback_scene import add_entry, scene
from sfanav.localization.error_metrics import align, localization_metrics
from sfanav.loopclosure import make_detector
from sfanav.pipeline import train_localizer


def main() -> None:
    name, out_path, train, test, elev = scene(__doc__)
    t0 = time.perf_counter()
    found = make_detector("bow").detect(train.images)
    loc = train_localizer(train.images, odometry=train.odometry, gyro=train.gyro, supervision="odometry",
                          camera_elevation=elev, loop_closures=found)
    world = align(loc.predict(train.images), train.xy)
    med = localization_metrics(world.apply(loc.predict(test.images)), test.xy)["med"]
    entry = {"closures": int(len(found)), "no ground truth + feedback MED (m)": med,
             "seconds": time.perf_counter() - t0}
    add_entry(out_path, name, entry)


if __name__ == "__main__":
    main()
