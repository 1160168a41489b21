"""Navigation in the open field (thesis 7.1.2) with a horizon-band network.

The thesis-5.2 network trained on panoramas of the elevation band -10 .. +20
degrees (a camera without the near ground, cf. ``sfanav.data.image_rows``) of the
first ``--frames`` poses of the ``7.1-open`` training run, in mixed precision
with simulated rotation in 5 px steps; navigation with the thesis rule (n = 2
raw outputs, the thesis's setting) and the robust descent with n = 2 raw and
n = ``--n`` outputs weighted by beta_1 / beta_i (thesis 7.2.1). Trials are
drawn exactly like ``sfanav experiment 7.1-open`` (``--trial-seed 0``: the
same trials; other seeds: other trials, for choosing settings).

    PYTHONPATH=python python3 scripts/investigations/nav_band_arm.py --out DIR [--frames 1500]
        [--trials 25] [--trial-seed 0] [--n 8]

With ``--full-network PATH`` the same arms run on the 7.1-open network
(full panorama) instead.

Writes DIR/nav-<band|full>-arm-s<trial seed>.json and a trajectory plot; the
network is cached in DIR/cache.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from sfanav import navigation as nav
from sfanav.experiments import navigation as EN
from sfanav.experiments import navigation_scenes as NS
from sfanav.sfa import load
from sfanav.sfa import Network, Rotation, spatial_pairs
from sfanav.sim.cameras import PanoramicCamera

BAND = (-10.0, 20.0)


def band_network(sc: NS.Scene, frames: int, cache: Path, pairs: bool = False) -> Network:
    if cache.exists():
        return load(cache)
    r = sc.simulator.renderer
    poses = sc.trajectory.poses[:frames]
    imgs = np.stack([r.render(sc.camera, p) for p in poses])
    net = Network.from_preset("thesis-5.2", precision="mixed")
    kw = {}
    if pairs:
        # supervised GSFA pairs of the training positions in the top layer, each compared at a random
        # relative orientation in 5 px steps (docs/gardens.md, "graph weights": the gardens' best variant)
        xy = np.asarray(poses)[:, :2]
        parts = [spatial_pairs(xy, 1.2, 4, min_gap=4, shifts=imgs.shape[2], shift_step=5, seed=0),
                 spatial_pairs(xy, 0.6, 4, shifts=imgs.shape[2], shift_step=5, seed=1)]
        kw = {"pairs": tuple(np.concatenate(z) for z in zip(*parts)), "pair_layers": [4]}
    net.fit(imgs, rotation=Rotation(5), progress=False, **kw)
    cache.parent.mkdir(parents=True, exist_ok=True)
    net.save(cache)
    return net


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--frames", type=int, default=1500)
    ap.add_argument("--trials", type=int, default=25)
    ap.add_argument("--trial-seed", type=int, default=0)
    ap.add_argument("--n", type=int, default=8)
    ap.add_argument("--grid", action="store_true", help="also the position-code error on a 0.5 m grid")
    ap.add_argument("--only-weighted", action="store_true",
                    help="run only the robust descent with n weighted outputs (the n = 2 arms of the full "
                         "network are 7.1-open's own rows)")
    ap.add_argument("--pairs", action="store_true",
                    help="train the network with top-layer spatial pairs of the training positions")
    ap.add_argument("--no-band", action="store_true", help="train on the full panorama (with --pairs)")
    ap.add_argument("--lawn", choices=("patchy", "uniform"), default="patchy",
                    help="the scene's lawn (patchy: the 7.1 scenes until 2026-11-24, which the docs' numbers used)")
    ap.add_argument("--full-network", type=Path, default=None, metavar="SFANAV",
                    help="instead: the 7.1-open network (full panorama, e.g. OUT/cache/thesis-7.1-open-seed0.sfanav)")
    a = ap.parse_args()
    if not 1 <= a.trials <= 50:
        raise SystemExit("--trials must be in 1..50")
    base = NS.scene("open", 0, lawn=a.lawn)
    t0 = time.time()
    if a.full_network is not None:
        sc, tag = base, "full"
        net = load(a.full_network)
    elif a.no_band:
        sc, tag = base, "full-pairs" if a.pairs else "full-retrained"
        net = band_network(sc, a.frames, a.out / "cache" / f"{tag}-open-seed0-{a.frames}.sfanav", a.pairs)
    else:
        sc, tag = dataclasses.replace(base, name="thesis-7.1-open-band",
                                      camera=PanoramicCamera(600, 60, elevation_deg=BAND)), "band"
        tag += "-pairs" if a.pairs else ""
        net = band_network(sc, a.frames, a.out / "cache" / f"{tag}-open-seed0-{a.frames}.sfanav", a.pairs)
    t_fit = time.time() - t0
    beta = np.asarray(net.beta_values_, float)
    w = nav.beta_weights(beta, relative=True)
    # the trials of 7.1-open (50 drawn, the first --trials used)
    S, T, *_ = EN.trials_71(sc, "open", a.trial_seed, a.trials)
    arms = [("thesis rule, n=2", nav.ThesisDescent(NS.ETA, NS.GAMMA), 2, None),
            ("robust descent, n=2", nav.RobustDescent(), 2, None),
            (f"robust descent, n={a.n} weighted", nav.RobustDescent(), a.n, w)]
    if a.only_weighted:
        arms = arms[2:]
    rows, results = [], {}
    for label, d, n, ww in arms:
        t = time.time()
        s = nav.evaluate_trials(NS.navigator(sc, net, d, n=n, weights=ww), S, T)
        results[label] = s
        rows.append({"arm": label, "success": s.success_rate, "efficiency": s.efficiency,
                     "mean_stops": s.mean_iterations, "reasons": s.reasons, "seconds": time.time() - t})
        print(rows[-1], flush=True)
    out = {"trial_seed": a.trial_seed, "trials": a.trials, "frames": a.frames, "network": tag, "band_deg": BAND if tag == "band" else None,
           "beta": beta.tolist(), "fit_seconds": t_fit, "rows": rows}
    if a.grid:
        xs, ys, F = NS.grid_features(sc, net, 0.5, False)
        out["position_code_rms_m"] = {n: NS.position_code_error(xs, ys, F, n) for n in range(2, 9)}
        tf = F[np.argmin(abs(ys - T[0][1])), np.argmin(abs(xs - T[0][0]))]
        nav.plot_cost_surface(xs, ys, F, tf, a.out / f"nav-{tag}-arm-cost-surface.png", ns=(2, a.n), weights=w,
                              n_firing=4, target=T[0], world=sc.world,
                              title="7.1 open, horizon-band network: s1-s4, cost n = 2 and weighted")
        print(out["position_code_rms_m"], flush=True)
    label = f"robust descent, n={a.n} weighted"
    s = results[label]
    sel = EN.pick_trials(s.results, 8)
    nav.plot_trajectories([s.results[i] for i in sel], a.out / f"nav-{tag}-arm-s{a.trial_seed}.png", world=sc.world,
                          titles=[("reached" if s.results[i].success else s.results[i].reason)
                                  + (f" e={s.efficiencies[i]:.2f}" if s.results[i].success else "") for i in sel],
                          title=f"7.1 open, {tag} network: {label}")
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / f"nav-{tag}-arm-s{a.trial_seed}.json").write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
