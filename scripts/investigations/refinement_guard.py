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


DEFAULT_GRAPH = {"solver": "gtsam", "pair_closures": "relative-pose"}
"""What ``train_localizer(supervision="odometry")`` passes to the pose graph by default."""


def run_data(dataset: Path, cache: Path, run: str) -> dict[str, np.ndarray]:
    """The run's images, the sfanav default's slow features (its network trained on the run), odometry and
    true poses, cached in ``cache/RUN.npz``."""
    path = cache / f"{run}.npz"
    if not path.exists():
        from sfanav.data.dataset import Dataset
        from sfanav.data.preprocessing import Preprocessing
        from sfanav.data.sources import load_run
        from sfanav.pipeline import train_localizer

        from sfanav.localization.recipe import default_network

        ds = Dataset(dataset)
        cam = ds.metadata["camera"]
        tr = ds.select(run=run)
        X, xy = load_run(tr, Preprocessing.for_network(default_network()))  # as sfanav train resizes them
        loc = train_localizer(X, xy=xy, camera_elevation=tuple(cam.get("elevation_deg", (-30.0, 20.0))))
        cache.mkdir(parents=True, exist_ok=True)
        np.savez(path, X=X, F=loc.features(X), odometry=tr.odometry, truth=tr.poses)
    return dict(np.load(path))


def cached_run(spec: str, cache: Path) -> tuple[str, dict[str, np.ndarray], np.ndarray | None]:
    """``DATASET:RUN``'s key (``DATASET-folder:RUN``), its cached data (:func:`run_data`'s, which must exist)
    and the run's gyro (None without one), for the studies that read this cache."""
    from sfanav.data.dataset import Dataset

    ds, _, run = spec.rpartition(":")
    path = cache / Path(ds).name / f"{run}.npz"
    if not path.exists():
        raise SystemExit(f"{path}: no cache (run refinement_guard.py on {spec} first)")
    return f"{Path(ds).name}:{run}", dict(np.load(path)), Dataset(Path(ds)).select(run=run).gyro


def map_error(P: np.ndarray, T: np.ndarray) -> float:
    return float(np.hypot(*(align(P, T).apply(P) - T).T).mean())


GROWTHS = {"with the misfit test": 1.1, "with the misfit test at 1.0": 1.0}
"""The thresholds compared: the default (``MAX_MISFIT_GROWTH``) and the strict one."""


def outcomes(entry: dict, rounds: int = 2) -> dict[str, float]:
    """The map error (m) the pose graph ends with after at most ``rounds`` refinement rounds, without the misfit
    test (the default before 2026-12-06) and with it at each of :data:`GROWTHS`, from the rounds tried."""
    tried = entry["rounds tried"][: min(rounds, entry["rounds kept"])]  # the older tests refuse a round: it stops
    res = {"without the misfit test": tried[-1]["map error (m)"] if tried else entry["unrefined"]["map error (m)"],
           "rounds kept without": len(tried)}
    for name, growth in GROWTHS.items():
        k = 0
        while k < len(tried) and tried[k]["misfit"] <= growth * entry["unrefined"]["misfit"]:
            k += 1
        res[name] = tried[k - 1]["map error (m)"] if k else entry["unrefined"]["map error (m)"]
        res[f"rounds kept {name}"] = k
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--run", action="append", default=[], help="DATASET:RUN (none: only the summaries again)")
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
    for entry in res.values():
        if isinstance(entry, dict) and "rounds tried" in entry:
            entry["map error (m), two rounds"] = outcomes(entry)
            for n in (1, 2):  # flat, None where the older tests refused an earlier round (for the docs' table)
                r = entry["rounds tried"][n - 1] if len(entry["rounds tried"]) >= n else {}
                entry[f"round {n}"] = {"map error (m)": r.get("map error (m)"), "misfit": r.get("misfit")}
    keys = [k for k, v in res.items() if isinstance(v, dict) and "rounds tried" in v]
    res["mean map error (m), two rounds"] = {
        w: float(np.mean([res[k]["map error (m), two rounds"][w] for k in keys]))
        for w in ("without the misfit test", *GROWTHS)}
    a.out.write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res["mean map error (m), two rounds"]))


if __name__ == "__main__":
    main()
