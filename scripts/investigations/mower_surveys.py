#!/usr/bin/env python3
"""The product on a lawn mower's survey patterns (issue 42): for each survey run of the ``mower-survey``
preset (30x30 m garden, the robot facing its direction of travel, frames 1.2 m apart, the mower's odometry
noise, a yaw gyro), the sfanav default trained on that run with ground truth and without (positions learned
from the run's images and odometry, what ``sfanav train --supervision odometry`` runs), tested on the
preset's ``test-walk``; single images and fused with the test walk's odometry, beside the peers
(:func:`sfanav.experiments.product_rows.product_rows`, the experiments' product rows). Writes one JSON
with every pattern's rows, incrementally.

    sfanav simulate --preset mower-survey --out runs/mower            # or reuse a dataset of that preset
    PYTHONPATH=python python3 scripts/investigations/mower_surveys.py runs/mower OUT.json \\
        [--patterns serpentine perimeter-serpentine spiral crossing random] [--closures relative-pose] [--tag T]

Other presets' runs too (``--patterns train --test test`` on a ``thesis-5.1.1-grid`` dataset).

The survey runs' yaw gyro (``gyro_heading``) goes to the pose graph of the training without ground truth, as
``sfanav train`` passes it (the product rows' ``ProductRun.gyro``, since 2026-12-06); ``--no-gyro`` trains without
it, as every entry of docs/results/investigations/mower-surveys.json was.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from sfanav.data import Dataset
from sfanav.experiments.product_rows import product_rows, product_runs
from sfanav.localization.recipe import default_network

PATTERNS = ("serpentine", "perimeter-serpentine", "spiral", "crossing", "random")
SUMMARY = {"no ground truth over ground truth": "MED ratio sfanav default [no ground truth] / [ground truth]",
           "no ground truth over best peer": "MED ratio sfanav default [no ground truth] / best peer",
           "training time no ground truth over ground truth":
               "training time ratio sfanav default [no ground truth] / [ground truth]"}
"""Three ratios of the rows repeated under names without a slash (the docs' result paths split on "/")."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", help="a dataset of the mower-survey preset")
    ap.add_argument("out", help="JSON to write")
    ap.add_argument("--patterns", nargs="*", default=list(PATTERNS))
    ap.add_argument("--test", default="test-walk")
    ap.add_argument("--closures", default=None, choices=("heading", "relative-pose", "min-warping", "auto"),
                    help="the pose graph's closures without ground truth (train_localizer(closures=); default: its "
                         "default: relative-pose from 2026-12-06, auto since 2026-12-07)")
    ap.add_argument("--no-gyro", action="store_true", help="train without the runs' gyro (the entries before "
                    "2026-12-06 15:00)")
    ap.add_argument("--tag", default="", help="appended to each run's key in the JSON (e.g. ' (relative-pose)')")
    a = ap.parse_args()
    ds = Dataset(a.dataset)
    elev = tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))
    out_path = Path(a.out)
    res = json.loads(out_path.read_text()) if out_path.exists() else {}
    for pattern in a.patterns:
        t0 = time.perf_counter()
        train, tests = product_runs(ds, default_network(), train=pattern, tests=(a.test,))
        if a.no_gyro:
            train.gyro = None
        r = product_rows(train, tests, camera_elevation=elev, closures=a.closures)
        rows = {row["metric"]: row["sfanav"] for row in r.rows}
        summary = {k: rows.get(v) for k, v in SUMMARY.items()}
        fused, single = (rows.get(f"MED (m) sfanav default [no ground truth{x}]") for x in (", fused", ""))
        summary["fused over single images, no ground truth"] = fused / single if fused and single else None
        res[pattern + a.tag] = {"frames": len(train.images), "rows": rows, "seconds": time.perf_counter() - t0,
                                "summary": summary}
        sup = rows.get("MED (m) sfanav default [ground truth]")
        ngt = rows.get("MED (m) sfanav default [no ground truth]")
        print(f"{pattern}: supervised {sup:.3f} m, no ground truth {ngt:.3f} m (ratio {ngt / sup:.2f}), "
              f"fused {rows.get('MED (m) sfanav default [no ground truth, fused]', float('nan')):.3f} m, "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
        tmp = out_path.with_suffix(".part")
        tmp.write_text(json.dumps(res, indent=1, default=float) + "\n")
        tmp.replace(out_path)


if __name__ == "__main__":
    main()
