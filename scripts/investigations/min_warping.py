#!/usr/bin/env python3
"""Min-warping against the warping for the relative-pose closures of training without ground truth (issue 42):
the closures' relative heading and baseline direction against the truth, and the learned map's error, per run.

For each run (its cached slow features and images, as refinement_guard.py caches them) the pose graph is fitted
as ``train_localizer(supervision="odometry")`` fits it (GTSAM, relative-pose closures, the run's gyro, the misfit
test), once per variant of :data:`sfanav.odometry.pair_closures.WARP_OPTIONS` (``method``, ``temperature``); the
closures of the first variant's last measurement are measured again under every variant, so their errors compare
on the same pairs. Ground truth is used for scoring only.

Each variant's entry also holds the map's ``misfit`` (:attr:`sfanav.odometry.pose_graph.PoseGraph.misfit`, no ground
truth), and ``choice by misfit`` the variant of the lower one with its map error: what
``fit_pose_graph(closure_method="auto")`` keeps (tests/test_pair_closures.py checks that it keeps the lower one).

    PYTHONPATH=python python3 scripts/investigations/min_warping.py OUT.json --cache CACHE \\
        --run DATASET:RUN [--run DATASET:RUN ...] [--variants "warping,min-warping"]

A variant is a method, optionally with `` tT`` for another temperature (``"min-warping t12"``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import sfanav.odometry.pair_closures as pc
import sfanav.odometry.pose_graph as pg
from sfanav.localization.error_metrics import align
from sfanav.loopclosure.relative_pose import relative_poses_by_method
from refinement_guard import cached_run  # noqa: E402  (this folder: the cache's reader)

MAX_SIGMA_BEARING = np.radians(30.0)


def wrap(a: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * a))


def options(variant: str, base: dict) -> dict:
    method, _, temp = variant.partition(" t")
    out = dict(base, method=method)
    if temp:
        out["temperature"] = float(temp)
    return out


def fit(d: dict, gyro, warp: dict, spy: list) -> pg.PoseGraph:
    """The pose graph under ``warp``; ``spy`` receives every (images, i, j, kwargs, frames i, frames j) measured."""
    saved = dict(pc.WARP_OPTIONS)
    orig_rp, orig_pair = pc.relative_poses_by_method, pc.pair_relative_poses

    def rp(images, i, j, **kw):
        spy.append([images, np.asarray(i), np.asarray(j), kw])
        return orig_rp(images, i, j, **kw)

    def pair(*a, **k):
        out = orig_pair(*a, **k)
        spy[-1] += [out.i, out.j]
        return out

    pc.WARP_OPTIONS.clear()
    pc.WARP_OPTIONS.update(warp)
    pc.relative_poses_by_method, pc.pair_relative_poses = rp, pair
    try:
        return pg.fit_pose_graph(d["X"], d["F"], d["odometry"], n_outputs=8, solver="gtsam",
                                 pair_closures="relative-pose", gyro=gyro)
    finally:
        pc.relative_poses_by_method, pc.pair_relative_poses = orig_rp, orig_pair
        pc.WARP_OPTIONS.clear()
        pc.WARP_OPTIONS.update(saved)


def closure_errors(call: list, T: np.ndarray, warp: dict) -> dict:
    """Heading and bearing errors (deg) of one measurement's pairs under ``warp``, their ratio to the reported
    sigma, on the informative pairs."""
    images, i, j, kw, fi, fj = call
    kw = {k: v for k, v in kw.items() if k not in ("methods", "temperature")}
    method = warp.get("method", "warping")
    rp = relative_poses_by_method(images, i, j, **kw, methods=(method,),
                                  **{k: v for k, v in warp.items() if k != "method"})[method]
    ok = rp.informative(MAX_SIGMA_BEARING)
    dv = T[fj, :2] - T[fi, :2]
    eh = np.degrees(wrap(rp.dtheta - wrap(T[fj, 2] - T[fi, 2])))[ok]
    eb = np.degrees(wrap(rp.bearing - wrap(np.arctan2(dv[:, 1], dv[:, 0]) - T[fi, 2])))[ok]
    zh, zb = np.abs(eh) / np.degrees(rp.sigma_dtheta[ok]), np.abs(eb) / np.degrees(rp.sigma_bearing[ok])
    return {"pairs": int(len(i)), "informative": int(ok.sum()),
            "heading error median |.| (deg)": float(np.median(np.abs(eh))), "heading error mean (deg)": float(eh.mean()),
            "heading error / sigma median": float(np.median(zh)),
            "bearing error median |.| (deg)": float(np.median(np.abs(eb))), "bearing error mean (deg)": float(eb.mean()),
            "bearing error / sigma median": float(np.median(zb)), "bearing within 2 sigma": float((zb <= 2).mean())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--cache", type=Path, required=True, help="refinement_guard.py's cache folder")
    ap.add_argument("--run", action="append", default=[], help="DATASET:RUN")
    ap.add_argument("--variants", default="warping,min-warping")
    a = ap.parse_args()
    variants = [v.strip() for v in a.variants.split(",") if v.strip()]
    base = dict(pc.WARP_OPTIONS)
    res = json.loads(a.out.read_text()) if a.out.exists() else {}
    for spec in a.run:
        key, d, gyro = cached_run(spec, a.cache)
        T = d["truth"]
        entry = res.get(key, {"frames": len(T), "map error (m)": {}, "closures": {}})
        first_call = None
        for v in variants:
            spy: list = []
            t = time.perf_counter()
            g = fit(d, gyro, options(v, base), spy)
            P = g.poses[:, :2]
            err = np.hypot(*(align(P, T[:, :2]).apply(P) - T[:, :2]).T)
            entry["map error (m)"][v] = {"mean": float(err.mean()), "median": float(np.median(err)),
                                         "fit (s)": time.perf_counter() - t, "misfit": g.misfit}
            first_call = first_call or spy[-1]
            print(key, v, json.dumps(entry["map error (m)"][v]), flush=True)
        for v in variants:
            entry["closures"][v] = closure_errors(first_call, T, options(v, {}))
        me = entry["map error (m)"]
        if {"warping", "min-warping"} <= set(me):
            best = "min-warping" if me["min-warping"]["misfit"] < me["warping"]["misfit"] else "warping"
            entry["choice by misfit"] = {"method": best, "map error (m)": me[best]["mean"],
                                         "misfit min-warping over warping":
                                             me["min-warping"]["misfit"] / me["warping"]["misfit"],
                                         "over the warping": me[best]["mean"] / me["warping"]["mean"]}
        res[key] = entry
        a.out.write_text(json.dumps(res, indent=1) + "\n")
    runs = [e for k, e in res.items() if isinstance(e, dict) and "choice by misfit" in e]
    if runs:
        me = [e["map error (m)"] for e in runs]
        gm = lambda r: float(np.exp(np.mean(np.log(r))))  # noqa: E731
        res["summary"] = {
            "runs": len(runs),
            "min-warping over the warping, geometric mean": gm([m["min-warping"]["mean"] / m["warping"]["mean"]
                                                               for m in me]),
            "min-warping over the warping, worst": max(m["min-warping"]["mean"] / m["warping"]["mean"] for m in me),
            "choice by misfit over the warping, geometric mean": gm([e["choice by misfit"]["over the warping"]
                                                                    for e in runs]),
            "choice by misfit over the warping, worst": max(e["choice by misfit"]["over the warping"] for e in runs),
            "choice by misfit over the better method, worst": max(
                e["choice by misfit"]["map error (m)"] / min(m["warping"]["mean"], m["min-warping"]["mean"])
                for e, m in zip(runs, me)),
            "choices of the better method": sum(
                e["choice by misfit"]["map error (m)"] <= min(m["warping"]["mean"], m["min-warping"]["mean"])
                for e, m in zip(runs, me))}
        a.out.write_text(json.dumps(res, indent=1) + "\n")
        print(json.dumps(res["summary"], indent=1))


if __name__ == "__main__":
    main()
