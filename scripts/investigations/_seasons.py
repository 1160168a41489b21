"""Shared by the 6.1.2 investigation scripts (features_*.py): the route run's images by pose and season, the F1
of a match count, and a robustness predictor trained as experiment 6.1.2 trains one."""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from sfanav.data import Dataset
from sfanav.features import (RobustnessPredictor, balanced, detect, match_distances, robustness_vectors,
                             stability_labels, true_match)
from sfanav.experiments.features import GRID, MAX_SAMPLES, THRESHOLD


def route_images(run: Path, seed: int = 0) -> Callable[[int, str], np.ndarray]:
    """``image(k, season)``: the k-th pose of run ``route`` of RUN/data/thesis-6.1-seasons-seedSEED in a season."""
    ds = Dataset(Path(run) / "data" / f"thesis-6.1-seasons-seed{seed}").select(run="route")
    by = {c: np.flatnonzero(ds.conditions == c)[np.argsort(ds.frames[ds.conditions == c], kind="stable")]
          for c in np.unique(ds.conditions)}

    def image(frame: int, season: str) -> np.ndarray:
        return ds.image(int(by[season][frame]))

    return image


def f1(tp: int, fp: int, n_ref: int) -> float:
    """F1 with precision true / (true + false) and recall true / reference features kept."""
    p = tp / (tp + fp) if tp + fp else 0.0
    r = tp / n_ref if n_ref else 0.0
    return 2 * p * r / (p + r) if p + r else 0.0


def train_predictor(image: Callable[[int, str], np.ndarray], det: str, frames: Sequence[int],
                    seasons: Sequence[str], seed: int = 0,
                    vectors: Callable | None = None) -> RobustnessPredictor:
    """A predictor on the poses ``frames`` labelled over ``seasons`` (1000 features per image, stable / unstable,
    at most MAX_SAMPLES balanced samples, the experiment's grid, 5-fold CV). ``vectors(img, features)``: the
    robustness vectors (default: the library's fixed 48x48 patch)."""
    vectors = vectors or (lambda im, ft: robustness_vectors(im, ft.xy))
    X, y = [], []
    for f in frames:
        imgs = [image(f, s) for s in seasons]
        feats = [detect(im, det, 1000) for im in imgs]
        for im, ft, lab in zip(imgs, feats, stability_labels(feats, threshold=THRESHOLD)):
            keep = np.flatnonzero(lab >= 0)
            X.append(vectors(im, ft.subset(keep)))
            y.append(lab[keep])
    Xa, ya = np.vstack(X), np.concatenate(y)
    rng = np.random.default_rng(seed)
    sel = balanced(ya, rng)
    if len(sel) > MAX_SAMPLES:
        sel = np.sort(rng.choice(sel, MAX_SAMPLES, replace=False))
    return RobustnessPredictor.fit(Xa[sel], ya[sel], detector=det, grid=GRID, cv=5, seed=seed)


def gains(counts: dict, names: Sequence[str], queries: Sequence[str]) -> dict:
    """``{"name/query": {gain, mean_f1, f1}}`` from ``counts[(name, query)]`` (memory sizes, 3) of (true, false,
    reference kept): the mean over memory sizes of the relative F1 change over ``"response"``, in %."""
    out = {}
    for q in queries:
        base = np.array([f1(*c) for c in counts[("response", q)]])
        valid = base > 0
        for v in names:
            fv = np.array([f1(*c) for c in counts[(v, q)]])
            out[f"{v}/{q}"] = {"gain": float(np.mean((fv[valid] - base[valid]) / base[valid]) * 100),
                               "mean_f1": float(fv.mean()), "f1": fv.tolist()}
    return out


def count_matches(dist: np.ndarray, ref, rows: np.ndarray, query, cols: np.ndarray) -> tuple[int, int, int]:
    """(true, false, reference kept) of the mutual matches between reference features ``rows`` and query features
    ``cols``, ``dist`` the full descriptor distance matrix (true: within THRESHOLD px)."""
    pairs = match_distances(dist[np.ix_(rows, cols)], cross_check=True)
    ok = true_match(ref.subset(rows), query.subset(cols), pairs, THRESHOLD)
    return int(ok.sum()), int((~ok).sum()), len(rows)


def load_or_train(path: Path, train: Callable[[], RobustnessPredictor]) -> RobustnessPredictor:
    """The predictor saved at ``path``, or ``train()``'s, saved there."""
    if Path(path).exists():
        return RobustnessPredictor.load(path)
    pred = train()
    pred.save(path)
    return pred


def print_gains(res: dict, names: Sequence[str], queries: Sequence[str], width: int = 14) -> None:
    """One line per variant: gain % / mean F1 per query season of :func:`gains`' result, and the mean gain."""
    print(f"{'variant':{width}s}" + "".join(f"{q:>18s}" for q in queries) + f"{'mean gain':>11s}")
    for v in names:
        g = [res[f"{v}/{q}"]["gain"] for q in queries]
        print(f"{v:{width}s}" + "".join(f"{gi:+9.1f} / {res[f'{v}/{q}']['mean_f1']:.3f}" for gi, q in zip(g, queries))
              + f"{np.mean(g):+11.1f}", flush=True)
