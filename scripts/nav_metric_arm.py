"""Navigation in the learned metric space (beyond the thesis; docs/navigation.md).

The sfanav default network (horizon band, Table 5.1 with wider layers, 12
outputs; 350x40 RGB panoramas rendered at the robot's centre along the
scene's 5000-frame training run) and the GP readout of its outputs to the
run's positions make a :class:`sfanav.Localizer`; the robot's two cameras
are localized at every stop (:class:`sfanav.navigation.MetricFeatures`).
Arms, on the same trials as ``sfanav experiment 7.1-<kind>``:

* thesis rule and robust descent on the Euclidean distance between the
  cameras' and the target's estimated positions (n = 2);
* metric descent (:class:`sfanav.navigation.MetricDescent`) on the same
  cost, without and with the exploration run's geodesic field
  (:class:`sfanav.navigation.GeodesicField`).

    PYTHONPATH=python python3 scripts/nav_metric_arm.py --kind open --out DIR [--trials 50]

Writes DIR/nav-metric-<kind>.json and trajectory plots; the network is cached
in DIR/cache.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import sfanav
from sfanav import navigation as nav
from sfanav.defaults import default_network, default_rows
from sfanav.experiments import navigation as EN
from sfanav.modelfile import load
from sfanav.network import Rotation
from sfanav.sim.render import PanoramicCamera


def trials(sc: EN.Scene, kind: str, n: int):
    rng = EN._rng(0, 71, 0 if kind == "open" else 1)
    free = EN._free(sc)
    w, h = sc.area
    if kind == "open":
        s, t = nav.sample_trials(n, sc.area, free=free, min_distance=15.0, margin=0.4, rng=rng)
        return s, t, None
    apex_y, arm = -0.15 * h, 0.3 * min(w, h)
    target = np.array([0.0, apex_y + 0.45 * arm])

    def below(x: float, y: float) -> bool:
        return y < 0 and y < apex_y + abs(x) - 0.3

    s, t = nav.sample_trials(n, sc.area, free=free, min_distance=4.0, margin=0.4, target=target, start_region=below,
                             rng=rng)
    grid = nav.occupancy_grid(sc.area, lambda x, y: sc.world.free(x, y, sc.robot.size / 2), resolution=0.1,
                              margin=sc.robot.size / 2)
    return s, t, np.array([nav.shortest_path(grid, a, b)[1] for a, b in zip(s, t)])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--kind", choices=("open", "obstacle"), required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    out = a.out
    (out / "cache").mkdir(parents=True, exist_ok=True)
    sc = EN.scene(a.kind, a.seed)
    cam = PanoramicCamera(350, 40)
    rows = default_rows((-30.0, 20.0))
    r = sc.simulator.renderer
    P = sc.trajectory.poses
    t0 = time.perf_counter()
    imgs = np.stack([r.render(cam, p) for p in P])
    cache = out / "cache" / f"default-{sc.name}-seed{a.seed}.sfanav"
    if cache.exists():
        net = load(cache)
    else:
        net = default_network()
        net.fit(rows(imgs), rotation=Rotation(5), progress=False)
        net.save(cache)
    loc = sfanav.Localizer(net, readout={"kind": "gp", "n_outputs": 12}, rows=rows).fit(imgs, P[:, :2])
    field = nav.GeodesicField(P[:, :2])
    train_s = time.perf_counter() - t0
    feats = nav.MetricFeatures(loc, r, cam)
    starts, targets, optimal = trials(sc, a.kind, a.trials)
    arms = [("thesis rule, metric cost", nav.ThesisDescent(EN.ETA, EN.GAMMA)),
            ("robust descent, metric cost", nav.RobustDescent()),
            ("metric descent", nav.MetricDescent()),
            ("metric descent + geodesic field", nav.MetricDescent(field=field))]
    res = {"kind": a.kind, "scene": sc.name, "trials": a.trials, "training_frames": len(P),
           "setup_seconds": round(train_s, 1), "geodesic_nodes": field.n_nodes, "arms": []}
    for name, d in arms:
        navi = nav.Navigator(sc.simulator, feats, d, n_outputs=2, success_radius=EN.SUCCESS_RADIUS,
                             max_iterations=EN.MAX_ITERATIONS)
        t1 = time.perf_counter()
        s = nav.evaluate_trials(navi, starts, targets, optimal_lengths=optimal, progress=False)
        row = {"arm": name, "success": s.success_rate, "efficiency": s.efficiency, "mean_stops": s.mean_iterations,
               "reasons": dict(s.reasons), "seconds": round(time.perf_counter() - t1, 1)}
        print(row, flush=True)
        res["arms"].append(row)
        sel = EN._pick(s.results, 8)
        nav.plot_trajectories([s.results[i] for i in sel], out / f"nav-metric-{a.kind}-{name.replace(' ', '-').replace(',', '').replace('+', 'plus')}.png",
                              world=sc.world, title=f"7.1 {a.kind}: {name}")
    (out / f"nav-metric-{a.kind}.json").write_text(json.dumps(res, indent=1, default=float))


if __name__ == "__main__":
    main()
