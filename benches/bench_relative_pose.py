#!/usr/bin/env python3
"""The relative poses of loop closures (the warping method), as ratios measured in one run.

``sfanav.loopclosure.relative_poses`` scores every warping hypothesis of a
pair of panoramas (baseline directions x distance ratios x relative headings
around the panorama compass's). This times, on P pairs of seeded smooth
350x40 RGB panoramas (``bench_network.make_images``) with the pose graph's
grid (48 directions, 5 ratios, +-20 deg around the compass, the channels'
mean as ``fit_pose_graph(pair_closures="relative-pose")`` calls it):

* the per-pair numpy path (``reference_warping``): the reference, as the
  library ran it before;
* ``relative_poses`` (the scores in the Rust core, pairs in parallel).

    python3 benches/bench_relative_pose.py [--pairs 200] [--repeats 3] [--json out.json]

Prints seconds, the ratio reference / core and the largest difference of the
estimates; quote the ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _benchlib import best  # noqa: E402  (shared with the other benches)
from bench_network import make_images  # noqa: E402  (seeded synthetic panoramas)

N_BEARINGS = 48
RATIOS = (0.05, 0.1, 0.2, 0.3, 0.4)
MAX_TURN_DEG = 20.0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pairs", type=int, default=200, help="pairs of panoramas (default: %(default)s)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--json", help="also write every number here")
    a = p.parse_args(argv)

    from sfanav import get_num_threads
    from sfanav.loopclosure.relative_pose import reference_warping, relative_poses

    n = a.pairs + 1
    X = make_images(0, n, 40, 350, 3, seed=7)
    i = np.arange(a.pairs)
    j = i + 1
    gray = X.mean(axis=-1)
    rp, t_core = best(lambda: relative_poses(gray, i, j, n_bearings=N_BEARINGS, ratios=RATIOS,
                                             max_turn_deg=MAX_TURN_DEG), a.repeats)
    ref, t_ref = best(lambda: reference_warping(gray, i, j, n_bearings=N_BEARINGS, ratios=RATIOS,
                                                max_turn_deg=MAX_TURN_DEG), a.repeats)
    diff = float(np.nanmax(np.abs(np.c_[rp.dtheta, rp.bearing] - ref[:, :2])))
    res = {"pairs": a.pairs, "threads": get_num_threads(), "cpus": os.cpu_count(),
           "seconds numpy reference": t_ref, "seconds core": t_core, "ratio reference / core": t_ref / t_core,
           "max |difference| of heading and bearing (rad)": diff}
    print(f"{a.pairs} pairs of 350x40 panoramas, {N_BEARINGS} directions x {len(RATIOS)} ratios x "
          f"+-{MAX_TURN_DEG:g} deg, {res['threads']} core threads")
    print(f"  numpy, pair by pair : {t_ref:8.3f} s")
    print(f"  relative_poses      : {t_core:8.3f} s   ratio {t_ref / t_core:.1f}x")
    print(f"  largest difference of the estimates: {diff:.2e} rad")
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
