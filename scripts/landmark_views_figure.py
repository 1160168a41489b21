"""The marker views of thesis 5.4 (its Fig. 5.25) on the thesis-5.4-landmarks
scene: one omnidirectional frame with the detected markers outlined, and
the views of both markers from a few poses of the test walk, each turned
upright by the marker's polar angle and cut to its bounding box + 50 px.

    PYTHONPATH=python python3 scripts/landmark_views_figure.py docs/images
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

from sfanav import sim
from sfanav.landmarks import ViewExtractor
from sfanav.sim import presets, recording


def main(out: Path) -> None:
    p = presets.get("thesis-5.4-landmarks")
    s_world, s_runs, s_traj, _ = recording.random_streams(0)
    world = sim.World.generate(int(s_world.integers(2**31)), **p.world)
    cam, ren = p.camera(), sim.Renderer(world)
    runs = p.runs(s_runs)
    runs[0].trajectory(world, s_traj)  # the test walk is drawn after the training grid
    walk = runs[1].trajectory(world, s_traj)
    ex = ViewExtractor((136, 144))
    poses = walk.poses[np.linspace(0, len(walk) - 1, 6).round().astype(int)]
    frame = ren.render(cam, poses[0])
    shown = frame.copy()
    for mid, c in ex.detect(frame).items():
        cv2.polylines(shown, [c.round().astype(np.int32)], True, (255, 0, 0), 4)
        cv2.putText(shown, str(mid), tuple(int(v) for v in c.min(axis=0) - [0, 12]), cv2.FONT_HERSHEY_SIMPLEX, 1.4,
                    (255, 0, 0), 3)
    shown = cv2.resize(shown, (480, 480), interpolation=cv2.INTER_AREA)
    views = ex.transform(np.stack([ren.render(cam, q) for q in poses]))
    rows = [np.concatenate(list(views.views[:, j]), axis=1) for j in range(2)]
    grid = np.concatenate(rows, axis=0)  # 240 x 720
    grid = np.pad(grid, ((120, 120), (0, 0), (0, 0)), constant_values=255)
    fig = np.concatenate([shown, np.full((480, 10, 3), 255, np.uint8), grid], axis=1)
    out.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out / "landmark-views.png"), fig[:, :, ::-1])
    print(f"wrote {out / 'landmark-views.png'}; found {views.found.mean(axis=0)} of the 6 poses")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/images"))
