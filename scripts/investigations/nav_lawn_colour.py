"""What the 7.1 image network's slowest outputs code: lawn colour or position.

Renders the 7.1 scene's 5000-frame training run on a patchy or a uniform
lawn, trains the thesis-5.2 network on it (as ``sfanav experiment 7.1-*``
does) or loads one (``--network``), and prints, for s1..s4 on the training
run, the share of variance (R^2) explained linearly by the mean lawn colour
(R, G, B of the ground colour map) within 1, 3 and 6 m of the robot, and by a
cubic polynomial of the position; and Delta (mean squared step difference of
the unit-variance outputs) beside that of SFA on the coordinates.

    PYTHONPATH=python python3 scripts/investigations/nav_lawn_colour.py --lawn patchy --out OUT
    PYTHONPATH=python python3 scripts/investigations/nav_lawn_colour.py --lawn uniform --network OUT/cache/....sfanav
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np


from sfanav.experiments import navigation_scenes as NS
from sfanav.sfa import load
from sfanav.sfa import Network, Rotation


def r2(A: np.ndarray, y: np.ndarray) -> float:
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(1 - np.var(y - A @ coef) / np.var(y))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kind", choices=("open", "obstacle"), default="open")
    ap.add_argument("--lawn", choices=("patchy", "uniform"), default="patchy")
    ap.add_argument("--network", type=Path, help="a trained network of this scene (else trained, about 6 min)")
    ap.add_argument("--out", type=Path, default=Path("runs/lawn"), help="where a trained network is saved")
    a = ap.parse_args()
    sc = NS.scene(a.kind, 0, lawn=a.lawn)
    poses = sc.trajectory.poses
    ren = sc.simulator.renderer
    imgs = np.stack([ren.render(sc.camera, p) for p in poses])
    if a.network:
        net = load(a.network)
    else:
        t = time.time()
        net = Network(NS.network_config(False))
        net.fit(imgs, rotation=Rotation(5), progress=False)
        a.out.mkdir(parents=True, exist_ok=True)
        path = a.out / f"thesis-5.2-{a.kind}-{a.lawn}.sfanav"
        net.save(path)
        print(f"trained in {time.time() - t:.0f} s: {path}")
    Y = np.asarray(net.transform(imgs), float)
    xy = poses[:, :2]
    gm, res, o = ren.ground_colour_map()
    ix = ((xy[:, 0] - o) / res).astype(int)
    iy = ((xy[:, 1] - o) / res).astype(int)
    print(f"scene {sc.name}, lawn {a.lawn}: R^2 of the network's outputs on the {len(poses)} training frames")
    print("output | mean lawn colour within 1 m | 3 m | 6 m | cubic polynomial of x, y")
    cols = {}
    for R in (1.0, 3.0, 6.0):
        k = int(R / res)
        blur = cv2.blur(gm, (2 * k + 1, 2 * k + 1))
        g = blur[iy, ix]
        cols[R] = np.column_stack([g, np.ones(len(g))])
    x, y = xy[:, 0], xy[:, 1]
    P = np.column_stack([x**i * y**j for i in range(4) for j in range(4 - i)])
    for i in range(4):
        print(f"s{i + 1} | " + " | ".join(f"{r2(cols[R], Y[:, i]):.2f}" for R in (1.0, 3.0, 6.0))
              + f" | {r2(P, Y[:, i]):.2f}")
    Z = (Y - Y.mean(0)) / Y.std(0)
    C = NS.coordinate_model(sc)(xy)
    C = (C - C.mean(0)) / C.std(0)
    d = lambda M: " ".join(f"{v:.5f}" for v in np.mean(np.diff(M[:, :4], axis=0) ** 2, axis=0))
    print(f"Delta s1-s4 per frame: network {d(Z)}; SFA on the coordinates {d(C)}")


if __name__ == "__main__":
    main()
