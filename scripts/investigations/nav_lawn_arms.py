"""Navigation on a patchy vs a uniform lawn: the thesis rule on the raw slow
features of three networks, on the first trials of ``sfanav experiment
7.1-open`` / ``7.1-obstacle``.

Networks (trained on the scene's 5000-frame run, cached in ``--cache``):

* ``thesis``: thesis-5.2 on the full 600x60 panorama (the experiment's);
* ``rownorm``: the same with each ground row's mean colour removed from the
  image (a rotation-invariant normalisation of the lawn's colour);
* ``default``: the sfanav default network (horizon band, 350x40 renders).

For each: the position code (RMS of x, y fitted quadratically from s1-s2 and
s1-s8 on a 0.5 m grid) and the thesis rule (eta 1, gamma 0.5) with n = 2 raw
outputs and n = 8 weighted by beta_1/beta_i, every arm from the same odometry noise.

    PYTHONPATH=python python3 scripts/investigations/nav_lawn_arms.py --lawn patchy uniform --networks thesis default --trials 10
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from sfanav import navigation as nav
from sfanav.localization.recipe import CAMERA_ELEVATION
from sfanav.localization import default_network, default_rows
from sfanav.experiments import navigation as E
from sfanav.experiments import navigation_scenes as NS
from sfanav.sfa import load
from sfanav.sfa import Network, Rotation
from sfanav.sim.cameras import PanoramicCamera
from sfanav.sim.robot import Simulator


class RowNorm:
    """Subtracts each ground row's mean colour (over the 360 degrees) from the image."""

    def __init__(self, camera: Any) -> None:
        self.ground = np.asarray(camera.elevations) < 0
        self.identity = False

    def __call__(self, imgs: np.ndarray) -> np.ndarray:
        f = np.asarray(imgs).astype(np.float32)
        f[:, self.ground] = f[:, self.ground] - f[:, self.ground].mean(axis=2, keepdims=True) + 100.0
        return f


def network(kind: str, sc: NS.Scene, lawn: str, cache: Path) -> tuple[Any, Any, Any]:
    """(network, camera, rows) of a kind, trained on the scene's run or loaded."""
    if kind == "default":
        cam, rows = PanoramicCamera(350, 40), default_rows(CAMERA_ELEVATION)
    else:
        cam = sc.camera
        rows = RowNorm(cam) if kind == "rownorm" else None
    path = cache / f"{kind}-{sc.name}-{lawn}.sfanav"
    if path.exists():
        return load(path), cam, rows
    ren = sc.simulator.renderer
    imgs = np.stack([ren.render(cam, p) for p in sc.trajectory.poses])
    net = default_network() if kind == "default" else Network(NS.network_config(False))
    t = time.time()
    net.fit(imgs if rows is None else rows(imgs), rotation=Rotation(5), progress=False)
    print(f"  trained {path.name} in {time.time() - t:.0f} s", flush=True)
    cache.mkdir(parents=True, exist_ok=True)
    net.save(path)
    return net, cam, rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kind", choices=("open", "obstacle"), default="open")
    ap.add_argument("--lawn", nargs="+", choices=("patchy", "uniform"), default=["patchy", "uniform"])
    ap.add_argument("--networks", nargs="+", choices=("thesis", "rownorm", "default"), default=["thesis", "default"])
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--cache", type=Path, default=Path("runs/lawn"))
    a = ap.parse_args()
    print("| network | lawn | position code RMS s1-s2 / s1-s8 (m) | thesis rule n = 2 | thesis rule n = 8 weighted |")
    print("|---|---|---|---|---|")
    for lawn in a.lawn:
        sc = NS.scene(a.kind, 0, lawn=lawn)
        starts, targets, opt, _, _ = E.trials_71(sc, a.kind, 0, a.trials)  # the experiment's first trials
        for kind in a.networks:
            net, cam, rows = network(kind, sc, lawn, a.cache)
            xs, ys, F = NS.grid_features(sc, net, 0.5, False, camera=cam, rows=rows)
            code = " / ".join(f"{NS.position_code_error(xs, ys, F, n):.2f}" for n in (2, 8))
            cells = []
            for n in (2, 8):
                w = None if n == 2 else nav.beta_weights(np.asarray(net.beta_values_, float)[:n], relative=True)
                sim = Simulator(sc.world, sc.camera, sc.robot, seed=0)  # every arm from the same odometry noise
                sim.renderer = sc.simulator.renderer
                navi = nav.Navigator(sim, nav.ImageFeatures(net, sc.simulator.renderer, cam, rows=rows),
                                     nav.ThesisDescent(NS.ETA, NS.GAMMA), n_outputs=n, weights=w,
                                     success_radius=NS.SUCCESS_RADIUS, max_iterations=NS.MAX_ITERATIONS)
                s = nav.evaluate_trials(navi, starts, targets, optimal_lengths=opt, progress=False)
                cells.append(f"{s.success_rate:.2f} / {s.efficiency:.2f}")
            print(f"| {kind} | {lawn} | {code} | {cells[0]} | {cells[1]} |", flush=True)
    print(f"({a.kind}, first {a.trials} trials; success / efficiency)")


if __name__ == "__main__":
    main()
