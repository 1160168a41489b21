"""Estimates far outside the training positions: a regression readout (the
thesis's quadratic regression) extrapolates without bound when features leave
their training range, and reports positions kilometres (or 1e13 m) away.

:func:`distance_outside` measures how far estimates lie outside the training
positions' bounding box; :class:`ExtrapolationWarning` is what a readout warns
with when some lie farther than a margin (a fraction of the box's diagonal).
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator

import numpy as np

from .._checks import as_matrix

#: default margin: estimates farther outside the training box than this
#: fraction of its diagonal count as extrapolated
MARGIN = 0.5


class ExtrapolationWarning(UserWarning):
    """A readout's estimates lie far outside its training positions."""


def training_bounds(xy: object) -> np.ndarray:
    """The bounding box (2, d) of training positions (N, d): row 0 the
    minimum, row 1 the maximum per axis (ValueError if empty or not finite)."""
    Y = as_matrix(xy, "xy")
    if len(Y) == 0:
        raise ValueError("xy is empty")
    if not np.all(np.isfinite(Y)):
        raise ValueError("xy has non-finite values")
    return np.stack([Y.min(axis=0), Y.max(axis=0)])


def distance_outside(points: object, bounds: object) -> np.ndarray:
    """Euclidean distance (N,) of each point (N, d) from the box ``bounds``
    (2, d); 0 inside. Non-finite points are infinitely far.

    >>> distance_outside([[0.5, 0.5], [2.0, 0.0], [4.0, 5.0]], [[0, 0], [1, 1]]).tolist()
    [0.0, 1.0, 5.0]
    """
    P = np.asarray(points, dtype=np.float64)
    B = np.asarray(bounds, dtype=np.float64)
    if P.ndim != 2 or B.shape != (2, P.shape[1]):
        raise ValueError(f"points must be (N, d) and bounds (2, d), got {P.shape} and {B.shape}")
    out = np.maximum(np.maximum(B[0] - P, P - B[1]), 0.0)
    d = np.sqrt((out ** 2).sum(axis=1))
    d[~np.all(np.isfinite(P), axis=1)] = np.inf
    return d


def count_extrapolated(points: object, bounds: object, margin: float = MARGIN) -> int:
    """How many points lie farther than ``margin`` times the box's diagonal
    outside ``bounds`` (a degenerate box's diagonal counts as 1 m)."""
    B = np.asarray(bounds, dtype=np.float64)
    diag = float(np.linalg.norm(B[1] - B[0])) or 1.0
    return int(np.count_nonzero(distance_outside(points, B) > margin * diag))


def warn_extrapolated(n: int, total: int, bounds: object, margin: float, who: str) -> None:
    """Warns (:class:`ExtrapolationWarning`) that ``n`` of ``total``
    estimates of ``who`` lie outside the training box."""
    B = np.asarray(bounds, dtype=np.float64)
    box = " x ".join(f"[{lo:.3g}, {hi:.3g}]" for lo, hi in zip(B[0], B[1]))
    warnings.warn(f"{who}: {n} of {total} estimates lie more than {margin:g} x the diagonal outside the training "
                  f"positions {box}; the regression extrapolates and those estimates are not positions",
                  ExtrapolationWarning, stacklevel=3)


@contextlib.contextmanager
def quiet_extrapolation() -> Iterator[None]:
    """A context in which :class:`ExtrapolationWarning` is not shown: for
    the library's own cross-validation and resampling loops, whose held-out
    folds lie outside their training folds' box by construction (a fold at
    the run's edge) and which report errors, not positions; the counts
    (``n_extrapolated_``) are still kept.

    Example
    -------
    >>> with quiet_extrapolation():
    ...     pass
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExtrapolationWarning)
        yield
