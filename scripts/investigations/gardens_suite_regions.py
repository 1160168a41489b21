#!/usr/bin/env python3
"""Where the methods of the gardens suite err: per-point errors (written by
gardens_suite_parts.py, OUT/per-garden/*-points.npz) grouped by the point's
distance to the nearest training position and to the area's border, pooled
over every garden, training run and test run; and per garden the regions
where the default's mean error exceeds the best peer's.

    PYTHONPATH=python python3 scripts/investigations/gardens_suite_regions.py OUT"""

import sys
from pathlib import Path

import numpy as np

METHODS = ("sfanav default", "slow features only", "signature only", "perfect memory", "Fourier signature")
TRAINING_BINS = ((0.0, 0.2), (0.2, 0.35), (0.35, 0.6), (0.6, 99.0))
BORDER_BINS = ((-99.0, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, 99.0))


def main(out: Path) -> None:
    cases: list[dict[str, np.ndarray]] = []
    for f in sorted((out / "per-garden").glob("*-points.npz")):
        d = np.load(f)
        keys = {k.rsplit("|", 1)[0] for k in d.files}
        for case in sorted(keys):
            cases.append({"case": case, **{k.rsplit("|", 1)[1]: d[k] for k in d.files if k.startswith(case + "|")}})
    print(f"{len(cases)} garden / training run / test run cases, {sum(len(c['distance to training (m)']) for c in cases)} points")
    for what, bins in (("distance to training (m)", TRAINING_BINS), ("distance to border (m)", BORDER_BINS)):
        print(f"\nmean error (m) by {what}")
        print("| bin | points | " + " | ".join(METHODS) + " | default / best peer |")
        print("|---|---|" + "---|" * (len(METHODS) + 1))
        for lo, hi in bins:
            errs = {m: [] for m in METHODS}
            for c in cases:
                k = (c[what] >= lo) & (c[what] < hi)
                for m in METHODS:
                    errs[m].append(c[f"{m} error (m)"][k])
            e = {m: np.concatenate(v) for m, v in errs.items()}
            n = len(e[METHODS[0]])
            if n == 0:
                continue
            means = {m: float(v.mean()) for m, v in e.items()}
            peer = min(means["perfect memory"], means["Fourier signature"])
            print(f"| {lo:g}-{hi:g} | {n} | " + " | ".join(f"{means[m]:.3f}" for m in METHODS)
                  + f" | {means['sfanav default'] / peer:.2f} |")
    print("\ncases where the default's mean error is above the best peer's in a region (distance to training bins):")
    for c in cases:
        for lo, hi in TRAINING_BINS:
            k = (c["distance to training (m)"] >= lo) & (c["distance to training (m)"] < hi)
            if k.sum() < 5:
                continue
            d = c["sfanav default error (m)"][k].mean()
            p = min(c["perfect memory error (m)"][k].mean(), c["Fourier signature error (m)"][k].mean())
            if d > p:
                print(f"  {c['case']}: {lo:g}-{hi:g} m from training, {k.sum()} points: default {d:.3f}, peer {p:.3f}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
