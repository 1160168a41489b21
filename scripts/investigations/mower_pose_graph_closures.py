"""Issue 42 on the mower survey: the ground-truth-free training map (the
pose graph of ``sfanav train --supervision odometry``) against the truth,
for the hand-written solver, GTSAM with heading-only closures and GTSAM
with relative-pose closures (sfanav.odometry.pair_closures), each without
and with the run's gyro (sfanav.odometry.gyro), on the serpentine and the
crossing runs of the ``mower-survey`` preset.

The slow features are those of the sfanav default (``train_localizer``) fitted
once per run and cached (``CACHE/RUN.npz``); every pose-graph variant reuses
them. Every variant runs without the readout refinement (``refine=0``: the
back ends and closures alone, seconds each) and, for those named by
``--refined``, with the default refinement (two rounds of the GP readout's
offsets, about two minutes each on a busy 2-core machine). The map's error is the mean distance to the truth after a rigid 2-D
alignment (evaluation only; nothing in the map reads the truth). Writes JSON.

    PYTHONPATH=python python3 -m sfanav.app.cli simulate --preset mower-survey --out /work/runs/mower
    PYTHONPATH=python python3 scripts/investigations/mower_pose_graph_closures.py /work/runs/mower \\
        --cache /work/runs/mower_cache --out docs/results/investigations/mower-pose-graph-closures.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from sfanav.localization.error_metrics import align
from sfanav.odometry import fit_pose_graph
from sfanav.odometry.gyro import fuse_gyro

VARIANTS = {"hand-written": {}, "gtsam heading-only": {"solver": "gtsam"},
            "gtsam relative-pose (map distance, the default)": {"solver": "gtsam", "pair_closures": "relative-pose"},
            "gtsam relative-pose (gradient + map distance)": {"solver": "gtsam", "pair_closures": "relative-pose",
                                                              "pair_options": {"use_gradient": True}}}
DEFAULT_VARIANTS = list(VARIANTS)


def errors(P: np.ndarray, T: np.ndarray) -> dict[str, float]:
    e = np.hypot(*(align(P, T).apply(P) - T).T)
    n = len(e)
    return {"mean (m)": float(e.mean()), "median (m)": float(np.median(e)),
            "first sixth mean (m)": float(e[: n // 6].mean()), "last sixth mean (m)": float(e[-(n // 6):].mean())}


def run_data(dataset: Path, cache: Path, run: str) -> dict[str, np.ndarray]:
    path = cache / f"{run}.npz"
    if not path.exists():
        from sfanav.data.dataset import Dataset
        from sfanav.data.preprocessing import Preprocessing
        from sfanav.data.sources import load_run
        from sfanav.pipeline import train_localizer

        ds = Dataset(dataset)
        cam = ds.metadata["camera"]
        prep = Preprocessing(int(cam["width"]), int(cam["height"]), False, False)
        tr = ds.select(run=run)
        X, xy = load_run(tr, prep)
        t0 = time.perf_counter()
        loc = train_localizer(X, xy=xy, camera_elevation=tuple(cam.get("elevation_deg", (-30.0, 20.0))))
        cache.mkdir(parents=True, exist_ok=True)
        np.savez(path, X=X, F=loc.features(X), odometry=tr.odometry, truth=tr.poses, gyro=tr.gyro,
                 fit_seconds=time.perf_counter() - t0)
    return dict(np.load(path))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--runs", nargs="*", default=["serpentine", "crossing"])
    ap.add_argument("--variants", nargs="*", default=DEFAULT_VARIANTS, choices=list(VARIANTS))
    ap.add_argument("--refined", nargs="*",
                    default=["hand-written", "gtsam relative-pose (map distance, the default) + gyro"])
    a = ap.parse_args()
    out: dict = {"command": "scripts/investigations/mower_pose_graph_closures.py", "runs": {}}
    for run in a.runs:
        d = run_data(a.dataset, a.cache, run)
        X, F, odo, T, gyro = d["X"], d["F"], d["odometry"], d["truth"][:, :2], d["gyro"]
        res = {"frames": len(X), "feature fit (s)": float(d["fit_seconds"]) if "fit_seconds" in d else None,
               "dead reckoning": errors(odo[:, :2], T),
               "dead reckoning with the gyro": errors(fuse_gyro(odo, gyro).odometry[:, :2], T)}
        jobs = [(name + (" + gyro" if g is not None else ""), VARIANTS[name], g, 0) for name in a.variants
                for g in (None, gyro)]
        jobs += [(key + ", refined", kw, g, 2) for key, kw, g, _ in list(jobs) if key in a.refined]
        for key, kw, g, refine in jobs:
            t0 = time.perf_counter()
            pg = fit_pose_graph(X, F, odo, n_outputs=8, gyro=g, refine=refine, **kw)
            res[key] = {**errors(pg.poses[:, :2], T), "seconds": round(time.perf_counter() - t0, 2),
                        "pairs": len(pg.pairs), "kept": pg.n_inliers, "refined": pg.refined,
                        "drift (deg/m)": float(np.degrees(pg.drift_rate))}
            print(run, key, {k: round(v, 3) if isinstance(v, float) else v for k, v in res[key].items()},
                  flush=True)
        out["runs"][run] = res
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(out, indent=2) + "\n")  # after every run


if __name__ == "__main__":
    main()
