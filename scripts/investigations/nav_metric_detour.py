"""MetricDescent's geodesic-field settings on trials other than the reported ones.

Runs ``MetricDescent`` with and without the exploration run's
``GeodesicField`` and with other ``detour`` / ``slack`` / ``jump`` settings
and field radius on 30
trials of a 7.1 scene drawn with another trial seed (7) than
``sfanav experiment 7.1-*`` (0), using that experiment's cached metric
localizer; every variant starts from the same odometry noise. Prints success, efficiency and mean stops per variant.

    PYTHONPATH=python python3 scripts/investigations/nav_metric_detour.py --kind open --localizer OUT/cache/metric-thesis-7.1-open-seed0-*.sfanav
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


from sfanav import navigation as nav
from sfanav.experiments import navigation as E
from sfanav.experiments import navigation_scenes as NS
from sfanav.sfa import load
from sfanav.sim.cameras import PanoramicCamera


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kind", choices=("open", "obstacle"), default="open")
    ap.add_argument("--localizer", type=Path, required=True, help="the experiment's cached metric localizer")
    ap.add_argument("--trials", type=int, default=30)
    ap.add_argument("--trial-seed", type=int, default=7)
    ap.add_argument("--only", nargs="+", help="run only these variants (names as printed)")
    a = ap.parse_args()
    sc = NS.scene(a.kind, 0)
    loc = load(a.localizer)
    starts, targets, opt, _, _ = E.trials_71(sc, a.kind, a.trial_seed, a.trials)
    field = nav.GeodesicField(sc.trajectory.poses[:, :2])
    wide = nav.GeodesicField(sc.trajectory.poses[:, :2], radius=0.6)
    feats = nav.MetricFeatures(loc, sc.simulator.renderer, PanoramicCamera(350, 40))
    variants = {
        "metric descent": {},
        "+ geodesic field, detour 1.2": {"field": field, "detour": 1.2},
        "+ geodesic field, detour 1.3": {"field": field, "detour": 1.3},
        "+ geodesic field, detour 1.4": {"field": field, "detour": 1.4},
        "+ geodesic field, detour 1.2, slack 1 m": {"field": field, "detour": 1.2, "slack": 1.0},
        "+ geodesic field, detour 1.2, slack 2 m": {"field": field, "detour": 1.2, "slack": 2.0},
        "+ geodesic field, detour 1.2, jump 1.5 m": {"field": field, "detour": 1.2, "jump": 1.5},
        "+ geodesic field, detour 1.2, jump 3 m": {"field": field, "detour": 1.2, "jump": 3.0},
        "+ geodesic field (radius 0.6 m), detour 1.2": {"field": wide, "detour": 1.2},
    }
    for name, kw in variants.items():
        if a.only and name not in a.only:
            continue
        t = time.time()
        sim = sc.fresh_noise()  # the same odometry noise for every variant
        navi = nav.Navigator(sim, feats, nav.MetricDescent(**kw), n_outputs=2,
                             success_radius=NS.SUCCESS_RADIUS, max_iterations=NS.MAX_ITERATIONS)
        s = nav.evaluate_trials(navi, starts, targets, optimal_lengths=opt, progress=False)
        print(f"{a.kind} | {name} | success {s.success_rate:.2f} | efficiency {s.efficiency:.3f} | "
              f"stops {s.mean_iterations:.1f} | {time.time() - t:.0f} s", flush=True)


if __name__ == "__main__":
    main()
