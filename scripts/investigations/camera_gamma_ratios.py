#!/usr/bin/env python3
"""What the camera-gamma tracker reads on a garden's test walk (docs/robustness.md, "The camera's gamma from the
stream"; sfanav.data.camera_gamma): the running median (last 200 images, from the 50th) of the log ratio of the
training spread to each test image's log spread, its smallest and largest magnitude along the walk, clean and under
corruptions, with the reference either the training run's pooled median spread or the median of the 10 training
views nearest the image (placed at its true position plus 0.2 m of noise, as a localizer's estimate under a
corruption would be), and the spread with and without the 2 px low-pass. A tracker is safe where the clean walk's
ratio stays well inside the dead zone (0.2) and a gamma's well outside.

    PYTHONPATH=python python3 scripts/investigations/camera_gamma_ratios.py ROOT docs/results/investigations/camera-gamma-ratios.json

ROOT holds the gardens as robustness_candidates.py's docstring simulates them. About 3 min.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.data.camera_gamma import log_spread
from sfanav.data.corruptions import corrupt
from sfanav.data.preprocessing import Preprocessor
from sfanav.localization.recipe import default_network

GARDENS = {"demo": ("train", "test"), "suite-inner": ("train-grid", "test-walk"),
           "suite-control": ("train-grid", "test-walk"), "suite-dense-trees": ("train-grid", "test-walk")}
CORRUPTIONS = ("clean", "defocus-2", "motion-blur", "dead-pixels", "noise-10", "jpeg-50", "exposure-1.5",
               "vignetting", "white-balance", "gamma-1.4", "gamma-0.7")


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    root, path = Path(sys.argv[1]), Path(sys.argv[2])
    prep = Preprocessing.for_network(default_network())
    out: dict = {}
    for g, (tr, te) in GARDENS.items():
        conform = Preprocessor(prep, log=lambda *m, **k: None)
        ds = Dataset(root / g)
        cam = ds.metadata["camera"]
        native = Preprocessing(int(cam["width"]), int(cam["height"]), False)
        X, xy = load_run(ds.select(run=tr), native, log=lambda m: None)
        T, xyt = load_run(ds.select(run=te), native, log=lambda m: None)
        X = conform(X)
        placed = xyt + np.random.default_rng(0).normal(0.0, 0.2, xyt.shape)
        _, nn = cKDTree(xy).query(placed, k=10)
        tests = {c: conform(T if c == "clean" else corrupt(T, c, seed=1)) for c in CORRUPTIONS}
        for lp in (0.0, 2.0):
            s_tr = log_spread(X, lowpass=lp)
            refs = {"pooled": np.full(len(xyt), np.median(s_tr)), "place": np.median(s_tr[nn], axis=1)}
            for c, Tc in tests.items():
                s = log_spread(Tc, lowpass=lp)
                for kind, ref in refs.items():
                    lr = np.log(ref / s)
                    run = np.abs([np.median(lr[max(0, i - 199): i + 1]) for i in range(49, len(lr))])
                    out.setdefault(g, {}).setdefault(f"{kind}, low-pass {lp:g}", {})[c] = [float(run.min()),
                                                                                          float(run.max())]
            print(g, f"low-pass {lp:g}", {k: {c: f"{a:.2f}-{b:.2f}" for c, (a, b) in v.items()}
                                         for k, v in out[g].items() if k.endswith(f"{lp:g}")}, flush=True)
    path.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
