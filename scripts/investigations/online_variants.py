#!/usr/bin/env python3
"""6.2.2-online (or 6.2.2-seasons-online) with another readout memory or readout policy (issue 45): a memory that
cannot keep every view (the every-layer update's error against a retrain on all the data, measured with a thinned
memory), or every model keeping its first readout kind.

With a memory that keeps every image, ``UpdatePolicy(resolve="all")`` trains every layer again on all the data: it
is the retrain (tested to 1e-9). With ``--memory N`` below the stream's images (6.2.2's ten recordings: 2790), each
update trains again on the N evenly spaced views the memory keeps plus the new recording, so the old recordings
lose views; this runs the experiment's permutations (default all three) with that memory and writes its results JSON beside the
full-memory run's, whose every-layer curve is the retrain on all the data (same permutations, same seed).

    PYTHONPATH=python python3 scripts/investigations/online_variants.py OUT --memory 1000 [--readout keep] [--permutations P]
        [--preset thesis-6.2.2-conditions]   # ~10 min per permutation; OUT/data may hold the simulated scene

``--readout keep``: every model keeps the readout kind its first recording chose and the batch is not told the
recordings (the experiment before updates chose the readout again: the slow features' own join on equal readouts).

Writes OUT/6.2.2-online-memory-N[-readout-kept].json (the experiment's rows, and ``curves``: every permutation's
MED per number of recordings and arm) or the seasons' alike.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from sfanav.experiments.updates import run_online


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--memory", type=int, default=3000, help="views the readout memory keeps (default 3000: all)")
    ap.add_argument("--readout", choices=("auto", "keep"), default="auto",
                    help="keep: every model keeps its first readout kind (the slow features' own join)")
    ap.add_argument("--permutations", type=int, default=None, help="default: the experiment's (3)")
    ap.add_argument("--preset", default="thesis-6.2.2-conditions")
    args = ap.parse_args()
    seasons = args.preset == "thesis-6.2.2-seasons"  # as 6.2.2-seasons-online: one order, spring to winter
    res = run_online(args.out, quick=False, seed=0, progress=True, preset=args.preset, chronological=seasons,
                     permutations=args.permutations, readout_memory=args.memory, readout=args.readout)
    stem = "6.2.2-seasons-online" if seasons else "6.2.2-online"
    tag = f"-memory-{args.memory}" + ("-readout-kept" if args.readout == "keep" else "")
    path = res.write_json(args.out / f"{stem}{tag}.json")
    # and every permutation's curve (the experiment's rows are means over the permutations)
    out = json.loads(path.read_text())
    out["curves"] = {k: v for k, v in res.details["curves"].items()}
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(out, indent=2) + "\n")
    os.replace(tmp, path)
    print(path)


if __name__ == "__main__":
    main()
