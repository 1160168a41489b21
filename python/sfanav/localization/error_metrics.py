"""Localization error metrics and trajectory alignment (thesis 5.1, 5.2).

* :func:`localization_metrics`: MAE per axis in metres and in % of the
  coordinate range (thesis 5.1), MED (mean Euclidean distance, thesis 5.2-5.4),
  RMSE, median and percentiles of the Euclidean error.
* :func:`align`: least-squares rigid or similarity alignment (Umeyama 1991) of
  an estimated trajectory to ground truth, with an optional allowed scale
  range for scale-free estimates (monocular SLAM, unsupervised metric
  learning; thesis 5.2: "we perform the fitting over a predefined scale
  range").

All positions are arrays of shape (N, d), d = 2 (x, y) in metres unless said
otherwise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_matrix, check_same_length


def _pair(xy_pred: Any, xy_true: Any) -> tuple[np.ndarray, np.ndarray]:
    p = as_matrix(xy_pred, "xy_pred")
    t = as_matrix(xy_true, "xy_true")
    check_same_length(p, t, "xy_pred", "xy_true")
    if p.shape[1] != t.shape[1]:
        raise ValueError(f"xy_pred has {p.shape[1]} columns but xy_true has {t.shape[1]}")
    return p, t


def euclidean_errors(xy_pred: Any, xy_true: Any) -> np.ndarray:
    """Euclidean distance of each estimate from ground truth, shape (N,), metres."""
    p, t = _pair(xy_pred, xy_true)
    return np.linalg.norm(p - t, axis=1)


def med(xy_pred: Any, xy_true: Any) -> float:
    """Mean Euclidean distance from ground truth (the thesis's MED), metres."""
    return float(euclidean_errors(xy_pred, xy_true).mean())


def mae(xy_pred: Any, xy_true: Any) -> np.ndarray:
    """Mean absolute error per axis, shape (d,), metres."""
    p, t = _pair(xy_pred, xy_true)
    return np.abs(p - t).mean(axis=0)


def _range(t: np.ndarray, coordinate_range: Any) -> np.ndarray:
    if coordinate_range is None:
        rng = t.max(axis=0) - t.min(axis=0)
    else:
        rng = np.broadcast_to(np.asarray(coordinate_range, dtype=np.float64), (t.shape[1],)).copy()
    if not np.all(np.isfinite(rng)) or np.any(rng <= 0):
        raise ValueError(
            f"the coordinate range must be positive on every axis, got {rng}; with a single "
            "ground-truth position (or a straight line along one axis) pass coordinate_range"
        )
    return rng


def mae_percent(xy_pred: Any, xy_true: Any, coordinate_range: Any = None) -> np.ndarray:
    """Mean absolute error per axis in percent of the coordinate range (thesis
    5.1.1: "relative to the coordinate range of the test run").

    Parameters
    ----------
    coordinate_range : float or array of shape (d,), optional
        Range per axis in metres; default ``max - min`` of ``xy_true``.
    """
    p, t = _pair(xy_pred, xy_true)
    return 100.0 * np.abs(p - t).mean(axis=0) / _range(t, coordinate_range)


def localization_metrics(
    xy_pred: Any,
    xy_true: Any,
    *,
    coordinate_range: Any = None,
    percentiles: Sequence[float] = (50, 90, 95),
) -> dict[str, float]:
    """All localization metrics of one set of estimates.

    Parameters
    ----------
    xy_pred, xy_true : array of shape (N, 2)
        Estimated and true positions, metres.
    coordinate_range : float or array of shape (2,), optional
        Range per axis for the relative MAE; default ``max - min`` of ``xy_true``.
    percentiles : sequence of float
        Percentiles of the Euclidean error to report.

    Returns
    -------
    dict
        ``med`` (mean Euclidean distance, m), ``rmse`` (root mean squared
        Euclidean error, m), ``mae_x``/``mae_y`` (m), ``mae_x_pct``/``mae_y_pct``
        (% of the range), ``std_x``/``std_y`` (standard deviation of the
        absolute error per axis, m), ``p50``, ``p90``, ... (percentiles of the
        Euclidean error, m), ``max`` (m) and ``n`` (number of estimates).
        Axes beyond the second are named ``z``, then ``axis3``, ...
    """
    p, t = _pair(xy_pred, xy_true)
    err = np.linalg.norm(p - t, axis=1)
    absd = np.abs(p - t)
    rng = _range(t, coordinate_range)
    out: dict[str, float] = {"n": int(len(p)), "med": float(err.mean()), "rmse": float(np.sqrt((err**2).mean()))}
    names = ["x", "y", "z"] + [f"axis{i}" for i in range(3, p.shape[1])]
    for i in range(p.shape[1]):
        out[f"mae_{names[i]}"] = float(absd[:, i].mean())
        out[f"mae_{names[i]}_pct"] = float(100.0 * absd[:, i].mean() / rng[i])
        out[f"std_{names[i]}"] = float(absd[:, i].std())
    for q in percentiles:
        if not 0 <= q <= 100:
            raise ValueError(f"percentiles must be in [0, 100], got {q}")
        out[f"p{q:g}"] = float(np.percentile(err, q))
    out["max"] = float(err.max())
    return out


@dataclass(frozen=True)
class Alignment:
    """A similarity transform ``y = scale * rotation @ x + translation``.

    Attributes
    ----------
    rotation : ndarray of shape (d, d)
        Orthogonal; determinant +1 unless a reflection was allowed and chosen.
    translation : ndarray of shape (d,)
        Metres (in the reference frame).
    scale : float
        1.0 for a rigid alignment.
    kind : str
        ``"rigid"`` or ``"similarity"``.
    scale_clipped : bool
        True if the unconstrained optimal scale lay outside the allowed range
        and was clipped to it.
    rmse : float
        Root mean squared Euclidean residual of the aligned estimate, metres.
    """

    rotation: np.ndarray
    translation: np.ndarray
    scale: float = 1.0
    kind: str = "rigid"
    scale_clipped: bool = False
    rmse: float = field(default=float("nan"))

    def apply(self, points: Any) -> np.ndarray:
        """Transforms points (N, d) of the estimate's frame into the reference frame."""
        pts = as_matrix(points, "points", n_cols=self.rotation.shape[0], min_rows=0)
        return self.scale * pts @ self.rotation.T + self.translation

    @property
    def angle_deg(self) -> float:
        """Rotation angle in degrees (2-D alignments only)."""
        if self.rotation.shape != (2, 2):
            raise ValueError("angle_deg is defined for 2-D alignments only")
        return float(np.degrees(np.arctan2(self.rotation[1, 0], self.rotation[0, 0])))

    def matrix(self) -> np.ndarray:
        """The homogeneous (d + 1, d + 1) matrix of the transform."""
        d = self.rotation.shape[0]
        m = np.eye(d + 1)
        m[:d, :d] = self.scale * self.rotation
        m[:d, d] = self.translation
        return m


def align(
    estimate: Any,
    reference: Any,
    *,
    scale: bool | tuple[float, float] = False,
    allow_reflection: bool = False,
) -> Alignment:
    """Least-squares alignment of an estimated trajectory to the reference
    (Umeyama 1991): finds ``s, R, t`` minimising
    ``sum_i || reference_i - (s R estimate_i + t) ||^2``.

    Parameters
    ----------
    estimate, reference : array of shape (N, d)
        Corresponding points (d = 2 or 3; N >= d).
    scale : bool or (min, max)
        False: rigid (s = 1). True: similarity with the optimal scale. A
        ``(min, max)`` pair: similarity with the scale restricted to that
        range (for estimates whose scale is unknown but bounded, thesis 5.2).
        For a fixed rotation the cost is a convex quadratic in ``s`` and the
        optimal rotation does not depend on ``s`` (> 0), so the constrained
        optimum is the unconstrained one clipped to the range.
    allow_reflection : bool
        Allow an improper rotation (det R = -1), e.g. for unsupervised
        estimates that may come out mirrored. Default False.

    Returns
    -------
    Alignment
        Use ``alignment.apply(estimate)`` for the aligned trajectory.
    """
    src = as_matrix(estimate, "estimate")
    dst = as_matrix(reference, "reference")
    check_same_length(src, dst, "estimate", "reference")
    n, d = src.shape
    if dst.shape[1] != d:
        raise ValueError(f"estimate has {d} columns but reference has {dst.shape[1]}")
    if n < 2:
        raise ValueError(f"alignment needs at least 2 point pairs, got {n}")
    lo_hi: tuple[float, float] | None = None
    if isinstance(scale, (tuple, list)):
        if len(scale) != 2:
            raise ValueError(f"scale must be a bool or a (min, max) pair, got {scale!r}")
        lo, hi = float(scale[0]), float(scale[1])
        if not (0 < lo <= hi and np.isfinite(hi)):
            raise ValueError(f"the scale range must satisfy 0 < min <= max < inf, got {scale!r}")
        lo_hi = (lo, hi)
    elif not isinstance(scale, (bool, np.bool_)):
        raise TypeError(f"scale must be a bool or a (min, max) pair, got {type(scale).__name__}")
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    xs, xd = src - mu_s, dst - mu_d
    var_s = float((xs**2).sum() / n)
    if var_s <= 1e-300:
        raise ValueError("the estimate is a single point repeated: no rotation or scale can be fitted")
    cov = xd.T @ xs / n
    U, D, Vt = np.linalg.svd(cov)
    S = np.ones(d)
    if not allow_reflection and np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[-1] = -1.0
    R = U @ np.diag(S) @ Vt
    clipped = False
    if scale is False or scale is np.False_:
        s, kind = 1.0, "rigid"
    else:
        s, kind = float((D * S).sum() / var_s), "similarity"
        if lo_hi is not None:
            c = float(np.clip(s, *lo_hi))
            clipped, s = c != s, c
        elif s <= 0:
            raise ValueError("the optimal scale is not positive: the estimate does not resemble the reference")
    t = mu_d - s * R @ mu_s
    res = dst - (s * src @ R.T + t)
    rmse = float(np.sqrt((res**2).sum(axis=1).mean()))
    return Alignment(rotation=R, translation=t, scale=s, kind=kind, scale_clipped=clipped, rmse=rmse)
