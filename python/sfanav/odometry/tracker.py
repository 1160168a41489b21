""":class:`MapTracker`: position estimates fused with odometry by a robust
rigid fit (Huber-weighted IRLS) of the recent odometry positions to their
estimates, a filter between the metric space and navigation."""

from __future__ import annotations

from typing import Any

import numpy as np


def rigid_fit(P: np.ndarray, Q: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``Rot`` (2, 2) and translation ``t`` minimising
    ``sum w |Rot p + t - q|^2`` over rows of ``P``, ``Q`` (k, 2) (Umeyama
    1991 without scale; ``w`` default ones)."""
    w = np.ones(len(P)) if w is None else np.asarray(w, float)
    mp, mq = (w @ P) / w.sum(), (w @ Q) / w.sum()
    U, _, Vt = np.linalg.svd(((P - mp) * w[:, None]).T @ (Q - mq))
    D = np.diag([1.0, float(np.sign(np.linalg.det(Vt.T @ U.T))) or 1.0])
    rot = Vt.T @ D @ U.T
    return rot, mq - rot @ mp


class MapTracker:
    """Odometry-fused positions for metric features: a filter between the
    learned metric space and navigation (beyond the thesis; cf. its
    odometry fusion, 5.3.2).

    Single-image position estimates (:class:`MetricFeatures`) scatter by
    tenths of a metre and, near walls, by metres; the robot's odometry is
    precise over a few metres. At every stop :meth:`update` takes the
    cameras' odometry positions and their estimates; a rigid transform
    (rotation and translation) from the odometry frame to the map, fitted
    to the last ``window`` stops by iteratively reweighted least squares
    (weights ``min(1, huber / residual)``, ``iterations`` rounds, so a few
    far-off estimates barely pull), maps the current odometry positions into
    the map, and these replace the estimates' x, y. Until the cameras'
    odometry positions in the window span ``min_spread`` metres along x or
    y the estimates pass through unchanged (two cameras 0.7 m apart span
    the default 0.5 m from the first stop on; the fit then keeps their
    estimates' mean and direction at the baseline's length).

    ``Navigator(..., tracker=MapTracker())`` applies it to every stop's
    features (their first two outputs must be x, y in metres) before the
    cost; the navigator calls :meth:`reset` at the start of every run.
    """

    def __init__(self, window: int = 20, *, min_spread: float = 0.5, huber: float = 0.6, iterations: int = 3) -> None:
        if isinstance(window, bool) or int(window) != window or int(window) < 2:
            raise ValueError(f"window must be an integer >= 2 stops, got {window!r}")
        for nm, v in (("min_spread", min_spread), ("huber", huber)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{nm} must be a positive number of metres, got {v}")
        if isinstance(iterations, bool) or int(iterations) != iterations or int(iterations) < 1:
            raise ValueError(f"iterations must be a positive integer, got {iterations!r}")
        self.window, self.min_spread, self.huber, self.iterations = int(window), float(min_spread), float(huber), int(iterations)
        self.reset()

    def reset(self) -> None:
        self._odo: list[np.ndarray] = []
        self._est: list[np.ndarray] = []

    def update(self, odometry: Any, features: Any) -> np.ndarray:
        """``odometry`` (k, 2): the cameras' positions by odometry (m);
        ``features`` (k, m >= 2): their features, x, y first. Returns the
        features with x, y replaced by the fused positions (a copy)."""
        P = np.array(odometry, dtype=float, ndmin=2)
        if P.ndim != 2 or P.shape[1] != 2:
            raise ValueError(f"odometry must be (k, 2) positions in metres, got shape {P.shape}")
        F = np.array(features, dtype=float, ndmin=2)
        if F.shape[0] != len(P) or F.shape[1] < 2:
            raise ValueError(f"features must be ({len(P)}, >= 2) with x, y first, got shape {F.shape}")
        if not (np.isfinite(P).all() and np.isfinite(F[:, :2]).all()):
            raise ValueError("odometry or position estimates contain NaN or inf")
        self._odo.append(P)
        self._est.append(F[:, :2].copy())
        del self._odo[: -self.window], self._est[: -self.window]
        A, B = np.concatenate(self._odo), np.concatenate(self._est)
        if float(np.ptp(A, axis=0).max()) < self.min_spread:
            return F
        w = np.ones(len(A))
        for _ in range(self.iterations):
            rot, t = rigid_fit(A, B, w)
            r = np.hypot(*(A @ rot.T + t - B).T)
            w = np.minimum(1.0, self.huber / np.maximum(r, 1e-12))
        F[:, :2] = P @ rot.T + t
        return F
