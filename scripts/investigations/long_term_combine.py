#!/usr/bin/env python3
"""Experiment 6.2.2's result from runs split over processes (the full run trains 10 permutations x 9 set counts
in both configurations one after the other: over an hour on 2 cores). Reads error curves from
`scripts/investigations/long_term.py` JSON files and/or the per-fit lines of `sfanav experiment 6.2.2` logs
("6.2.2 CONFIG permutation P K sets: MED M m (...), on the held-out last recording H m, perfect memory Q m"), and writes OUT/NAME.json in the
experiment's format with the error-vs-sets plot. The permutations and fits are the same as in one process
(seeded), so the rows are those `sfanav experiment 6.2.2` prints.

    PYTHONPATH=python python3 scripts/investigations/long_term_combine.py OUT --logs runs/exp622/log-6.2.2.txt \
        --json runs/exp622/6.2.2-partial-sfanav_default-p10.json --configs "thesis config" "sfanav default"

--product adds the product rows of a long_term.py run (they are computed on the first permutation's split, so a
one-permutation run of the first configuration gives the rows the full run would).
"""
import argparse
import json
import re
from pathlib import Path

import numpy as np

from sfanav.experiments import ExperimentResult
from sfanav.experiments.robustness import HELD_OUT as HELD, THESIS_622, curve_rows, plot_curves

ap = argparse.ArgumentParser()
ap.add_argument("out", type=Path)
ap.add_argument("--logs", nargs="*", type=Path, default=[])
ap.add_argument("--json", nargs="*", type=Path, default=[])
ap.add_argument("--configs", nargs="+", default=["thesis config", "sfanav default"])
ap.add_argument("--preset", default="thesis-6.2.2-conditions")
ap.add_argument("--permutations", type=int, default=10)
ap.add_argument("--sets", type=int, default=9)
ap.add_argument("--diagonal", type=float, help="the area's diagonal (m): rows above 10x it are withheld and "
                "flagged, as the experiment does (6.2.2's loop: 19.1 m)")
ap.add_argument("--product", type=Path, help="a long_term.py JSON whose product rows (the sfanav default as a user "
                "trains it, and the peers, on the first permutation's split) join the combined result")
a = ap.parse_args()

name = "6.2.2" if a.preset == "thesis-6.2.2-conditions" else "6.2.2-seasons"
curves: dict[str, np.ndarray] = {}
notes = ""
line = re.compile(r"^6\.2\.2(?:-seasons)? (.+?) permutation (\d+) (\d+) sets: MED ([0-9.e+-]+) m \([^)]*\)"
                  r"(?:, on the held-out last recording ([0-9.e+-]+) m)?(?:, perfect memory ([0-9.e+-]+) m)?")
for log in a.logs:
    for text in log.read_text().replace("\r", "\n").splitlines():
        m = line.match(text)
        if not m:
            continue
        config, p, k = m.group(1), int(m.group(2)), int(m.group(3))
        for key, val in ((config, m.group(4)), (config + HELD, m.group(5)), ("perfect memory", m.group(6))):
            if val is None or key.removesuffix(HELD) not in a.configs + ["perfect memory"]:
                continue
            if key == "perfect memory" and config != a.configs[0]:
                continue
            curves.setdefault(key, np.full((a.permutations, a.sets), np.nan))[p, k - 1] = float(val)
for path in a.json:
    d = json.loads(path.read_text())
    notes = notes or d.get("notes", "")  # the first file's (the first configuration's run)
    for key, c in d["curves"].items():
        if key.removesuffix(HELD) in a.configs or (key == "perfect memory" and "perfect memory" not in curves):
            curves[key] = np.asarray(c, dtype=np.float64)
missing = {k: int(np.isnan(v).sum()) for k, v in curves.items() if np.isnan(v).any()}
if missing:
    print(f"missing fits (NaN, left out of the means): {missing}")
order = ([k for c in a.configs for k in (c, c + HELD) if k in curves]
         + ["perfect memory"] * ("perfect memory" in curves))
curves = {k: curves[k] for k in order}
rows = curve_rows(curves, a.preset, diagonal=a.diagonal)
if a.product:
    d = json.loads(a.product.read_text())
    curve = tuple(r["metric"] for r in curve_rows({k: np.asarray(v) for k, v in d["curves"].items()}, a.preset))
    rows += [r for r in d["rows"] if r["metric"] not in curve]
    notes += "\n" + d["notes"].split("\n", 1)[1].replace(
        "; 'thesis configuration': the first configuration's model on that split.", ".") if "\n" in d["notes"] else ""
plot = plot_curves(curves, a.out / f"{name}-error-vs-sets.png", name, THESIS_622[a.preset].get(9))
res = ExperimentResult(name, rows, [str(plot)], notes + " Combined from separate processes "
                       "(scripts/investigations/long_term_combine.py).",
                       details={"curves": {k: v.tolist() for k, v in curves.items()}})
res.write_json(a.out / f"{name}.json")
for r in rows:
    print(r)
for k, v in curves.items():
    print(k, "mean", np.round(np.nanmean(v, axis=0), 3).tolist(), "median", np.round(np.nanmedian(v, axis=0), 3).tolist())
