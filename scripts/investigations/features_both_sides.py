#!/usr/bin/env python3
"""6.1.2: the robustness filter on the map only (the thesis) or on the map and the query (docs/experiments.md,
6.1.2; issue 25).

The thesis selects the reference (map) features by predicted robustness and keeps the query's m strongest. This
script measures, for a memory of m features, which reference / query selections gain over keeping the m strongest
on both sides:

* ``ref-V-C``: the reference by variant V among its C m strongest, the query's m strongest (the thesis's protocol;
  ``ref-robust-1.5`` is the thesis's rule, ``ref-ranksum-1.5`` sfanav's selection before this study);
* ``both-V-C``: reference and query each by variant V among their C m strongest, scored by the same predictor;
* ``oracle-ref`` / ``oracle-both``: the ``robust-1.5`` rule with a perfect stability label instead of the SVM
  (stable: matched, ratio test 0.75, within 10 px, in both summer and autumn for the reference; in spring for a
  query) - how much any predictor could gain under each protocol.

V is ``ranksum`` (smallest rank by response + rank by SVM score) or ``robust`` (largest SVM score).
Splits as scripts/investigations/features_selection_variants.py: *validation* (predictor trained on loop poses
0..39, scored on 40..79), *test* (the experiment's predictor RUN/6.1.2-predictor-DET.json, poses 80..159).

    PYTHONPATH=python python3 scripts/investigations/features_both_sides.py runs/f612c \
        [--detectors fast-brief,sift] [--split validation,test] [--step 1] [--pools 1.25,1.5,2,3] [--tag T]

Writes RUN/both-sides/DET-SPLIT[T].json and prints gain % (mean F1) per query season.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from _seasons import count_matches, gains, load_or_train, print_gains, route_images, train_predictor
from sfanav.features import descriptor_distances, detect, match, select_ranked
from sfanav.features.detectors import pixel_distance
from sfanav.experiments.features import MEMORY, THRESHOLD

QUERIES = ("summer", "autumn", "winter")
TRAIN_SEASONS = ("spring", "summer", "autumn")
POOLS = (1.25, 1.5, 2.0, 3.0)


def variants(pools=POOLS) -> list[str]:
    return (["response", "ref-robust-1.5", "ref-ranksum-1.5"]
            + [f"both-{v}-{c:g}" for v in ("ranksum", "robust") for c in pools] + ["oracle-ref", "oracle-both"])



def train(image, det, frames, seed):
    return train_predictor(image, det, frames, TRAIN_SEASONS, seed)


def matched_in(a, b):
    """Which features of ``a`` have a ratio-test match in ``b`` within THRESHOLD px."""
    pairs = match(a, b, cross_check=False, ratio=0.75)
    ok = pixel_distance(a.xy[pairs[:, 0]], b.xy[pairs[:, 1]], a.width) <= THRESHOLD
    out = np.zeros(len(a), bool)
    out[pairs[ok, 0]] = True
    return out


def pick(variant: str, s: np.ndarray, m: int, side: str) -> np.ndarray:
    """Indices (into response-sorted features with scores ``s``) that ``variant`` keeps on ``side``."""
    if variant == "response" or (variant.startswith("ref-") and side == "query"):
        return np.arange(min(len(s), m))
    if variant.startswith("oracle"):
        if side == "query" and variant == "oracle-ref":
            return np.arange(min(len(s), m))
        return select_ranked(s, m, candidates=1.5, method="robust")
    _, how, c = variant.split("-")
    return select_ranked(s, m, candidates=float(c), method="rank-sum" if how == "ranksum" else "robust")


def evaluate(image, det, frames, pred, names, pools):
    nd = int(np.ceil(max(pools + (1.5,)) * max(MEMORY)))
    counts = {(v, q): np.zeros((len(MEMORY), 3), int) for v in names for q in QUERIES}
    for f in frames:
        ri = image(f, "spring")
        ref = detect(ri, det, nd)
        s_ref = pred.score_keypoints(ri, ref)
        qi = {q: image(f, q) for q in QUERIES}
        qf = {q: detect(qi[q], det, nd) for q in QUERIES}
        s_q = {q: pred.score_keypoints(qi[q], qf[q]) for q in QUERIES}
        # perfect labels (+ a small SVM tie-break): reference stable in summer and autumn, a query in spring
        ref1000 = detect(ri, det, 1000)
        o_ref = (matched_in(ref, detect(qi["summer"], det, 1000)) & matched_in(ref, detect(qi["autumn"], det, 1000))
                 ) + 1e-3 * np.tanh(s_ref)
        o_q = {q: matched_in(qf[q], ref1000) + 1e-3 * np.tanh(s_q[q]) for q in QUERIES}
        dist = {q: descriptor_distances(ref, qf[q]) for q in QUERIES}
        for mi, m in enumerate(MEMORY):
            for v in names:
                oracle = v.startswith("oracle")
                rows = pick(v, o_ref if oracle else s_ref, m, "reference")
                for q in QUERIES:
                    cols = pick(v, o_q[q] if oracle else s_q[q], m, "query")
                    counts[(v, q)][mi] += count_matches(dist[q], ref, rows, qf[q], cols)
    return gains(counts, names, QUERIES)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("run", type=Path)
    ap.add_argument("--detectors", default="fast-brief,sift")
    ap.add_argument("--split", default="validation,test")
    ap.add_argument("--step", type=int, default=1, help="every STEP-th pose of the split (1)")
    ap.add_argument("--pools", default=",".join(f"{c:g}" for c in POOLS),
                    help="candidate pools of the both-sides variants, multiples of m (1.25,1.5,2,3)")
    ap.add_argument("--tag", default="", help="suffix of the output JSON names")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    pools = tuple(float(c) for c in a.pools.split(","))
    names = variants(pools)
    image = route_images(a.run, a.seed)
    outdir = a.run / "both-sides"
    outdir.mkdir(exist_ok=True)
    for det in a.detectors.split(","):
        for split in a.split.split(","):
            t0 = time.time()
            if split == "validation":
                path = outdir / f"predictor-{det}-0-39.json"
                train_f, test_f = np.arange(40), np.arange(40, 80)
            else:
                path = a.run / f"6.1.2-predictor-{det}.json"
                train_f, test_f = np.arange(80), np.arange(80, 160)
            pred = load_or_train(path, lambda: train(image, det, train_f, a.seed))
            res = evaluate(image, det, test_f[::a.step], pred, names, pools)
            doc = {"detector": det, "split": split, "train_poses": [int(train_f[0]), int(train_f[-1])],
                   "eval_poses": test_f[::a.step].tolist(), "cv_accuracy": pred.info.get("cv_accuracy"),
                   "memory": list(MEMORY), "results": res, "seconds": round(time.time() - t0, 1)}
            (outdir / f"{det}-{split}{a.tag}.json").write_text(json.dumps(doc, indent=1))
            print(f"\n{det}, {split} (train {train_f[0]}..{train_f[-1]}, eval {test_f[0]}..{test_f[-1]} step "
                  f"{a.step}, CV {pred.info.get('cv_accuracy', float('nan')):.3f}, {time.time() - t0:.0f} s): "
                  "gain % / mean F1")
            print_gains(res, names, QUERIES, 18)


if __name__ == "__main__":
    main()
