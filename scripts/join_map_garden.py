"""Measures a run without ground truth joined to a trained model's map
(sfanav.odometry.map_joining) on a small simulated garden: run A
(train-grid) trains the model with ground truth; run B (train-cross) comes
with its images and its odometry only, re-integrated from an unknown pose
in a frame of its own with a systematic heading drift and a heading random
walk added. Reports B's joined positions against its truth (LM and iSAM2),
then the MED on the test grid and the test walk of the stale model (A), the
model updated with B at its joined positions, the model updated with B at
its true positions, and a retrain of network and readout on A + B with
ground truth. docs/updates.md quotes it.

    PYTHONPATH=python python scripts/join_map_garden.py [DIR] \
        [--json docs/results/investigations/join-map-garden.json]
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from sfanav import Dataset, Network, Rotation
from sfanav.data.preprocessing import Preprocessing
from sfanav.data.sources import load_run, select_run
from sfanav.localization.error_metrics import align
from sfanav.localization.training import fit_localizer
from sfanav.localization.updates import LocalizerUpdater
from sfanav.odometry.map_joining import join_run
from sfanav.sim import reframed_odometry

CONFIG = {"input": {"width": 120, "height": 16, "channels": 3}, "network": {"precision": "double"},
          "layers": [{"rf": [8, 8], "stride": [4, 4], "out": 12}, {"rf": [5, 3], "stride": [3, 1], "out": 12},
                     {"rf": "full", "out": 12}]}
ROT = Rotation(step=4)
READOUTS = {"quadratic": dict(readout="quadratic", n_outputs=8),
            "gp (pooled 8)": dict(readout={"kind": "gp", "n_outputs": 12}, rotation_pooling=8)}
DRIFTS = (0.5, 2.0)  # deg per m added to the odometry's heading


def disguise(odo, theta=1.1, t=(7.0, -3.0), drift_deg_per_m=0.5, noise_deg=0.2, seed=0):
    """The run's odometry as a second drive reports it (sfanav.sim.reframed_odometry)."""
    return reframed_odometry(odo, (t[0], t[1], theta), drift_deg_per_m=drift_deg_per_m, heading_noise_deg=noise_deg,
                             seed=seed)


def stats(a, b):
    e = np.hypot(*(np.asarray(a) - np.asarray(b)).T)
    return {"median_m": float(np.median(e)), "p90_m": float(np.percentile(e, 90)), "max_m": float(e.max())}


def errors(a, b):
    e = np.hypot(*(np.asarray(a) - np.asarray(b)).T)
    return f"median {np.median(e):.3f} m, p90 {np.percentile(e, 90):.3f} m, max {e.max():.3f} m"


def main(root: Path, json_out: Path | None = None) -> None:
    results = []
    if not root.exists():
        subprocess.run([sys.executable, "-m", "sfanav", "simulate", "--preset", "suite-small-dense", "--out", str(root),
                        "--size", "120x16", "--no-progress"], check=True)
    ds = Dataset(root)
    prep = Preprocessing(120, 16, False, False)
    run, odo = {}, {}
    for name in ("train-grid", "train-cross", "test-grid", "test-walk"):
        d = select_run(ds, name)
        run[name] = load_run(d, prep, progress=False)
        odo[name] = d.odometry
    (XA, YA), (XB, YB) = run["train-grid"], run["train-cross"]
    print(f"A = train-grid {len(XA)} (ground truth), B = train-cross {len(XB)} (odometry only), "
          f"test-grid {len(run['test-grid'][0])}, test-walk {len(run['test-walk'][0])} images, 120x16 RGB")
    for name, kw in READOUTS.items():
        t = time.perf_counter()
        stale = fit_localizer(Network(CONFIG), XA, YA, rotation=ROT, progress=False, readout_memory=3000, **kw)
        print(f"\n{name}: train A {time.perf_counter() - t:.1f} s")
        joined = None
        for drift in DRIFTS if name == "quadratic" else DRIFTS[:1]:
            O = disguise(odo["train-cross"], drift_deg_per_m=drift)
            raw = align(O[:, :2], YB).apply(O[:, :2])
            print(f"  B's odometry, {drift} deg/m drift, best rigidly aligned to the truth: {errors(raw, YB)}")
            results.append({"readout": name, "what": "odometry alone, rigidly aligned to the truth",
                            "drift_deg_per_m": drift, **stats(raw, YB)})
            for solver in ("lm", "isam2"):
                j = join_run(stale, XB, O, solver=solver)
                print(f"  joined ({solver}): {errors(j.positions, YB)}; {j.n_kept} of {len(j.closures)} map "
                      f"closures kept, {j.n_compass} compass closures, {j.seconds:.2f} s")
                results.append({"readout": name, "what": f"joined ({solver})", "drift_deg_per_m": drift,
                                **stats(j.positions, YB), "kept": int(j.n_kept), "closures": len(j.closures),
                                "seconds": j.seconds})
                if solver == "lm" and drift == DRIFTS[0]:
                    joined = j
        t = time.perf_counter()
        updated = LocalizerUpdater(stale).partial_fit(XB, joined.positions).localizer_
        t_up = time.perf_counter() - t
        truth = LocalizerUpdater(stale).partial_fit(XB, YB).localizer_
        t = time.perf_counter()
        retrain = fit_localizer(Network(CONFIG), np.concatenate([XA, XB]), np.concatenate([YA, YB]), rotation=ROT,
                                progress=False, **kw)
        t_re = time.perf_counter() - t
        print(f"  update with the joined B {t_up:.1f} s, retrain A+B {t_re:.1f} s")
        for test in ("test-grid", "test-walk"):
            X, Y = run[test]
            m = [loc.score(X, Y) for loc in (stale, updated, truth, retrain)]
            print(f"  {test}: MED stale {m[0]:.3f} m, updated (B joined) {m[1]:.3f} m, updated (B's truth) "
                  f"{m[2]:.3f} m, retrain A+B with ground truth {m[3]:.3f} m")
            results.append({"readout": name, "what": "MED", "test": test, "stale": m[0], "updated_joined": m[1],
                            "updated_truth": m[2], "retrain": m[3]})
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps({"command": "scripts/join_map_garden.py", "garden": "suite-small-dense seed 0, "
                                        "120x16 RGB", "rows": results}, indent=1) + "\n")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", nargs="?", type=Path, default=Path("/tmp/sfanav-join-garden"))
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    main(a.root, a.json)
