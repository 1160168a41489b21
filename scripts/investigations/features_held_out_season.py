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
from _seasons import count_matches, f1, route_images, train_predictor
from sfanav.features import descriptor_distances, detect, robustness_vectors, select_ranked
from sfanav.experiments.features import MEMORY

RULES = {"resp": (None, None), "both-r4": (("robust", 4), ("robust", 4)), "ref-r4": (("robust", 4), None),
         "q-r4": (None, ("robust", 4)), "both-rs1.5": (("rank-sum", 1.5), ("rank-sum", 1.5)),
         "both-r1.5": (("robust", 1.5), ("robust", 1.5)), "ref-r4/q-rs1.5": (("robust", 4), ("rank-sum", 1.5))}


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
    image = route_images(a.run, a.seed)

    def vectors(im: np.ndarray, xy: np.ndarray) -> np.ndarray:
        v = robustness_vectors(im, xy)
        if a.no_hue:
            v[:, 59:] = 0.0
        return v

    other = "summer" if a.query == "autumn" else "autumn"
    sets = {"noq+winter": ("spring", other, "winter"), "noq": ("spring", other), "main": ("spring", "summer", "autumn")}
    preds = {}
    for name, seasons in sets.items():
        preds[name] = train_predictor(image, a.detector, range(80), seasons, a.seed,
                                      vectors=lambda im, ft: vectors(im, ft.xy))
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
                    counts[(p, r)][mi] += count_matches(D, ref, i, qf, j)
    print(f"\n{a.detector}, {a.query} to spring{' (no hue)' if a.no_hue else ''}: mean F1 gain % over the m strongest")
    for p in preds:
        base = np.array([f1(*c) for c in counts[(p, "resp")]])
        print(f"{p:11s} " + "  ".join(
            f"{r} {np.mean((np.array([f1(*c) for c in counts[(p, r)]]) - base) / base) * 100:+.1f}"
            for r in RULES if r != "resp"), flush=True)


if __name__ == "__main__":
    main()
