"""Runs a subset of the ``gardens`` experiment's configurations (issue 7)
over seeds, on data the full experiment simulated (or simulates now), and
writes ``OUT/gardens-subset.json`` and ``OUT/gardens-subset.md`` (the
ablation table of those configurations, mean over the seeds).

    PYTHONPATH=python python3 scripts/investigations/gardens_subset.py OUT --train "loop closures" [--rows ""] [--seeds 0 1 2]
    PYTHONPATH=python python3 scripts/investigations/gardens_subset.py OUT --default          # the sfanav default only
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from threadpoolctl import threadpool_limits

from sfanav.experiments import gardens as G


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--train", nargs="*", default=[], help="training variants (names of gardens.TRAIN_VARIANTS)")
    ap.add_argument("--rows", nargs="*", default=[], help="row variants (names of gardens.ROW_VARIANTS; '' = all rows)")
    ap.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    ap.add_argument("--scenes", nargs="*", default=["realistic", "control"])
    ap.add_argument("--default", action="store_true", help="also the sfanav default (row 'sfanav default')")
    ap.add_argument("--baselines", action="store_true", help="also perfect memory and the Fourier signature")
    a = ap.parse_args()
    out = Path(a.out)
    rows = {k: G.ROW_VARIANTS[k] for k in a.rows}
    train = {k: G.TRAIN_VARIANTS[k] for k in a.train}
    if rows:
        train[""] = None
    res: dict[str, list] = {s: [] for s in a.scenes}
    with threadpool_limits(limits=1, user_api="blas"):
        for seed in a.seeds:
            for scene in a.scenes:
                preset = "realistic-garden" if scene == "realistic" else "realistic-garden-control"
                r, _ = G.run_scene(out, preset, seed, quick=False, progress=True, control=(scene == "control"),
                                   row_variants=rows, train_variants=train, baselines_too=a.baselines,
                                   firing_maps=(seed == a.seeds[0]), default_too=a.default)
                res[scene].append(r)
    avg = {}
    for scene in a.scenes:
        avg.update(G.average_seeds(res[scene]))
    (out / "gardens-subset.json").write_text(json.dumps(avg, indent=1, default=float))
    (out / "gardens-subset.md").write_text(G.ablation_markdown(avg, a.seeds))
    print(G.ablation_markdown(avg, a.seeds))


if __name__ == "__main__":
    main()
