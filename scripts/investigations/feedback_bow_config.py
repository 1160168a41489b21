#!/usr/bin/env python3
"""Experiment 6.2.1-bow in chosen configurations only (the full `sfanav experiment 6.2.1-bow` fits 15 models in
three configurations). Writes OUT/6.2.1-bow-<configs>.json with the rows (docs/experiments.md, 6.2.1-bow).

    PYTHONPATH=python python3 scripts/investigations/feedback_bow_config.py OUT --configs "sfanav default, normalised"
"""
import argparse
import json
from pathlib import Path

from sfanav.experiments.robustness import CONFIGS_621, run_621

ap = argparse.ArgumentParser()
ap.add_argument("out", type=Path)
ap.add_argument("--configs", nargs="+", default=[CONFIGS_621[-1]], choices=CONFIGS_621)
ap.add_argument("--seed", type=int, default=0)
a = ap.parse_args()
a.out.mkdir(parents=True, exist_ok=True)
res = run_621(a.out, "light", quick=False, seed=a.seed, progress=True, detectors=("bow", "fourier"), weighted=True,
              configs=tuple(a.configs))
slug = "-".join(c.replace(",", "").replace(" ", "_") for c in a.configs)
(a.out / f"6.2.1-bow-{slug}.json").write_text(json.dumps({"rows": res.rows, "notes": res.notes}, indent=1,
                                                         default=float))
for r in res.rows:
    print(r)
