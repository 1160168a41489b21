#!/usr/bin/env python3
"""The three loop-closure detectors on a 6.2.1 training run (docs/loop-closures.md): candidates' average
precision at 0.1 m, accepted closures, their precision and mean true distance, and the BoW acceptance
threshold's trade-off; plots of the closures.

    sfanav simulate --preset thesis-6.2.1-gain --out runs/621-gain --seed 0   # measured on the global-gain scene
    PYTHONPATH=python python3 scripts/investigations/loop_closure_detectors.py runs/621-gain
"""
import sys
import time
from pathlib import Path

import numpy as np

from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.loopclosure import BagOfWordsDetector, FourierDetector, GroundTruthDetector, closure_precision_recall, plot_closures

root = Path(sys.argv[1])
ds = Dataset(root).select(run="train")
X, xy = load_run(ds, Preprocessing(600, 60, False), log=lambda m: None)
print(f"{len(X)} training panoramas 600x60 of {root}")
for name, det in (("ground truth", GroundTruthDetector(max_distance=0.1, min_gap=50)),
                  ("Fourier signature", FourierDetector(min_gap=50)), ("bag of words", BagOfWordsDetector(min_gap=50))):
    t0 = time.perf_counter()
    cand = det.candidates(X, positions=xy)
    acc = cand.select(det.accepted_)
    qc, qa = closure_precision_recall(cand, xy), closure_precision_recall(acc, xy)
    print(f"| {name} | {qc.average_precision:.2f} | {qa.n} | {qa.mean_distance:.3f} | {qa.precision:.2f} | "
          f"{qa.recall:.2f} | {time.perf_counter() - t0:.0f} s |", flush=True)
    plot_closures(xy, acc, root / f"closures-{name.replace(' ', '-')}.png", title=f"{name}: {len(acc)} closures")
    if isinstance(det, BagOfWordsDetector):
        ratio = 1 / cand.score - 1
        for a in (0.3, 0.5, 0.7, 1.0, 2.0):
            q = closure_precision_recall(cand.select(ratio <= a), xy)
            print(f"  accept {a}: {q.n} closures, mean distance {q.mean_distance:.3f} m, precision {q.precision:.2f}, "
                  f"recall {q.recall:.2f}")
