"""Training time of the gardens training variants against the thesis
configuration, back to back on the same training run (issue 7's budget:
at most 2x the thesis configuration).

    PYTHONPATH=python python3 scripts/investigations/gardens_timing.py DATASET_DIR [--run train] [--repeats 2] [--only "thesis config" "sfanav default"]

"sfanav default" is the whole default training (sfanav.pipeline.train_localizer:
horizon band, the sfanav-default network, the "auto" readout's
cross-validation and fit); "thesis config" the network plus its quadratic
regression (a least-squares fit, milliseconds).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sfanav.data import Dataset
from sfanav.experiments.gardens import LOOP_CLOSURES, WIDER, WIDEST, network_variant
from sfanav.loopclosure import find_loop_closures, interleave
from sfanav.sfa import Rotation
from sfanav.data import Preprocessing, load_run


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--run", default="train", help="the dataset's training run (suite gardens: train-grid, train-cross)")
    ap.add_argument("--only", nargs="*", default=None, help="configurations to time (default: all)")
    a = ap.parse_args()
    ds = Dataset(a.dataset).select(run=a.run)
    cam = ds.metadata["camera"]
    X, xy = load_run(ds, Preprocessing(int(cam["width"]), int(cam["height"]), False, False), log=lambda m: None)
    elev = tuple(cam.get("elevation_deg", (-30.0, 20.0)))
    odo = ds.odometry[:, :2]
    shape = X.shape[1:]
    times: dict[str, list[float]] = {"thesis config": [], "capacity: wider layers": [], "capacity: widest layers": [],
                                     "loop closures": [], "sfanav default": []}
    if a.only:
        times = {k: v for k, v in times.items() if k in a.only}
    from sfanav.pipeline import train_localizer
    from sfanav.localization import QuadraticRegression

    for _ in range(a.repeats):
        for name in times:
            t0 = time.perf_counter()
            if name == "sfanav default":
                loc = train_localizer(X, xy=xy, camera_elevation=elev)
                times[name].append(time.perf_counter() - t0)
                print(f"{name}: {times[name][-1]:.1f} s (network {loc.info['fit_seconds']:.1f} s, readout "
                      f"{loc.info['readout_seconds']:.1f} s: {loc.describe_readout()})", flush=True)
                continue
            if name == "loop closures":
                lc = find_loop_closures(X, odo, **LOOP_CLOSURES)
                seq = interleave(X, lc)
                net = network_variant(False, shape)
            else:
                seq = X
                opts = {"capacity: wider layers": WIDER, "capacity: widest layers": WIDEST}.get(name, {})
                net = network_variant(False, shape, **opts.get("network", {}))
            net.fit(seq, Rotation(5, 1.0), progress=False)
            if name == "thesis config":
                QuadraticRegression(8).fit(net.transform(X), xy)
            times[name].append(time.perf_counter() - t0)
            print(f"{name}: {times[name][-1]:.1f} s", flush=True)
    base = np.median(times["thesis config"]) if "thesis config" in times else np.nan
    for name, t in times.items():
        print(f"| {name} | {np.median(t):.1f} | {np.median(t) / base:.2f}x |")


if __name__ == "__main__":
    main()
