#!/usr/bin/env python3
"""The camera-gamma study's results in one JSON (docs/robustness.md, "The camera's gamma from the stream"): merges
robustness_candidates.py JSONs (later files win on the same garden|candidate key) and adds, per garden and
candidate trained at several seeds, the clean MED's mean, min and max, every corruption's mean over the seeds, the
mean over the corruptions, and the worst corruption's mean over the clean mean (all thirteen corruptions of
``--extra``; seeds without them are left out of a candidate's means).

    S=scripts/investigations/robustness_candidates.py; ROOT=runs/cand    # the four gardens, as that script says
    PYTHONPATH=python python3 $S $ROOT --extra --candidates gammafix2-0.25,gammafix2-0.25@1,gammafix2-0.25@2,gammafix2-0.25@3 --json a.json
    PYTHONPATH=python python3 $S $ROOT --extra --candidates rungamma-0.25,rungamma-0.25@1,rungamma-0.25@2,rungamma-0.25@3 --json b.json
    PYTHONPATH=python python3 $S $ROOT --extra --candidates rungammaf-0.25,rungammaf-0.25@1,rungammaf-0.25@2,rungammaf-0.25@3 --json c.json
    PYTHONPATH=python python3 $S $ROOT --extra --candidates lowpass-2-flat-0.25,lowpass-2-flat-0.25@1,lowpass-2-flat-0.25@2,lowpass-2-flat-0.25@3 --json d.json
    python3 scripts/investigations/camera_gamma_summary.py OUT.json d.json a.json b.json c.json

(the committed JSON took the default's seeds 1-3 of the demo garden and suite-control from
docs/results/investigations/robustness-bound.json, the same command's, and ran the rest).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from _seeds import seed_groups


def summary(entries: dict) -> dict:
    out = {}
    for key, by_seed in sorted(seed_groups(entries).items()):
        full = {s: m for s, m in by_seed.items() if len(m) >= 14}  # clean and the thirteen corruptions
        if len(full) < 2:
            continue
        names = sorted(set.intersection(*(set(m) for m in full.values())) - {"clean"})
        clean = [full[s]["clean"] for s in sorted(full)]
        mean = {c: float(np.mean([full[s][c] for s in full])) for c in names}
        worst = max(mean, key=mean.get)
        out[key] = {"seeds": sorted(full), "clean": clean, "clean mean": float(np.mean(clean)),
                    "clean min": min(clean), "clean max": max(clean), "mean": mean,
                    "corrupted mean": float(np.mean(list(mean.values()))), "worst corruption": worst,
                    "worst over clean": mean[worst] / float(np.mean(clean))}
    return out


def main() -> None:
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out, ins = Path(sys.argv[1]), sys.argv[2:]
    merged: dict = {}
    for p in ins:
        merged.update({k: v for k, v in json.loads(Path(p).read_text()).items() if k.count("|") == 1})
    res = {"entries": merged, "summary": summary(merged), "sources": [Path(p).name for p in ins]}
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(res, indent=1) + "\n")
    tmp.replace(out)
    for k, v in res["summary"].items():
        print(f"{k:40s} seeds {v['seeds']} clean {v['clean mean']:.3f} ({v['clean min']:.3f}-{v['clean max']:.3f}) "
              f"corrupted {v['corrupted mean']:.3f} worst {v['worst corruption']} x{v['worst over clean']:.2f}")


if __name__ == "__main__":
    main()
