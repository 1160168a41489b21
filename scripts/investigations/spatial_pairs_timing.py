"""Training time of the thesis configuration vs spatial pairs in the top layer (shifted / unshifted),
back to back on realistic-garden seed 0 (docs/gardens.md).

    PYTHONPATH=python python3 scripts/investigations/spatial_pairs_timing.py
"""
import time, numpy as np, os
from sfanav.data import Dataset
from sfanav.experiments.gardens import network_variant
from sfanav.sfa import Rotation, spatial_pairs
from sfanav.data import Preprocessing, load_run
ds = Dataset("/work/gardens-runs/full1/data/realistic-garden-seed0").select(run="train")
cam = ds.metadata["camera"]
X, xy = load_run(ds, Preprocessing(int(cam["width"]), int(cam["height"]), False, False), log=lambda m: None)
parts = [spatial_pairs(xy, 1.2, 4, min_gap=4, shifts=X.shape[2], seed=0), spatial_pairs(xy, 0.6, 4, shifts=X.shape[2], seed=0)]
P = tuple(np.concatenate(z) for z in zip(*parts))
parts5 = [spatial_pairs(xy, 1.2, 4, min_gap=4, shifts=X.shape[2], shift_step=5, seed=0),
          spatial_pairs(xy, 0.6, 4, shifts=X.shape[2], shift_step=5, seed=0)]
P5 = tuple(np.concatenate(z) for z in zip(*parts5))
for name, kw in [("thesis config", {}),                  ("pairs top unshifted (cache)", {"pairs": P[:3], "pair_layers": [4]}), ("pairs top shifted5 (cache)", {"pairs": P5, "pair_layers": [4]}), ("thesis config", {})]:
    net = network_variant(False, X.shape[1:])
    t0 = time.perf_counter(); net.fit(X, Rotation(5, 1.0), progress=False, **kw); t = time.perf_counter() - t0
    print(f"| {name} | {t:.1f} | load {os.getloadavg()[0]:.1f} |", flush=True)
