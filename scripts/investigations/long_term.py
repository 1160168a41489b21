#!/usr/bin/env python3
"""Experiment 6.2.2 with fewer permutations or one configuration (the full `sfanav experiment 6.2.2` runs
10 permutations of 1..9 training sets in both configurations: hours on 2 cores). Writes OUT/6.2.2-partial.json
and the error-vs-sets plot (docs/loop-closures.md).

    PYTHONPATH=python python3 scripts/investigations/long_term.py OUT --permutations 1 --configs "thesis config"
"""
import argparse
import json
from pathlib import Path

from sfanav.experiments.robustness import run_622

ap = argparse.ArgumentParser()
ap.add_argument("out", type=Path)
ap.add_argument("--permutations", type=int, default=1)
ap.add_argument("--configs", nargs="+", default=["thesis config", "sfanav default"])
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--by", choices=["position", "arc"], default="position",
                help="place correspondences by ground-truth position or by the odometry's arc fraction of the loop")
ap.add_argument("--preset", default="thesis-6.2.2-conditions", help="or thesis-6.2.2-seasons")
ap.add_argument("--max-sets", type=int, default=9)
a = ap.parse_args()
res = run_622(a.out, quick=False, seed=a.seed, progress=True, permutations=a.permutations, configs=tuple(a.configs),
              by=a.by, preset=a.preset, max_sets=a.max_sets)
name = ("6.2.2-partial-" + ("seasons-" if "seasons" in a.preset else "") + ("arc-" if a.by == "arc" else "")
        + "-".join(c.replace(" ", "_").replace(",", "") for c in a.configs) + f"-p{a.permutations}")
(a.out / f"{name}.json").write_text(json.dumps({"rows": res.rows, "notes": res.notes, "curves": res.details["curves"]},
                                               indent=1, default=float))
for r in res.rows:
    print(r)
