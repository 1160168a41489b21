"""Measures a localizer update on a small simulated garden: the stale model
(trained on the grid run), the model updated with the crossing run
(sfanav.localization.updates), and a retrain of network and readout on both
runs; MED on the garden's test grid and test walk. docs/updates.md quotes it.

    PYTHONPATH=python python scripts/update_localizer_garden.py [DIR] \
        [--json docs/results/investigations/update-localizer-garden.json]
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
from sfanav.localization.training import fit_localizer
from sfanav.localization.updates import LocalizerUpdater, readout_memory_bytes

CONFIG = {"input": {"width": 120, "height": 16, "channels": 3}, "network": {"precision": "double"},
          "layers": [{"rf": [8, 8], "stride": [4, 4], "out": 12}, {"rf": [5, 3], "stride": [3, 1], "out": 12},
                     {"rf": "full", "out": 12}]}
ROT = Rotation(step=4)
READOUTS = {"quadratic": dict(readout="quadratic", n_outputs=8),
            "gp (pooled 8)": dict(readout={"kind": "gp", "n_outputs": 12}, rotation_pooling=8)}


def main(root: Path, json_out: Path | None = None) -> None:
    results = []
    if not root.exists():
        subprocess.run([sys.executable, "-m", "sfanav", "simulate", "--preset", "suite-small-dense", "--out", str(root),
                        "--size", "120x16", "--no-progress"], check=True)
    ds = Dataset(root)
    prep = Preprocessing(120, 16, False, False)
    run = {name: load_run(select_run(ds, name), prep) for name in ("train-grid", "train-cross", "test-grid",
                                                                    "test-walk")}
    (XA, YA), (XB, YB) = run["train-grid"], run["train-cross"]
    print(f"A = train-grid {len(XA)}, B = train-cross {len(XB)}, test-grid {len(run['test-grid'][0])}, "
          f"test-walk {len(run['test-walk'][0])} images, 120x16 RGB")
    for name, kw in READOUTS.items():
        t = time.perf_counter()
        stale = fit_localizer(Network(CONFIG), XA, YA, rotation=ROT, progress=False, readout_memory=3000, **kw)
        t_stale = time.perf_counter() - t
        t = time.perf_counter()
        updated = LocalizerUpdater(stale).partial_fit(XB, YB).localizer_
        t_update = time.perf_counter() - t
        t = time.perf_counter()
        retrain = fit_localizer(Network(CONFIG), np.concatenate([XA, XB]), np.concatenate([YA, YB]), rotation=ROT,
                                progress=False, **kw)
        t_retrain = time.perf_counter() - t
        sizes = readout_memory_bytes(updated)
        print(f"\n{name}: train A {t_stale:.1f} s, update with B {t_update:.1f} s, retrain A+B {t_retrain:.1f} s; "
              f"readout memory {sizes['readout_memory']} B, network statistics {sizes['network_statistics']} B")
        for test in ("test-grid", "test-walk"):
            X, Y = run[test]
            meds = [m.score(X, Y) for m in (stale, updated, retrain)]
            print(f"  {test}: MED stale {meds[0]:.3f} m, updated {meds[1]:.3f} m, retrain {meds[2]:.3f} m")
            results.append({"readout": name, "test": test, "stale": meds[0], "updated": meds[1], "retrain": meds[2],
                            "seconds_train_a": t_stale, "seconds_update": t_update, "seconds_retrain": t_retrain,
                            **{f"bytes_{k}": int(v) for k, v in sizes.items()}})
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps({"command": "scripts/update_localizer_garden.py", "garden": "suite-small-dense "
                                        "seed 0, 120x16 RGB", "rows": results}, indent=1) + "\n")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", nargs="?", type=Path, default=Path("/tmp/sfanav-update-garden"))
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    main(a.root, a.json)
