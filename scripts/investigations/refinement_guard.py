#!/usr/bin/env python3
"""When the pose graph's readout refinement hurts (issue 42): for each training run, the sfanav default's slow
features (cached), the pose graph of training without ground truth (GTSAM, relative-pose closures decorrelated by
place) with --rounds refinement rounds and without the misfit test (``max_misfit_growth=None``: every round the
older tests let through is kept), and for the unrefined map and every refinement round tried: the
map's mean distance to the truth (after a rigid fit; evaluation only), the odometry residual (chi), the area
change, and the closures' misfit (:func:`sfanav.odometry.pose_graph.closure_misfit`: the median squared
Mahalanobis distance of the closures' measured relative positions from the map's), which needs no ground truth.

    PYTHONPATH=python python3 scripts/investigations/refinement_guard.py OUT.json --cache CACHE \\
        --run DATASET:RUN [--run DATASET:RUN ...]

Writes OUT.json after every run (key ``DATASET-folder:RUN``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import sfanav.odometry.pose_graph as pg
from sfanav.localization.error_metrics import align

sys.path.insert(0, str(Path(__file__).parent))
from mower_pose_graph_closures import run_data  # noqa: E402  (the cached features of a run)

DEFAULT_GRAPH = {"solver": "gtsam", "pair_closures": "relative-pose"}
"""What ``train_localizer(supervision="odometry")`` passes to the pose graph by default."""


def map_error(P: np.ndarray, T: np.ndarray) -> float:
    return float(np.hypot(*(align(P, T).apply(P) - T).T).mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--run", action="append", required=True, help="DATASET:RUN")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    res = json.loads(a.out.read_text()) if a.out.exists() else {}
    original = pg.closure_misfit
    for spec in a.run:
        ds, _, run = spec.rpartition(":")
        key = f"{Path(ds).name}:{run}"
        d = run_data(Path(ds), a.cache / Path(ds).name, run)
        X, F, odo, T = d["X"], d["F"], d["odometry"], d["truth"][:, :2]
        seen: list[tuple[np.ndarray, float]] = []

        def spy(positions, headings, closures, keep=None):
            v = original(positions, headings, closures, keep)
            seen.append((np.array(positions, copy=True), v))
            return v

        pg.closure_misfit = spy
        try:
            t0 = time.perf_counter()
            g = pg.fit_pose_graph(X, F, odo, n_outputs=8, refine=a.rounds, max_misfit_growth=None, **DEFAULT_GRAPH)
            secs = time.perf_counter() - t0
        finally:
            pg.closure_misfit = original
        rounds = [{"map error (m)": map_error(P, T), "misfit": v} for P, v in seen]
        for r, t in zip(rounds[1:], g.refine_trace):
            r.update({"chi": t["chi"], "area": t["area"], "offset sigma (m)": t["offset sigma"]})
        res[key] = {"frames": len(X), "rounds kept": g.refined, "seconds": secs, "unrefined": rounds[0],
                    "rounds tried": rounds[1:], "final map error (m)": map_error(g.poses[:, :2], T)}
        print(key, json.dumps(res[key]), flush=True)
        a.out.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
