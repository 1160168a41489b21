"""Training time of the gardens training variants against the thesis
configuration, back to back on the same training run (issue 7's budget:
at most 2x the thesis configuration).

    PYTHONPATH=python python3 scripts/gardens_timing.py DATASET_DIR [--repeats 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sfanav.dataset import Dataset
from sfanav.experiments.gardens import LOOP_CLOSURES, WIDER, WIDEST, _network
from sfanav.loopclosure import find_loop_closures, interleave
from sfanav.network import Rotation
from sfanav.workflow import Preprocessing, load_run


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset")
    ap.add_argument("--repeats", type=int, default=2)
    a = ap.parse_args()
    ds = Dataset(a.dataset).select(run="train")
    cam = ds.metadata["camera"]
    X, _ = load_run(ds, Preprocessing(int(cam["width"]), int(cam["height"]), False, False), log=lambda m: None)
    odo = ds.odometry[:, :2]
    shape = X.shape[1:]
    times: dict[str, list[float]] = {"thesis config": [], "capacity: wider layers": [], "capacity: widest layers": [],
                                     "loop closures": []}
    for _ in range(a.repeats):
        for name in times:
            t0 = time.perf_counter()
            if name == "loop closures":
                lc = find_loop_closures(X, odo, **LOOP_CLOSURES)
                seq = interleave(X, lc)
                net = _network(False, shape)
            else:
                seq = X
                opts = {"capacity: wider layers": WIDER, "capacity: widest layers": WIDEST}.get(name, {})
                net = _network(False, shape, **opts.get("network", {}))
            net.fit(seq, Rotation(5, 1.0), progress=False)
            times[name].append(time.perf_counter() - t0)
            print(f"{name}: {times[name][-1]:.1f} s", flush=True)
    base = np.median(times["thesis config"])
    for name, t in times.items():
        print(f"| {name} | {np.median(t):.1f} | {np.median(t) / base:.2f}x |")


if __name__ == "__main__":
    main()
