"""Navigation without ground truth on the 7.1 scenes (issue 19): the metric
arm "metric descent + geodesic field" with the localizer and field of ground
truth beside the same arm trained without it (pose graph on the exploration
run's images and simulated odometry; field over the learned positions), on
the experiments' 50 trials. Only these two arms run (the full experiments
run all of them). Writes ``OUT/nav-no-ground-truth-<kind>.json``.

    PYTHONPATH=python python3 scripts/investigations/nav_no_ground_truth.py OUT [--kinds open obstacle] [--trials 50]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from sfanav import navigation as nav
from sfanav.experiments import navigation as N
from sfanav.experiments import navigation_scenes as NS


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--kinds", nargs="*", default=["open", "obstacle"])
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    for kind in a.kinds:
        t0 = time.perf_counter()
        sc = NS.scene(kind, a.seed)
        starts, targets, optimal, _, _ = N.trials_71(sc, kind, a.seed, a.trials)
        loc, cam = NS.metric_localizer(sc, out, a.seed, progress=True)
        free, free_xy, info = NS.no_ground_truth_localizer(sc, out, a.seed, loc, cam, progress=True)
        arms = [("metric descent + geodesic field", loc, nav.GeodesicField(sc.trajectory.poses[:, :2])),
                ("metric descent + geodesic field, no ground truth", free, nav.GeodesicField(free_xy))]
        res = {"kind": kind, "trials": a.trials, "no ground truth": info, "arms": {}}
        for name, L, field in arms:
            navi = nav.Navigator(sc.fresh_noise(), nav.MetricFeatures(L, sc.simulator.renderer, cam),
                                 nav.MetricDescent(field=field), n_outputs=2, success_radius=NS.SUCCESS_RADIUS,
                                 max_iterations=NS.MAX_ITERATIONS)
            s = nav.evaluate_trials(navi, starts, targets, optimal_lengths=optimal, progress=True, desc=name)
            res["arms"][name] = {"success rate": s.success_rate, "efficiency": s.efficiency,
                                 "mean stops": s.mean_iterations, "reasons": s.reasons}
            print(f"{kind} {name}: success {s.success_rate:.2f}, efficiency {s.efficiency:.3f}, {s.reasons}",
                  flush=True)
        res["wall (s)"] = time.perf_counter() - t0
        (out / f"nav-no-ground-truth-{kind}.json").write_text(json.dumps(res, indent=1, default=float) + "\n")
        print(json.dumps(res, indent=1, default=float))


if __name__ == "__main__":
    main()
