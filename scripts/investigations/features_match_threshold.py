#!/usr/bin/env python3
"""Experiment 6.1.2 with another distance for a true test match (thesis 6.1.2 counts a match as true within 40 px;
the experiment uses 10 px, as 6.1.1 and the training labels do). Writes OUT/6.1.2-match-<px>px.json.

    PYTHONPATH=python python3 scripts/investigations/features_match_threshold.py runs/f612 --px 40
"""
import argparse
import json
from pathlib import Path

from sfanav.experiments.features import run_612

ap = argparse.ArgumentParser()
ap.add_argument("out", type=Path)
ap.add_argument("--px", type=float, default=40.0)
ap.add_argument("--seed", type=int, default=0)
a = ap.parse_args()
res = run_612(a.out, quick=False, seed=a.seed, progress=True, match_threshold=a.px)
(a.out / f"6.1.2-match-{a.px:g}px.json").write_text(json.dumps({"rows": res.rows, "notes": res.notes}, indent=1,
                                                                default=float))
for r in res.rows:
    print(r["metric"], "|", r["thesis"], "|", r["sfanav"])
