#!/usr/bin/env python3
"""Relative-pose loop closures between neighbouring lanes of a serpentine (docs/relative-pose.md): for
frames on one lane and a frame of the next lane near it (true positions; 0-0.75 m along the lane apart),
the error of the relative heading, of the baseline direction, of the along-lane and lateral offsets
(with the true distance and with the lane spacing as the distance prior), the calibration of the
reported sigmas and the time per pair. The gardens suite's worlds, its training serpentine (lanes along
x, the robot facing where it drives), panoramas rendered directly at the true poses.

    PYTHONPATH=python python3 scripts/investigations/relative_pose_lanes.py [--pairs 60] [--width 120 --height 16]
"""
import argparse
import time

import numpy as np

from sfanav import sim
from sfanav.loopclosure.relative_pose import relative_poses
from sfanav.sim import trajectories as T

ap = argparse.ArgumentParser()
ap.add_argument("--pairs", type=int, default=60, help="pairs per garden")
ap.add_argument("--width", type=int, default=120)
ap.add_argument("--height", type=int, default=16)
ap.add_argument("--gray", action="store_true")
ap.add_argument("--rows", type=int, default=None, help="compare only the top ROWS rows (default all)")
ap.add_argument("--gardens", default="suite-inner:1.0,suite-large-inner:1.5,suite-open-lawn:1.0")
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--triangulate", type=int, default=60,
                help="frames per garden whose lateral offset to the next lane is triangulated from bearings alone")
a = ap.parse_args()


def wrapdeg(x):
    return np.degrees(np.angle(np.exp(1j * np.asarray(x, float))))


