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

import json
import sys
import time
from pathlib import Path

from sfanav.data import Dataset
from sfanav.experiments.product_rows import product_runs
from sfanav.localization.error_metrics import align, localization_metrics
from sfanav.localization.recipe import default_network
from sfanav.loopclosure import make_detector
from sfanav.pipeline import train_localizer


def main() -> None:
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    name, root, out_path = sys.argv[1], sys.argv[2], Path(sys.argv[3])
    ds = Dataset(root)
    elev = tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))
    train, (test,) = product_runs(ds, default_network())
    t0 = time.perf_counter()
    found = make_detector("bow").detect(train.images)
    loc = train_localizer(train.images, odometry=train.odometry, gyro=train.gyro, supervision="odometry",
                          camera_elevation=elev, loop_closures=found)
    world = align(loc.predict(train.images), train.xy)
    med = localization_metrics(world.apply(loc.predict(test.images)), test.xy)["med"]
    entry = {"closures": int(len(found)), "no ground truth + feedback MED (m)": med,
             "seconds": time.perf_counter() - t0}
    res = json.loads(out_path.read_text()) if out_path.exists() else {}
    res[name] = entry
    out_path.write_text(json.dumps(res, indent=1, sort_keys=True) + "\n")
    print(name, json.dumps(entry), flush=True)


if __name__ == "__main__":
    main()
