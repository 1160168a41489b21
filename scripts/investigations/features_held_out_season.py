#!/usr/bin/env python3
"""6.1.2: the robustness filter on a query season the predictor never saw (docs/experiments.md, 6.1.2; issue 25).

Trains three predictors on loop poses 0..79 of run ``route`` (as experiment 6.1.2: 1000 features per image,
stable / unstable over the training seasons, 4000 balanced samples, the experiment's grid, 5-fold CV): without the
query season but with winter (``noq+winter``), without the query season and without winter (``noq``: the thesis's
seasons minus the query), and the experiment's ``main`` (spring, summer, autumn). On poses 80..159 (every
``--step``-th), spring the reference and QUERY the query, it prints the mean relative F1 gain (%) over keeping the m
strongest keypoints on both sides, memory sizes 5..2000, for these selections (pool in multiples of m):

* ``both-r4``: the most robust of 4 m on the reference and the query (sfanav's default);
* ``ref-r4`` / ``q-r4``: the same on the reference only / the query only (the other side keeps its m strongest);
* ``both-rs1.5``, ``both-r1.5``: rank-sum / most robust of 1.5 m on both sides;
* ``ref-r4/q-rs1.5``: most robust of 4 m on the reference, rank-sum of 1.5 m on the query.

``--no-hue`` zeroes the 18 hue bins of every robustness vector (texture only), to see whether the colours of an
unseen season are what misleads the predictor.

    PYTHONPATH=python python3 scripts/investigations/features_held_out_season.py runs/f612c \
        [--detector fast-brief] [--query autumn] [--step 2] [--no-hue]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from sfanav.data import Dataset
from sfanav.features import (RobustnessPredictor, balanced, descriptor_distances, detect, match_distances,
                             robustness_vectors, select_ranked, stability_labels, true_match)
from sfanav.experiments.features import GRID, MAX_SAMPLES, MEMORY, THRESHOLD

SEASONS = ("spring", "summer", "autumn", "winter")
RULES = {"resp": (None, None), "both-r4": (("robust", 4), ("robust", 4)), "ref-r4": (("robust", 4), None),
         "q-r4": (None, ("robust", 4)), "both-rs1.5": (("rank-sum", 1.5), ("rank-sum", 1.5)),
         "both-r1.5": (("robust", 1.5), ("robust", 1.5)), "ref-r4/q-rs1.5": (("robust", 4), ("rank-sum", 1.5))}


def f1(tp: int, fp: int, n: int) -> float:
    p = tp / (tp + fp) if tp + fp else 0.0
    r = tp / n if n else 0.0
    return 2 * p * r / (p + r) if p + r else 0.0


def kept(rule, s: np.ndarray, m: int) -> np.ndarray:
    return np.arange(min(len(s), m)) if rule is None else select_ranked(s, m, candidates=rule[1], method=rule[0])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("run", type=Path)
    ap.add_argument("--detector", default="fast-brief")
    ap.add_argument("--query", default="autumn", choices=("summer", "autumn"))
    ap.add_argument("--step", type=int, default=2)
    ap.add_argument("--no-hue", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    ds = Dataset(a.run / "data" / f"thesis-6.1-seasons-seed{a.seed}").select(run="route")
    by = {c: np.flatnonzero(ds.conditions == c)[np.argsort(ds.frames[ds.conditions == c], kind="stable")]
          for c in np.unique(ds.conditions)}

    def image(f: int, s: str) -> np.ndarray:
        return ds.image(int(by[s][f]))

    def vectors(im: np.ndarray, xy: np.ndarray) -> np.ndarray:
        v = robustness_vectors(im, xy)
        if a.no_hue:
            v[:, 59:] = 0.0
        return v

    other = "summer" if a.query == "autumn" else "autumn"
    sets = {"noq+winter": ("spring", other, "winter"), "noq": ("spring", other), "main": ("spring", "summer", "autumn")}
    labelled = []
    for f in range(80):
        ims = [image(f, s) for s in SEASONS]
        ft = [detect(im, a.detector, 1000) for im in ims]
        labelled.append((ft, [vectors(im, x.xy) for im, x in zip(ims, ft)]))
    preds = {}
    for name, seasons in sets.items():
        X, y = [], []
        idx = [SEASONS.index(s) for s in seasons]
        for ft, vec in labelled:
            for i, lab in zip(idx, stability_labels([ft[i] for i in idx], threshold=THRESHOLD)):
                keep = lab >= 0
                X.append(vec[i][keep])
                y.append(lab[keep])
        Xa, ya = np.vstack(X), np.concatenate(y)
        rng = np.random.default_rng(a.seed)
        sel = balanced(ya, rng)
        if len(sel) > MAX_SAMPLES:
            sel = np.sort(rng.choice(sel, MAX_SAMPLES, replace=False))
        preds[name] = RobustnessPredictor.fit(Xa[sel], ya[sel], detector=a.detector, grid=GRID, cv=5, seed=a.seed)
        print(f"predictor {name} ({', '.join(seasons)}): CV accuracy {preds[name].info['cv_accuracy']:.3f}", flush=True)
    counts = {(p, r): np.zeros((len(MEMORY), 3), int) for p in preds for r in RULES}
    for f in range(80, 160, a.step):
        ri, qi = image(f, "spring"), image(f, a.query)
        ref, qf = detect(ri, a.detector, 4 * max(MEMORY)), detect(qi, a.detector, 4 * max(MEMORY))
        D = descriptor_distances(ref, qf)
        vr, vq = vectors(ri, ref.xy), vectors(qi, qf.xy)
        for p, pred in preds.items():
            sr, sq = pred.decision_function(vr), pred.decision_function(vq)
            for mi, m in enumerate(MEMORY):
                for r, (rule_ref, rule_q) in RULES.items():
                    i, j = kept(rule_ref, sr, m), kept(rule_q, sq, m)
                    pairs = match_distances(D[np.ix_(i, j)], cross_check=True)
                    ok = true_match(ref.subset(i), qf.subset(j), pairs, THRESHOLD)
                    counts[(p, r)][mi] += (int(ok.sum()), int((~ok).sum()), len(i))
    print(f"\n{a.detector}, {a.query} to spring{' (no hue)' if a.no_hue else ''}: mean F1 gain % over the m strongest")
    for p in preds:
        base = np.array([f1(*c) for c in counts[(p, "resp")]])
        print(f"{p:11s} " + "  ".join(
            f"{r} {np.mean((np.array([f1(*c) for c in counts[(p, r)]]) - base) / base) * 100:+.1f}"
            for r in RULES if r != "resp"), flush=True)


if __name__ == "__main__":
    main()
