#!/usr/bin/env python3
"""Why relative-pose closures hurt some gardens (issue 42): the warping's bearing of each place pair of the
default pose graph against the truth (evaluation only), and the pose graph solved with those bearings and with the
true ones. For each run: the signed and absolute bearing errors, their standardised size, how much the errors of
closures whose midpoints lie within 1 m of each other correlate (against random closures), and the training
positions' median error (rigid fit) of GTSAM relative-pose graphs with the closures independent (the rule before
2026-12-06), decorrelated by place (the default since), and with each measured bearing replaced by the true one.

    PYTHONPATH=python python3 scripts/investigations/closure_bearing_errors.py ROOT OUT.json \\
        [--runs suite-control 5.1.1 mower-serpentine mower-spiral demo]

ROOT is a directory of ``pose_graph_refinement.py``: ``ROOT/cache/RUN.npz`` (images, features, odometry, truth)
and the datasets under ``ROOT/data`` (for the true headings). docs/odometry.md, "Correlated bearing errors".
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import sfanav.odometry.pair_closures as pc
from pose_graph_refinement import SCENES, median_error
from sfanav.data import Dataset
from sfanav.loopclosure import relative_poses
from sfanav.odometry import fit_pose_graph
from sfanav.odometry.pose_graph_gtsam import RelativePoses


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def true_relative(P: np.ndarray, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pose of j in the frame of i: (dx, dy) (M, 2) and the bearing (M,)."""
    v = P[j, :2] - P[i, :2]
    c, s = np.cos(P[i, 2]), np.sin(P[i, 2])
    loc = np.c_[c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]]
    return loc, np.arctan2(loc[:, 1], loc[:, 0])


def bearing_errors(imgs: np.ndarray, P: np.ndarray, i: np.ndarray, j: np.ndarray) -> dict[str, float]:
    used, inv = np.unique(np.r_[i, j], return_inverse=True)
    sub = imgs[used].astype(np.float32)
    if sub.ndim == 4:
        sub = sub.mean(axis=3)
    loc, bt = true_relative(P, i, j)
    d = np.hypot(*loc.T)
    rp = relative_poses(sub, inv[: len(i)], inv[len(i):], distance=np.maximum(d, 1e-3), **pc.WARP_OPTIONS)
    e = wrap(rp.bearing - bt)
    ok = np.isfinite(rp.sigma_bearing) & (rp.sigma_bearing <= np.radians(30))
    e, sb, d, ii, jj = e[ok], rp.sigma_bearing[ok], d[ok], i[ok], j[ok]
    mid = 0.5 * (P[ii, :2] + P[jj, :2])
    near = cKDTree(mid).query_pairs(1.0, output_type="ndarray")
    rnd = np.random.default_rng(0).integers(0, len(e), (max(len(near), 1000), 2))
    return {"closures": int(len(i)), "informative": int(ok.sum()),
            "mean error (deg)": float(np.degrees(e.mean())),
            "median |error| (deg)": float(np.degrees(np.median(np.abs(e)))),
            "median |error| in sigmas": float(np.median(np.abs(e) / sb)),
            "lateral error mean (m)": float(np.mean(np.abs(e) * d)),
            "error correlation, closures within 1 m": float(np.corrcoef(e[near[:, 0]], e[near[:, 1]])[0, 1]),
            "error correlation, random closures": float(np.corrcoef(e[rnd[:, 0]], e[rnd[:, 1]])[0, 1])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root")
    ap.add_argument("out")
    ap.add_argument("--runs", nargs="*", default=["suite-control", "5.1.1", "mower-serpentine", "mower-spiral", "demo"])
    a = ap.parse_args()
    root, out = Path(a.root), Path(a.out)
    res = json.loads(out.read_text()) if out.exists() else {}
    measured = pc.pair_relative_poses
    truth_poses: dict[str, np.ndarray] = {}

    def oracle(images, features, positions, i_idx, j_idx, compass, sigma, **kw):
        """The measured closures with each informative bearing replaced by the true one (same length, same
        covariance)."""
        rp = measured(images, features, positions, i_idx, j_idx, compass, sigma, **kw)
        full = rp.covariance[:, 0, 0] < 1.0
        _, bt = true_relative(truth_poses["P"], rp.i, rp.j)
        d = np.hypot(rp.dx, rp.dy)
        return RelativePoses(rp.i, rp.j, np.where(full, d * np.cos(bt), rp.dx), np.where(full, d * np.sin(bt), rp.dy),
                             rp.dtheta, covariance=rp.covariance)

    for run in a.runs:
        z = np.load(root / "cache" / f"{run}.npz", allow_pickle=False)
        imgs, F, odo, truth = z["images"], z["features"], z["odometry"], z["truth"]
        noise = json.loads(str(z["noise"])) if str(z["noise"]) != "null" else None
        preset, seed, name = SCENES[run]
        P = Dataset(root / "data" / f"{preset}-seed{seed}").select(run=name).poses
        truth_poses["P"] = P
        g = fit_pose_graph(imgs, F, odo, odometry_noise=noise)
        r = {"heading-only (default) median error (m)": median_error(g.poses[:, :2], truth),
             **bearing_errors(imgs, P, g.pairs.past, g.pairs.current)}
        kw = dict(odometry_noise=noise, solver="gtsam", pair_closures="relative-pose")
        for label, radius, fn in (("independent", None, measured), ("decorrelated", pc.CORRELATION_RADIUS, measured),
                                  ("independent, true bearings", None, oracle)):
            pc.pair_relative_poses = fn
            try:
                m = fit_pose_graph(imgs, F, odo, pair_options={"correlation_radius": radius}, **kw)
            finally:
                pc.pair_relative_poses = measured
            r[f"relative-pose {label} median error (m)"] = median_error(m.poses[:, :2], truth)
        res[run] = r
        print(run, json.dumps({k: round(v, 3) for k, v in r.items()}), flush=True)
        tmp = out.with_suffix(".part")
        tmp.write_text(json.dumps(res, indent=1) + "\n")
        tmp.replace(out)


if __name__ == "__main__":
    main()
