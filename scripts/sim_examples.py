#!/usr/bin/env python3
"""Renders the example images of docs/simulator.md from the garden of the
``thesis-5.3-garden`` preset (seed 0), robot at the origin facing +x:

* docs/images/sim-panorama.png: 600x60 RGB panorama (the network's input),
* docs/images/sim-panorama-wide.png: the same view at 1800x240 for reading,
* docs/images/sim-omni.png: 500x500 omnidirectional (mirror) image,
* docs/images/sim-omni-unwarped.png: that omni image unwarped to 600x55;

and from the garden of ``thesis-6.2.2-seasons`` (seed 0), at the start of
its border-wire loop:

* docs/images/sim-seasons.png: 1200x100 panoramas in spring, summer,
  autumn and winter (top to bottom), each under a sun in the middle of the
  season's typical elevations.

Usage: PYTHONPATH=python python3 scripts/sim_examples.py [OUT_DIR]
"""

import sys
from pathlib import Path

import cv2
import numpy as np

from sfanav import sim


def save(path: Path, img) -> None:
    cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {path} {img.shape}")


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/images")
    out.mkdir(parents=True, exist_ok=True)
    world = sim.recording.preset_world("thesis-5.3-garden", seed=0)
    ren = sim.Renderer(world)
    pose = (0.0, 0.0, 0.0)
    save(out / "sim-panorama.png", ren.render(sim.PanoramicCamera(600, 60), pose))
    save(out / "sim-panorama-wide.png", ren.render(sim.PanoramicCamera(1800, 240, (-30, 30)), pose))
    omni = sim.OmniCamera(500)
    img = ren.render(omni, pose)
    save(out / "sim-omni.png", img)
    save(out / "sim-omni-unwarped.png", omni.unwarp(img, 600, 55))

    world = sim.recording.preset_world("thesis-6.2.2-seasons", seed=0)
    ren = sim.Renderer(world)
    start = sim.trajectories.border_loop(world.area, 279, rng=0).poses[0]
    cam = sim.PanoramicCamera(1200, 100, (-30, 30))
    rows = [ren.render(cam, start, lighting=sim.Lighting(sun_elevation_deg=float(np.mean(s.sun_elevation_deg)),
                                                          season=s))
            for s in sim.SEASONS.values()]
    save(out / "sim-seasons.png", np.concatenate(rows))


if __name__ == "__main__":
    main()
