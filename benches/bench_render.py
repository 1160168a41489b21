#!/usr/bin/env python3
"""Rendering speed of the garden simulator (pure NumPy, one process).

Renders frames along a random walk through the 16x18 m garden of the
thesis's sections 5.3 / 6.2 (30 objects, 2 ArUco markers, default lighting)
and prints frames per second for each camera:

* 600x60 RGB panorama (the thesis's network input; target: hundreds of fps
  for closed-loop navigation),
* 600x60 gray panorama, 350x40 RGB panorama (section 5.1.1),
* 500x500 RGB omnidirectional image (section 6.2.1), and 300x300,
* the 500x500 omni image unwarped to 600x55 (render + unwarp).

Also the one-off cost of building a renderer (texture synthesis, ground and
sky maps) and of rendering + writing PNG files (what ``sfanav simulate``
does). Timings are the best of ``--repeats`` passes; the machines are shared
and noisy, so quote the fps of one run together with the machine.

Usage::

    PYTHONPATH=python python3 benches/bench_render.py [--frames 200] [--repeats 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time

import numpy as np

from sfanav import sim
from sfanav.data import write_image


def timed(fn, frames, repeats):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for k in range(frames):
            fn(k)
        best = min(best, time.perf_counter() - t0)
    return frames / best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=200, help="frames per camera and pass (omni: a quarter)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None, help="also write the numbers to this file")
    args = ap.parse_args()

    t0 = time.perf_counter()
    world = sim.World.generate(args.seed, area=(16.0, 18.0), n_objects=30, markers=(136, 144))
    t_world = time.perf_counter() - t0
    t0 = time.perf_counter()
    ren = sim.Renderer(world)
    t_renderer = time.perf_counter() - t0
    poses = sim.trajectories.random_walk(world.area, max(args.frames, 8), rng=args.seed).poses
    n_prims = sum(len(o.parts) for o in world.objects)

    cams = {
        "panorama 600x60 RGB": (sim.PanoramicCamera(600, 60), args.frames),
        "panorama 600x60 gray": (sim.PanoramicCamera(600, 60, rgb=False), args.frames),
        "panorama 350x40 RGB": (sim.PanoramicCamera(350, 40), args.frames),
        "omni 500x500 RGB": (sim.OmniCamera(500), max(args.frames // 4, 4)),
        "omni 300x300 RGB": (sim.OmniCamera(300), max(args.frames // 4, 4)),
    }
    print(f"sfanav garden renderer: {len(world.objects)} objects ({n_prims} primitives), "
          f"{os.cpu_count()} CPUs, {platform.processor() or platform.machine()}, NumPy {np.__version__}")
    print(f"world generation {t_world * 1e3:.0f} ms, renderer build (textures, ground, sky) {t_renderer:.2f} s")
    results: dict[str, float] = {}
    for name, (cam, n) in cams.items():
        ren.render(cam, poses[0])  # warm the per-camera caches and the shadow map
        fps = timed(lambda k: ren.render(cam, poses[k % len(poses)]), n, args.repeats)
        results[name] = fps
        print(f"  {name:<24} {fps:8.1f} frames/s  ({1e3 / fps:6.2f} ms/frame)")
    omni = sim.OmniCamera(500)
    fps = timed(lambda k: omni.unwarp(ren.render(omni, poses[k % len(poses)]), 600, 55),
                max(args.frames // 4, 4), args.repeats)
    results["omni 500x500 + unwarp to 600x55"] = fps
    print(f"  {'omni 500x500 + unwarp':<24} {fps:8.1f} frames/s")
    pano = sim.PanoramicCamera(600, 60)
    with tempfile.TemporaryDirectory() as d:
        fps = timed(lambda k: write_image(os.path.join(d, f"{k}.png"), ren.render(pano, poses[k % len(poses)])),
                    args.frames, 1)
    results["panorama 600x60 RGB + PNG write"] = fps
    print(f"  {'600x60 RGB + PNG write':<24} {fps:8.1f} frames/s  (what `sfanav simulate` does)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"fps": results, "renderer_build_s": t_renderer, "objects": len(world.objects),
                       "primitives": n_prims, "cpus": os.cpu_count()}, f, indent=1)


if __name__ == "__main__":
    main()
