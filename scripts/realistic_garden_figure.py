"""The figure of the realistic-garden preset in docs/simulator.md:
layout (training grid, test walk, objects), the lawn's colour map with the
ground patches, and a wide panorama at a training pose.

    PYTHONPATH=python python3 scripts/realistic_garden_figure.py docs/images [--seed 0]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from sfanav import sim  # noqa: E402
from sfanav.sim.primitives import BLOCK_HEIGHT  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    p = sim.presets.get("realistic-garden")
    world = sim.recording.preset_world("realistic-garden", a.seed)
    s_runs, s_traj = sim.recording.random_streams(a.seed)[1:3]
    runs = p.runs(s_runs)
    train = runs[0].trajectory(world, s_traj)
    test = runs[1].trajectory(world, s_traj)
    r = sim.Renderer(world)
    fig = plt.figure(figsize=(12, 7.2), layout="constrained")
    gs = fig.add_gridspec(2, 2, height_ratios=[3, 1.2])
    ax = fig.add_subplot(gs[0, 0])
    ax.plot(train.poses[:, 0], train.poses[:, 1], "-", lw=0.5, color="tab:blue", label=f"training grid ({len(train)})")
    ax.plot(test.poses[:, 0], test.poses[:, 1], "-", lw=0.6, color="tab:red", label=f"test walk ({len(test)})")
    for o in world.obstacles:
        for q in o.parts:
            low = q.z0 < BLOCK_HEIGHT
            ax.add_patch(plt.Circle((q.x, q.y), q.bound_radius, fill=low, alpha=0.5 if low else 1.0,
                                    color="k" if low else "g", lw=0.8))
        ax.annotate(o.kind, (o.x, o.y), fontsize=7, ha="center", va="bottom")
    w, h = world.area
    ax.add_patch(plt.Rectangle((-w / 2, -h / 2), w, h, fill=False, ls="--", color="gray"))
    ax.set_aspect("equal")
    ax.set_xlim(-w / 2 - 1, w / 2 + 1)
    ax.set_ylim(-h / 2 - 1, h / 2 + 1)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title("layout (m)")
    ax2 = fig.add_subplot(gs[0, 1])
    gmap, res, o = r.ground_colour_map()
    i0, i1 = int((-w / 2 - 1 - o) / res), int((w / 2 + 1 - o) / res)
    j0, j1 = int((-h / 2 - 1 - o) / res), int((h / 2 + 1 - o) / res)
    ax2.imshow(np.clip(gmap[j0:j1, i0:i1], 0, 1), origin="lower",
               extent=(-w / 2 - 1, w / 2 + 1, -h / 2 - 1, h / 2 + 1))
    ax2.set_title("lawn colour map with the ground patches")
    ax3 = fig.add_subplot(gs[1, :])
    k = len(train) // 3
    ax3.imshow(r.render(sim.PanoramicCamera(1200, 160), train.poses[k]))
    ax3.set_axis_off()
    ax3.set_title(f"1200x160 panorama at training pose {k} "
                  f"({train.poses[k, 0]:.1f}, {train.poses[k, 1]:.1f}) m")
    path = out / "realistic-garden.png"
    fig.savefig(path, dpi=80)
    print(path)


if __name__ == "__main__":
    main()
