"""Estimating the cost's gradient from two cameras (thesis 7.1.1): the
difference quotient of the left and right cameras' costs, then a plane
through the cost values of the last two stops (:class:`PlaneGradient`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .cost import as_vector2


def difference_quotient(p_left: Any, p_right: Any, c_left: float, c_right: float) -> np.ndarray:
    """Gradient estimate from two cost values (thesis 7.1.1, first step): the
    difference quotient along the baseline from the right to the left camera,
    as a vector along that baseline. Its component across the baseline is
    unknown and set to zero."""
    a, b = as_vector2(p_left, "p_left"), as_vector2(p_right, "p_right")
    d = a - b
    L2 = float(d @ d)
    if L2 <= 1e-18:
        return np.zeros(2)
    return (float(c_left) - float(c_right)) * d / L2


def plane_gradient(points: Any, costs: Any, *, weighting: str = "area") -> np.ndarray | None:
    """Slope of the plane through four cost values (thesis 7.1.1).

    For each of the four three-point combinations of the points (x, y,
    cost) the plane normal is the cross product of two edge vectors,
    oriented upwards; the normals are averaged and the gradient is the
    slope of the plane with the mean normal: ``-(n_x, n_y) / n_z``.

    Parameters
    ----------
    points : array (k, 2), k >= 3
        Measurement positions (m).
    costs : array (k,)
    weighting : ``"area"`` or ``"unit"``
        ``"area"`` averages the raw cross products (each triangle weighted by
        its area, so nearly collinear triples count little); ``"unit"``
        averages unit normals.

    Returns
    -------
    ndarray (2,), or None when all triples are (nearly) collinear.
    Exact for costs that are a plane (any weighting).
    """
    P = np.asarray(points, dtype=float)
    c = np.asarray(costs, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or len(P) < 3 or c.shape != (len(P),):
        raise ValueError(f"need points (k>=3, 2) and costs (k,), got {P.shape} and {c.shape}")
    if weighting not in ("area", "unit"):
        raise ValueError(f"weighting must be 'area' or 'unit', got {weighting!r}")
    Q = np.column_stack([P, c])
    k = len(P)
    scale = max(float(np.ptp(P, axis=0).max()), 1e-12)
    normals = []
    for i in range(k):
        for j in range(i + 1, k):
            for m in range(j + 1, k):
                n = np.cross(Q[j] - Q[i], Q[m] - Q[i])
                if abs(n[2]) <= 1e-9 * scale * scale:  # collinear in the plane
                    continue
                if n[2] < 0:
                    n = -n
                if weighting == "unit":
                    n = n / np.linalg.norm(n)
                normals.append(n)
    if not normals:
        return None
    n = np.mean(normals, axis=0)
    if n[2] <= 0:
        return None
    return -n[:2] / n[2]


class PlaneGradient:
    """The thesis's gradient estimator for a robot with two cameras (7.1.1).

    Call :meth:`update` once per stop with the two camera positions and
    their costs. The first call (and any call after which the last two
    stops give only collinear points, e.g. when the robot could not move)
    returns the difference quotient between the cameras; later calls return
    the slope of the plane fitted to the four values of the last two stops
    (:func:`plane_gradient`).

    With ``values`` (the two cameras' slow features, or their weighted
    differences to the target) the same planes are fitted to every output
    separately: ``jacobian`` (n, 2) then holds each output's gradient (the
    local linear map from metres to slow features), used by
    :class:`RobustDescent`'s Gauss-Newton step. ``last_method`` tells
    ``"difference"`` or ``"plane"``.
    """

    def __init__(self, *, weighting: str = "area") -> None:
        if weighting not in ("area", "unit"):
            raise ValueError(f"weighting must be 'area' or 'unit', got {weighting!r}")
        self.weighting = weighting
        self.reset()

    def reset(self) -> None:
        self._prev: tuple[np.ndarray, np.ndarray, np.ndarray | None] | None = None
        self.last_method = ""
        self.jacobian: np.ndarray | None = None

    def update(self, positions: Any, costs: Any, values: Any = None) -> np.ndarray:
        """``positions`` (2, 2): left and right camera (m); ``costs`` (2,);
        ``values`` (2, n), optional. Returns the gradient estimate (2,)
        (cost per metre); sets ``jacobian`` (n, 2) when ``values`` is given."""
        P = np.asarray(positions, dtype=float)
        c = np.asarray(costs, dtype=float)
        if P.shape != (2, 2) or c.shape != (2,):
            raise ValueError(f"need positions (2, 2) and costs (2,), got {P.shape} and {c.shape}")
        V = None if values is None else np.asarray(values, dtype=float).reshape(2, -1)
        g = None
        prev = self._prev
        if prev is not None:
            pp, pc, _ = prev
            g = plane_gradient(np.vstack([pp, P]), np.concatenate([pc, c]), weighting=self.weighting)
        if g is None:
            g = difference_quotient(P[0], P[1], c[0], c[1])
            self.last_method = "difference"
        else:
            self.last_method = "plane"
        self.jacobian = None
        if V is not None:
            rows = []
            for i in range(V.shape[1]):
                gi = None
                if self.last_method == "plane" and prev is not None and prev[2] is not None and prev[2].shape == V.shape:
                    gi = plane_gradient(np.vstack([prev[0], P]), np.concatenate([prev[2][:, i], V[:, i]]),
                                        weighting=self.weighting)
                rows.append(gi if gi is not None else difference_quotient(P[0], P[1], V[0, i], V[1, i]))
            self.jacobian = np.array(rows)
        self._prev = (P.copy(), c.copy(), None if V is None else V.copy())
        return g
