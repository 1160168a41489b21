"""Shared by the 6.1.2 investigation scripts (features_*.py): the route run's images by pose and season, the F1
of a match count, and a robustness predictor trained as experiment 6.1.2 trains one."""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from sfanav.data import Dataset
from sfanav.features import RobustnessPredictor, balanced, detect, robustness_vectors, stability_labels
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
