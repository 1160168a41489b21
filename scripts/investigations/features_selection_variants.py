#!/usr/bin/env python3
"""6.1.2: how to pick the reference features to keep, beyond "the m most robust of the 1.5 m strongest"
(docs/experiments.md, 6.1.2; issue 25).

Variants, for a memory of m features (the reference's keypoints sorted by decreasing detector response, s
the SVM decision value of each):

* ``response``: the m strongest (the baseline every gain is relative to);
* ``robust-C``: the m of largest s among the C m strongest (C = 1.5 is the experiment's), ``robust-all``
  among all keypoints;
* ``ranksum-C``: among the C m strongest, the m of smallest rank by response + rank by s;
* ``product-C``: the m of largest (response / largest response) * sigmoid(s);
* ``filter-C``: the strongest among the C m strongest whose s > 0 (predicted stable), topped up by the
  strongest of the others if fewer than m.

Two splits, so that the choice does not look at the test poses: *validation*: a predictor trained (as the
experiment does, same grid, 4000 balanced samples) on loop poses 0..39, variants scored on poses 40..79;
*test*: the experiment's predictor (poses 0..79, read from ``RUN/6.1.2-predictor-DET.json``) on poses 80..159.
Spring is the reference, summer, autumn and winter the queries, F1 and gain as the experiment.

    PYTHONPATH=python python3 scripts/investigations/features_selection_variants.py /work/runs/f612b \
        [--detectors fast-brief,sift] [--split validation,test] [--patch-scale K]

``--patch-scale K`` (SIFT-style detectors only): robustness vectors on a patch of K * keypoint size pixels
resized to 48x48 (the thesis's scale-dependent window) instead of the fixed 48x48 patch; the validation
predictor is trained on such vectors, and the test split then needs a predictor trained likewise on
poses 0..79 (trained here and cached as RUN/variants/predictor-DET-scaleK-0-79.json).
Writes RUN/variants/DET-SPLIT[-scaleK].json.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from _seasons import count_matches, gains, load_or_train, print_gains, route_images, train_predictor
from sfanav.features import descriptor_distances, detect, robustness_vectors
from sfanav.experiments.features import MEMORY

VARIANTS = ["response", "robust-1.25", "robust-1.5", "robust-2", "robust-3", "robust-all", "ranksum-1.25",
            "ranksum-1.5", "ranksum-2", "ranksum-3", "ranksum-all", "product-1.5", "product-3", "product-all",
            "filter-1.5", "filter-3", "filter-all"]
QUERIES = ("summer", "autumn", "winter")
TRAIN_SEASONS = ("spring", "summer", "autumn")
ALL = 20000  # "all keypoints"


def choose(variant: str, resp: np.ndarray, s: np.ndarray, m: int) -> np.ndarray:
    """Indices (into the response-sorted reference) of the m features a variant keeps."""
    n = len(resp)
    if variant == "response":
        return np.arange(min(n, m))
    how, c = variant.split("-")
    pool = np.arange(n if c == "all" else min(n, int(np.ceil(float(c) * m))))
    sp = s[pool]
    if how == "robust":
        return pool[np.argsort(-sp, kind="stable")[:m]]
    if how == "ranksum":
        rank_s = np.empty(len(pool))
        rank_s[np.argsort(-sp, kind="stable")] = np.arange(len(pool))
        return pool[np.argsort(pool + rank_s, kind="stable")[:m]]
    if how == "product":
        v = resp[pool] / max(resp[0], 1e-12) / (1 + np.exp(-sp))
        return pool[np.argsort(-v, kind="stable")[:m]]
    if how == "filter":
        good, bad = pool[sp > 0], pool[sp <= 0]
        return np.concatenate([good, bad])[:m]
    raise ValueError(variant)


def scaled_vectors(img: np.ndarray, xy: np.ndarray, size: np.ndarray, k: float) -> np.ndarray:
    """Robustness vectors of a patch of k * size pixels around each keypoint, resized to 48x48."""
    import cv2
    from sfanav.features.detectors import pad_panorama

    out = np.zeros((len(xy), 77))
    pad = 200
    big = pad_panorama(np.ascontiguousarray(img), pad)
    for i, ((x, y), sz) in enumerate(zip(xy, size)):
        half = int(np.clip(round(k * sz / 2), 6, pad - 1))
        cx, cy = int(np.floor(x)) + pad, int(np.floor(y)) + pad
        patch = big[cy - half:cy + half, cx - half:cx + half]
        patch = cv2.resize(patch, (48, 48), interpolation=cv2.INTER_AREA if 2 * half > 48 else cv2.INTER_LINEAR)
        # the patch as a tiny "panorama": robustness_vectors of its centre (its wrap is not used: 48-px window)
        out[i] = robustness_vectors(np.pad(patch, ((8, 8), (0, 0), (0, 0)), mode="reflect"), [[24.0, 32.0]])[0]
    return out


def vectors(img, feats, scale):
    return robustness_vectors(img, feats.xy) if scale is None else scaled_vectors(img, feats.xy, feats.size, scale)


def train(image, det, frames, seed, scale):
    return train_predictor(image, det, frames, TRAIN_SEASONS, seed, vectors=lambda im, ft: vectors(im, ft, scale))


def evaluate(image, det, frames, pred, scale):
    n_detect = ALL
    counts = {(v, q): np.zeros((len(MEMORY), 3), int) for v in VARIANTS for q in QUERIES}
    for f in frames:
        ref_img = image(f, "spring")
        ref = detect(ref_img, det, n_detect)
        s = pred.decision_function(vectors(ref_img, ref, scale))
        qs = {q: detect(image(f, q), det, max(MEMORY)) for q in QUERIES}
        dist = {q: descriptor_distances(ref, qf) for q, qf in qs.items()}
        for mi, m in enumerate(MEMORY):
            kept = {v: choose(v, ref.response, s, m) for v in VARIANTS}
            for q, qf in qs.items():
                cols = np.arange(min(len(qf), m))
                for v, idx in kept.items():
                    counts[(v, q)][mi] += count_matches(dist[q], ref, idx, qf, cols)
    return gains(counts, VARIANTS, QUERIES)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("run", type=Path)
    ap.add_argument("--detectors", default="fast-brief,sift")
    ap.add_argument("--split", default="validation,test")
    ap.add_argument("--patch-scale", type=float, default=None)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    image = route_images(a.run, a.seed)
    outdir = a.run / "variants"
    outdir.mkdir(exist_ok=True)
    tag = "" if a.patch_scale is None else f"-scale{a.patch_scale:g}"
    for det in a.detectors.split(","):
        for split in a.split.split(","):
            t0 = time.time()
            if split == "validation":
                path = outdir / f"predictor-{det}{tag}-0-39.json"
                train_f, test_f = np.arange(40), np.arange(40, 80)
            else:
                path = (a.run / f"6.1.2-predictor-{det}.json" if a.patch_scale is None
                        else outdir / f"predictor-{det}{tag}-0-79.json")
                train_f, test_f = np.arange(80), np.arange(80, 160)
            pred = load_or_train(path, lambda: train(image, det, train_f, a.seed, a.patch_scale))
            res = evaluate(image, det, test_f, pred, a.patch_scale)
            doc = {"detector": det, "split": split, "train_poses": [int(train_f[0]), int(train_f[-1])],
                   "eval_poses": [int(test_f[0]), int(test_f[-1])], "patch_scale": a.patch_scale,
                   "cv_accuracy": pred.info.get("cv_accuracy"), "memory": list(MEMORY), "results": res,
                   "seconds": round(time.time() - t0, 1)}
            (outdir / f"{det}-{split}{tag}.json").write_text(json.dumps(doc, indent=1))
            print(f"\n{det}, {split} (train {train_f[0]}..{train_f[-1]}, eval {test_f[0]}..{test_f[-1]}, "
                  f"CV {pred.info.get('cv_accuracy', float('nan')):.3f}, {time.time() - t0:.0f} s): gain % / mean F1")
            print_gains(res, VARIANTS, QUERIES)


if __name__ == "__main__":
    main()
