#!/usr/bin/env python3
"""What limits the serpentine's map without ground truth (issue 42): the closures' relative headings, per lane gap,
against the truth, the map's heading residual on the first and the last lanes, and the map error when the
relative-pose closures' heading variance is scaled or floored.

For each mower-survey run (its cached slow features, as refinement_guard.py caches them) the pose graph is fitted
as ``train_localizer(supervision="odometry")`` fits it (GTSAM, relative-pose closures, the run's gyro, the misfit
test); a wrapper around :func:`sfanav.odometry.pair_closures.pair_relative_poses` records the closures (and, for
the variants, changes their heading variance before the solve). Lanes are numbered by the true y (1.25 m apart,
the preset's lane spacing); ground truth is used for scoring only.

    PYTHONPATH=python python3 scripts/investigations/serpentine_heading_bias.py OUT.json --cache CACHE \\
        --run DATASET:RUN [--run DATASET:RUN ...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import sfanav.odometry.pair_closures as pc
import sfanav.odometry.pose_graph as pg
from sfanav.localization.error_metrics import align
from sfanav.odometry.gyro import fuse_gyro
from refinement_guard import cached_run  # noqa: E402  (this folder: the cache's reader)

VARIANTS = {"default": {}, "heading variance x 0.0625": {"scale": 1 / 16}, "heading variance x 0.25": {"scale": 0.25},
            "heading sigma floor 0.3 deg": {"floor_deg": 0.3}, "heading sigma floor 0.7 deg": {"floor_deg": 0.7},
            "heading sigma floor 1.5 deg": {"floor_deg": 1.5}}
"""The closures' heading variance: as measured (default), scaled, or with a floor added in quadrature."""

LANE_SPACING = 1.25


def wrap(a: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * a))


def fit(d: dict, gyro: np.ndarray, variant: dict) -> tuple[pg.PoseGraph, object]:
    seen = {}
    original = pc.pair_relative_poses

    def wrapped(images, F, X, i, j, *a, **k):
        rp = original(images, F, X, i, j, *a, **k)
        cov = rp.covariance
        good = cov[:, 0, 0] < 1e3  # relative-pose closures (heading-only ones keep the compass's sigma)
        if "floor_deg" in variant:
            cov[good, 2, 2] += np.radians(variant["floor_deg"]) ** 2
        if "scale" in variant:
            f = np.sqrt(variant["scale"])
            cov[good, 2, :] *= f
            cov[good, :, 2] *= f
        seen["rp"] = rp
        return rp

    pc.pair_relative_poses = wrapped
    try:
        g = pg.fit_pose_graph(d["X"], d["F"], d["odometry"], n_outputs=8, solver="gtsam",
                              pair_closures="relative-pose", gyro=gyro)
    finally:
        pc.pair_relative_poses = original
    return g, seen["rp"]


def diagnose(g: pg.PoseGraph, rp, T: np.ndarray, odometry: np.ndarray, gyro: np.ndarray) -> dict:
    """Closures' heading errors per lane gap, the map's heading residual per lane, drift rates."""
    i, j = rp.i, rp.j
    true_dth = wrap(T[j, 2] - T[i, 2])
    err = np.degrees(wrap(rp.dtheta - true_dth))
    map_err = np.degrees(wrap(g.poses[j, 2] - g.poses[i, 2] - true_dth))
    ok = (rp.covariance[:, 0, 0] < 1e3) & (g.weights >= 0.5)
    lane = np.floor((T[:, 1] - T[:, 1].min()) / LANE_SPACING + 0.5).astype(int)
    gap = np.abs(lane[j] - lane[i])
    per_gap = {}
    for k in (1, 2, 3):
        m = ok & (gap == k)
        if m.any():
            per_gap[str(k)] = {"closures": int(m.sum()), "median heading error (deg)": float(np.median(err[m])),
                               "baseline median (m)": float(np.median(np.hypot(*(T[j, :2] - T[i, :2])[m].T)))}
    pairs = []
    for L in range(lane.max()):
        m = ok & (np.minimum(lane[i], lane[j]) == L) & (gap == 1)
        if m.any():
            pairs.append({"lanes": [L, L + 1], "closure (deg)": float(np.median(err[m])),
                          "map (deg)": float(np.median(map_err[m]))})
    r = wrap(g.poses[:, 2] - T[:, 2])
    r = np.degrees(wrap(r - np.angle(np.exp(1j * r).mean())))
    first, last = lane == lane[0], lane == lane[-1]
    s = pg.travelled(odometry)
    fused = fuse_gyro(odometry, gyro).odometry
    true_drift = np.polyfit(s, np.unwrap(fused[:, 2]) - np.unwrap(T[:, 2]), 1)[0]
    return {"closure heading error per lane gap": per_gap, "neighbouring lanes (median)": pairs,
            "map heading residual, first lane (deg)": float(np.median(r[first])),
            "map heading residual, last lane (deg)": float(np.median(r[last])),
            "drift (deg per m): estimated": float(np.degrees(g.drift_rate)),
            "drift (deg per m): of the fused odometry against the truth": float(np.degrees(true_drift))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--cache", type=Path, required=True, help="refinement_guard.py's cache folder")
    ap.add_argument("--run", action="append", default=[], help="DATASET:RUN")
    a = ap.parse_args()
    res = json.loads(a.out.read_text()) if a.out.exists() else {}
    for spec in a.run:
        key, d, gyro = cached_run(spec, a.cache)
        T = d["truth"]
        entry: dict = {"frames": len(T), "map error (m)": {}}
        for name, variant in VARIANTS.items():
            g, rp = fit(d, gyro, variant)
            P = g.poses[:, :2]
            entry["map error (m)"][name] = float(np.hypot(*(align(P, T[:, :2]).apply(P) - T[:, :2]).T).mean())
            if name == "default":
                entry.update(diagnose(g, rp, T, d["odometry"], gyro))
        res[key] = entry
        print(key, json.dumps(entry["map error (m)"]), flush=True)
        a.out.write_text(json.dumps(res, indent=1) + "\n")
    keys = [k for k, v in res.items() if isinstance(v, dict) and "frames" in v]
    for pattern in ("serpentine", "perimeter-serpentine"):
        ks = [k for k in keys if k.endswith(f":{pattern}")]
        if ks:
            res[f"mean map error (m), {pattern}"] = {
                n: float(np.mean([res[k]["map error (m)"][n] for k in ks])) for n in VARIANTS}
    a.out.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
