"""Single-image localization error of a 7.1 metric localizer on a grid.

Renders 350x40 panoramas on a 1 m grid over the free area of a 7.1 scene,
each at a random heading, localizes them with the experiment's cached metric
localizer (``OUT/cache/metric-thesis-7.1-<kind>-seed0-*.sfanav``) and prints
the mean, median and 95th percentile of the position error (m).

    PYTHONPATH=python python3 scripts/investigations/nav_localizer_grid.py --kind open --localizer OUT/cache/metric-thesis-7.1-open-seed0-*.sfanav
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


from sfanav.experiments import navigation_scenes as NS
from sfanav.sfa import load
from sfanav.sim.cameras import PanoramicCamera


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kind", choices=("open", "obstacle"), default="open")
    ap.add_argument("--lawn", choices=("patchy", "uniform"), default=None, help="default: the preset's")
    ap.add_argument("--localizer", type=Path, required=True)
    ap.add_argument("--spacing", type=float, default=1.0, help="grid spacing (m)")
    ap.add_argument("--seed", type=int, default=0, help="random headings")
    a = ap.parse_args()
    sc = NS.scene(a.kind, 0, lawn=a.lawn)
    loc = load(a.localizer)
    w, h = sc.area
    xs = np.arange(-w / 2 + a.spacing / 2, w / 2, a.spacing)
    ys = np.arange(-h / 2 + a.spacing / 2, h / 2, a.spacing)
    X, Y = (g.ravel() for g in np.meshgrid(xs, ys))
    ok = np.asarray(sc.world.free(X, Y, sc.robot.size / 2))
    X, Y = X[ok], Y[ok]
    heading = np.random.default_rng(a.seed).uniform(-np.pi, np.pi, len(X))
    cam = PanoramicCamera(350, 40)
    ren = sc.simulator.renderer
    imgs = np.stack([ren.render(cam, (x, y, t)) for x, y, t in zip(X, Y, heading)])
    err = np.hypot(*(loc.predict(imgs) - np.column_stack([X, Y])).T)
    print(f"{sc.name} ({sc.world.ground.dry_fraction and 'patchy' or 'uniform'} lawn), {len(X)} places on a "
          f"{a.spacing:g} m grid, random headings: mean {err.mean():.2f} m, median {np.median(err):.2f} m, "
          f"95th percentile {np.percentile(err, 95):.2f} m")
    near = ~np.asarray(sc.world.free(X, Y, 1.0 + sc.robot.size / 2))  # within 1 m of an obstacle or the border
    regions = {"within 1 m of an obstacle or the border": near, "elsewhere": ~near}
    if a.kind == "obstacle":  # the V of experiments.navigation.trials_71: apex at -0.15 h, arms 0.3 min(w, h) at 45 deg
        apex, arm = -0.15 * h, 0.3 * min(w, h)
        cup = (Y > apex + np.abs(X)) & (Y < apex + arm / np.sqrt(2))
        regions = {"inside the V's cup": cup, "within 1 m of an obstacle or the border, outside the cup": near & ~cup,
                   "elsewhere": ~near & ~cup}
    for name, m in regions.items():
        if m.any():
            print(f"  {name}: {int(m.sum())} places, mean {err[m].mean():.2f} m, median {np.median(err[m]):.2f} m, "
                  f"95th percentile {np.percentile(err[m], 95):.2f} m")


if __name__ == "__main__":
    main()
