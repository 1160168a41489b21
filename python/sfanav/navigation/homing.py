"""Homing by perfect memory: the standard of insect-inspired navigation, as
the peer of navigation on slow features.

The robot keeps the target's panorama and descends the **rotational image
difference** between what its cameras see and that view (Zeil, Hofmann and
Chahl 2003): the root-mean-square pixel difference at the best relative
rotation, which in an open scene grows smoothly with the distance from the
place the view was taken. It needs no training, stores one image per goal
and is what :class:`sfanav.localization.baselines.PerfectMemory` compares
for localization.

* :class:`PanoramaFeatures`: the rendered panoramas themselves as the
  :class:`~sfanav.navigation.Navigator`'s features, (k, R * W) with the
  colour channels as extra rows, so that a rotation is a roll of columns;
* :class:`RotationalImageDifferenceCost` / :func:`image_difference_cost`:
  the cost, for the navigator's ``cost=``.

Example
-------
>>> feats = PanoramaFeatures(renderer, camera)                        # doctest: +SKIP
>>> navi = Navigator(sim, feats, RobustDescent(), n_outputs=1,
...                  cost=image_difference_cost(feats.width))         # doctest: +SKIP
>>> navi.run(start, target).success                                   # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .cost import SlowFeatureCost
from .features import ImageFeatures


def rotational_image_difference(images: Any, target: Any) -> np.ndarray:
    """RMS difference of each image (k, R, W) to ``target`` (R, W) at the
    column roll of the target that matches it best: ``min_d sqrt(mean((q -
    roll(target, d, axis=-1))^2))``, computed for every roll at once by FFT
    cross-correlation. Returns (k,)."""
    Q = np.asarray(images, dtype=np.float64)
    T = np.asarray(target, dtype=np.float64)
    if Q.ndim != 3 or Q.shape[1:] != T.shape:
        raise ValueError(f"images must be (k, {T.shape[0]}, {T.shape[1]}) for a target of shape {T.shape}, "
                         f"got {Q.shape}")
    W = T.shape[1]
    corr = np.fft.irfft(np.fft.rfft(Q, axis=2) * np.conj(np.fft.rfft(T, axis=1))[None], n=W, axis=2).sum(axis=1)
    sq = (Q**2).sum(axis=(1, 2))[:, None] + float((T**2).sum()) - 2.0 * corr  # (k, W): every roll
    return np.sqrt(np.maximum(sq.min(axis=1), 0.0) / T.size)


class PanoramaFeatures(ImageFeatures):
    """Rendered panoramas as navigation features: ``features(poses (k, 3))
    -> (k, R * W)`` float, the image (H, W[, C]) at each camera pose with
    its channels as extra rows (R = H * C), flattened. ``normalize``:
    zero mean and unit variance per image (invariant to a global
    brightness change). ``width`` is W; ``images`` counts the images
    rendered."""

    def __init__(self, renderer: Any, camera: Any, *, lighting: Any = None, rows: Any = None,
                 normalize: bool = False) -> None:
        super().__init__(None, renderer, camera, lighting=lighting, rows=rows)
        self.normalize = bool(normalize)
        self.width = int(camera.width)

    def __call__(self, poses: Any) -> np.ndarray:
        imgs = self.render(poses)
        if self.rows is not None:
            imgs = self.rows(imgs)
        a = np.asarray(imgs, dtype=np.float32)
        if a.ndim == 4:
            a = np.moveaxis(a, 3, 2)  # (k, H, C, W): channels become rows
        flat = a.reshape(len(a), -1)
        if self.normalize:
            sd = flat.std(axis=1, keepdims=True)
            flat = (flat - flat.mean(axis=1, keepdims=True)) / np.where(sd > 0, sd, 1.0)
        return flat


class RotationalImageDifferenceCost(SlowFeatureCost):
    """The navigator's cost of a place: the rotational image difference
    between its panorama and the target's (:func:`rotational_image_difference`),
    in the images' units (grey levels, or standard deviations with
    ``PanoramaFeatures(normalize=True)``).

    ``target``: the target's :class:`PanoramaFeatures` (R * W,); ``width``:
    W. Calling it on features (..., R * W) returns costs (...);
    :meth:`residuals` gives the cost as the one residual the navigator's
    gradient and Gauss-Newton steps read. ValueError for a target whose
    length is not a multiple of ``width``."""

    def __init__(self, target: Any, width: int) -> None:
        t = np.asarray(target, dtype=np.float64).ravel()
        w = int(width)
        if w < 1 or len(t) == 0 or len(t) % w or not np.isfinite(t).all():
            raise ValueError(f"target must be a finite panorama of {w}-column rows, got {len(t)} values")
        self.image = t.reshape(-1, w)
        self.n, self.target, self.weights = 1, np.zeros(1), None

    def __call__(self, features: Any) -> np.ndarray:
        F = np.asarray(features, dtype=np.float64)
        lead = F.shape[:-1]
        if F.shape[-1] != self.image.size:
            raise ValueError(f"features have {F.shape[-1]} values, the target panorama {self.image.size}")
        return rotational_image_difference(F.reshape((-1,) + self.image.shape), self.image).reshape(lead)

    def residuals(self, features: Any) -> np.ndarray:
        """(k, 1): the cost of each of k feature rows."""
        return self(features).reshape(-1, 1)


def image_difference_cost(width: int) -> Callable[..., RotationalImageDifferenceCost]:
    """A :class:`~sfanav.navigation.Navigator` ``cost=`` factory:
    ``cost(target_features, n_outputs, weights)`` -> the rotational image
    difference to the target's panorama (``n_outputs`` and ``weights`` do
    not apply)."""

    def make(target_features: Any, n_outputs: int = 1, weights: Any = None) -> RotationalImageDifferenceCost:
        return RotationalImageDifferenceCost(target_features, width)

    return make