cam = sim.PanoramicCamera(a.width, a.height, rgb=not a.gray)
rows = None if a.rows is None else slice(0, a.rows)
print(f"camera {a.width}x{a.height} {'gray' if a.gray else 'RGB'}, rows {rows}")
print("| garden | lane spacing | pairs | dtheta err median / p90 (deg) | bearing err median / p90 (deg) | "
      "z median | within 2 sigma | lateral err, true distance: median / p90 (m) | along err, true distance (m) | "
      "lateral err, spacing prior (m) | s / pair |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
allz = []
tri_rows = []
for spec in a.gardens.split(","):
    name, spacing = spec.split(":")
    spacing = float(spacing)
    rng = np.random.default_rng(a.seed)
    w = sim.recording.preset_world(name, a.seed)
    tr = T.detour(T.grid(w.area, spacing=spacing, step=0.25, turn="arc", margin=0.5, crossings=False), w)
    P = tr.poses
    straight = np.abs(np.sin(P[:, 2])) < 0.02
    lane = np.where(straight, np.round((P[:, 1] - P[straight, 1].min()) / spacing), -1).astype(int)
    cand = np.flatnonzero((lane >= 0) & (lane < lane.max()))
    pick = rng.choice(cand, size=min(a.pairs, len(cand)), replace=False)
    I, J = [], []
    for i in pick:
        nxt = np.flatnonzero(lane == lane[i] + 1)
        k = nxt[np.argmin(np.hypot(*(P[nxt, :2] - P[i, :2]).T))]
        k = int(np.clip(k + rng.integers(-3, 4), nxt.min(), nxt.max()))
        if lane[k] == lane[i] + 1:
            I.append(i)
            J.append(k)
    I, J = np.array(I, int), np.array(J, int)
    # triangulation: frame i and the next lane's frames 0.5 and 1 m along the lane before and after it
    TI, TJ = [], []
    for i in rng.choice(cand, size=min(a.triangulate, len(cand)), replace=False):
        nxt = np.flatnonzero(lane == lane[i] + 1)
        k = nxt[np.argmin(np.hypot(*(P[nxt, :2] - P[i, :2]).T))]
        ks = [k + o for o in (-4, -2, 2, 4) if nxt.min() <= k + o <= nxt.max() and lane[k + o] == lane[i] + 1]
        if len(ks) == 4:
            TI += [i] * 4
            TJ += ks
    TI, TJ = np.array(TI, int), np.array(TJ, int)
    frames = np.unique(np.r_[I, J, TI, TJ])
    ren = sim.Renderer(w)
    imgs = {f: ren.render(cam, P[f]) for f in frames}
    idx = {f: n for n, f in enumerate(frames)}
    X = np.array([imgs[f] for f in frames])
    ii, jj = np.array([idx[f] for f in I], int), np.array([idx[f] for f in J], int)
    d = P[J, :2] - P[I, :2]
    c, s = np.cos(P[I, 2]), np.sin(P[I, 2])
    tx, ty = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]  # truth in frame i
    dist = np.hypot(tx, ty)
    if len(I):
        t0 = time.perf_counter()
        rp = relative_poses(X, ii, jj, distance=dist, distance_sigma=0.05, rows=rows)
        per = (time.perf_counter() - t0) / len(I)
        prior = relative_poses(X, ii, jj, distance=spacing, rows=rows)
        eh = np.abs(wrapdeg(rp.dtheta - (P[J, 2] - P[I, 2])))
        eb = np.abs(wrapdeg(rp.bearing - np.arctan2(ty, tx)))
        z = eb / np.degrees(rp.sigma_bearing)
        allz.append(z)
        lat, along = np.abs(rp.dy - ty), np.abs(rp.dx - tx)
        latp = np.abs(prior.dy - ty)
        q = lambda v: f"{np.median(v):.2f} / {np.percentile(v, 90):.2f}"  # noqa: E731
        print(f"| {name} | {spacing} m | {len(I)} | {q(eh)} | {np.median(eb):.1f} / {np.percentile(eb, 90):.1f} | "
              f"{np.median(z):.2f} | {np.mean(z <= 2):.2f} | {q(lat)} | {q(along)} | {q(latp)} | {per:.3f} |", flush=True)
    if len(TI):
        tr_ = relative_poses(X, np.array([idx[f] for f in TI]), np.array([idx[f] for f in TJ]), rows=rows)
        d = P[TJ, :2] - P[TI, :2]
        c, s = np.cos(P[TI, 2]), np.sin(P[TI, 2])
        ds, L = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]  # along-lane (odometry) and lateral, frame i
        al = tr_.bearing.reshape(-1, 4)
        wgt = 1 / np.maximum(tr_.sigma_bearing.reshape(-1, 4), 1e-3) ** 2
        wgt = np.where(np.isfinite(wgt), wgt, 0.0)
        ds4 = ds.reshape(-1, 4)
        Lhat = (wgt * np.cos(al) * np.sin(al) * ds4).sum(1) / np.maximum((wgt * np.cos(al) ** 2).sum(1), 1e-12)
        Ltrue = L.reshape(-1, 4).mean(1)
        e = np.abs(Lhat - Ltrue)
        tri_rows.append(f"| {name} | {spacing} m | {len(e)} | {np.median(e):.2f} / {np.percentile(e, 90):.2f} | "
                        f"{np.mean(e):.2f} | {np.mean(Lhat - Ltrue):+.2f} | {np.mean(e < 0.25):.2f} |")
print()
print("Lateral offset to the next lane triangulated from the baseline directions to 4 frames of that lane "
      "(0.5 and 1 m before and after), along-lane distances from the (here true) odometry:")
print("| garden | lane spacing | frames | lateral error median / p90 (m) | mean (m) | mean signed (m) | share within 0.25 m |")
print("|---|---|---|---|---|---|---|")
print("\n".join(tri_rows))
z = np.concatenate(allz) if allz else np.zeros(0)
if len(z):
    print(f"all pairs: bearing error / sigma median {np.median(z):.2f} (0.67 for a calibrated Gaussian), "
          f"within 1 sigma {np.mean(z <= 1):.2f}, within 2 sigma {np.mean(z <= 2):.2f}")
