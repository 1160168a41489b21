#!/usr/bin/env python3
"""The corruption suite's test-only mode with the rows added on 2026-12-07 (docs/robustness.md, "The product path
and the camera's gamma under every corruption"): in the suite's three gardens, every model trained once on the clean
exploration run and tested on the clean and the 19 corrupted test runs, now with the product path (the
ground-truth-free default fused with the test run's odometry) and the supervised default with the camera's gamma
taken out over the stream (``sfanav localize --camera-gamma``). The full experiment (``sfanav experiment
corruptions``, 2 h) also trains every model again on corrupted exploration runs; this runs the test-only half, the
part the new rows are in (about 25 min on 2 cores).

    PYTHONPATH=python python3 scripts/investigations/corruptions_test_only.py OUT docs/results/investigations/corruptions-test-only.json
    PYTHONPATH=python python3 scripts/investigations/corruptions_test_only.py --resummarize JSON   # the summary again

OUT/data holds the simulated gardens (reused when there, as the experiment does). Writes the experiment's tables per
garden ({corruption: {row: MED}}) and their summary ratios. The committed JSON is 2026-12-07's; since 2026-12-08 the
suite itself has these rows, with the camera's gamma taken out by default (its row is now "sfanav default, no camera
gamma"), so a rerun writes the present rows.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from sfanav.data.corruptions import CORRUPTIONS
from sfanav.experiments.corruptions import GARDENS, run_garden, summarize


def summary(table: dict) -> dict:
    """The experiment's summary ratios of one garden's table, their keys without '/' (the docs' paths split on it)."""
    return {m: {k.replace(" / ", " over "): v for k, v in r.items()} for m, r in summarize(table).items()}


def main() -> None:
    if len(sys.argv) == 3 and sys.argv[1] == "--resummarize":  # the summary again from a finished run's tables
        path = Path(sys.argv[2])
        res = json.loads(path.read_text())
        res["summary"] = {g: summary(t) for g, t in res["gardens"].items()}
        path.write_text(json.dumps(res, indent=1) + "\n")
        return
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    out, path = Path(sys.argv[1]), Path(sys.argv[2])
    res: dict = {"seed": 0, "gardens": {}, "summary": {}}
    t0 = time.perf_counter()
    for preset, tr, te in GARDENS:
        r = run_garden(out, preset, tr, te, quick=False, seed=0, progress=True, both_runs=False,
                       corruptions=tuple(CORRUPTIONS))
        res["gardens"][preset] = r["test only"]
        res["summary"][preset] = summary(r["test only"])
        res["training (s)"] = {**res.get("training (s)", {}), preset: r["training (s)"]}
        res["wall (s)"] = time.perf_counter() - t0
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(res, indent=1) + "\n")
        tmp.replace(path)
        print(json.dumps(res["summary"][preset], indent=1), flush=True)


if __name__ == "__main__":
    main()
