"""Navigation costs (thesis 7.1, 7.2.1): :class:`SlowFeatureCost`, the
Euclidean distance between the current and the target's first ``n`` slow
features, optionally weighted by ``1 / beta`` (:func:`beta_weights`);
:class:`ScaledCost`, a cost divided by the exploration run's spread
(:func:`run_spread`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np


def as_vector2(v: Any, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.shape != (2,) or not np.isfinite(a).all():
        raise ValueError(f"{name} must be a finite (x, y) pair, got {v!r}")
    return a


def beta_weights(beta: Any, *, relative: bool = False) -> np.ndarray:
    """Weights ``1 / beta`` of the slow-feature outputs (thesis 7.2.1): slower
    outputs (smaller beta) count more. ``relative=True`` scales them so the
    first weight is 1 (``beta_1 / beta_i``), which leaves the cost of the
    slowest output in its own units; the thesis's 1/beta weights equal these
    times ``1 / beta_1`` (its step scale 0.0015 for weighted outputs plays
    the role of ``beta_1``)."""
    b = np.asarray(beta, dtype=float)
    if b.ndim != 1 or len(b) == 0 or not np.isfinite(b).all() or (b <= 0).any():
        raise ValueError(f"beta must be a 1-D array of positive numbers, got {beta!r}")
    w = 1.0 / b
    return w / w[0] if relative else w


class SlowFeatureCost:
    """Cost of a place: the distance in slow-feature space from its outputs
    to the target's (thesis 7.1: ``C(f(p)) = sqrt(sum_i (f(p)_i - f(t)_i)^2)``
    over the first ``n`` outputs; 7.2.1: each output weighted by ``w_i``,
    e.g. :func:`beta_weights`).

    Parameters
    ----------
    target : array (m,)
        SFA outputs at the target (from an image taken there); the first
        ``n`` are used.
    n : int, optional
        Number of outputs (default all of ``target``).
    weights : array (>= n,), optional
        Per-output weights.

    Calling the cost on features (..., m) returns costs (...).
    """

    def __init__(self, target: Any, n: int | None = None, weights: Any = None) -> None:
        t = np.asarray(target, dtype=float).ravel()
        if len(t) == 0 or not np.isfinite(t).all():
            raise ValueError("target must be a non-empty finite vector of SFA outputs")
        n = len(t) if n is None else int(n)
        if not 1 <= n <= len(t):
            raise ValueError(f"n must be in 1..{len(t)} (the target's outputs), got {n}")
        self.n = n
        self.target = t[:n].copy()
        if weights is None:
            self.weights = None
        else:
            w = np.asarray(weights, dtype=float).ravel()
            if len(w) < n or not np.isfinite(w[:n]).all() or (w[:n] < 0).any():
                raise ValueError(f"weights must hold at least {n} non-negative finite numbers")
            self.weights = w[:n].copy()

    def __call__(self, features: Any) -> np.ndarray:
        f = np.asarray(features, dtype=float)
        if f.shape[-1] < self.n:
            raise ValueError(f"features have {f.shape[-1]} outputs, the cost uses {self.n}")
        d = f[..., : self.n] - self.target
        if self.weights is not None:
            d = d * self.weights
        return np.sqrt(np.sum(d * d, axis=-1))


def run_spread(positions: Any) -> float:
    """The spread (m) of an exploration run's positions (N, 2): the RMS of
    their standard deviations along x and y. SFA's outputs have unit
    variance over the training run, so metric positions divided by this are
    on the scale of slow features (see :class:`ScaledCost`)."""
    P = np.asarray(positions, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or len(P) < 2:
        raise ValueError(f"positions must be (N >= 2, 2) metres, got shape {P.shape}")
    if not np.isfinite(P).all():
        raise ValueError("positions contain NaN or inf")
    spread = float(np.sqrt(np.mean(P.var(axis=0))))
    if not spread > 0:
        raise ValueError("the positions do not spread: all at one place")
    return spread


class ScaledCost:
    """A :class:`Navigator` ``cost=``: another cost divided by ``scale``.

    The thesis's descent rule (eta 1, gamma 0.5) was set for costs in
    slow-feature space, whose outputs have unit variance over the training
    run. On metric features (:class:`MetricFeatures`, metres) the same rule
    takes steps ``scale`` times too long; ``ScaledCost(run_spread(run_xy))``
    puts the metric cost on the slow features' scale, as if the outputs were
    the ideal x / y codes of unit variance (beyond the thesis;
    docs/navigation.md). ``cost``: the cost factory to scale
    (default :class:`SlowFeatureCost`; e.g. ``GeodesicField(run_xy).cost``)."""

    def __init__(self, scale: float, cost: Callable[..., SlowFeatureCost] | None = None) -> None:
        if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)):
            raise TypeError(f"scale must be a number, got {type(scale).__name__}")
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"scale must be a positive finite number (metres per unit), got {scale}")
        self.scale = float(scale)
        self.base = cost if cost is not None else SlowFeatureCost

    def __call__(self, target_features: Any, n_outputs: int = 2, weights: Any = None) -> SlowFeatureCost:
        return _Scaled(self.base(target_features, n_outputs, weights), self.scale)

    def __repr__(self) -> str:
        return f"ScaledCost({self.scale:.4g}, {getattr(self.base, '__qualname__', repr(self.base))})"


class _Scaled(SlowFeatureCost):
    def __init__(self, inner: SlowFeatureCost, scale: float) -> None:
        self.inner, self.scale = inner, scale
        self.n, self.target, self.weights = inner.n, inner.target, inner.weights

    def __call__(self, features: Any) -> np.ndarray:
        return np.asarray(self.inner(features), dtype=float) / self.scale
