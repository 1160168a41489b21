"""Navigation along slow-feature gradients (thesis chapter 7).

A robot that has learned a slow-feature representation of its garden can
drive to a target by gradient descent on the distance, in slow-feature space,
between what it sees and what it saw at the target:

* **Cost** (7.1, 7.2.1): :class:`SlowFeatureCost`, the Euclidean distance
  between the current and the target's first ``n`` SFA outputs, optionally
  with the outputs weighted by ``1 / beta`` (:func:`beta_weights`).
* **Gradient** (7.1.1): :class:`PlaneGradient`, from two cameras on the
  robot's left and right: the first estimate from their difference quotient,
  then a plane through the four cost values of the last two stops (the mean
  of the normals of the four three-point planes).
* **Descents** with one interface (``reset()``, ``step(gradient, cost,
  position, info) -> displacement``): :class:`ThesisDescent` (step scale
  ``eta``, momentum ``gamma``) and :class:`RobustDescent` (normalised steps
  sized by the cost's own distance estimate, direction momentum, step
  control by the measured cost, wall sliding and plateau escape).
* **Closed loop**: :class:`Navigator` drives a simulator's two-camera robot
  (:class:`sfanav.sim.Simulator`, obstacles are physical) with features from
  :class:`ImageFeatures` (render + trained :class:`~sfanav.Network`) or any
  function of the camera poses (:class:`CoordinateFeatures` for SFA on
  coordinates, 7.2.2).
* **Beyond the thesis**: the learned metric space (:class:`MetricFeatures`,
  :class:`ScaledCost`, :class:`MapTracker` fusing estimates with odometry),
  the exploration run's :class:`GeodesicField` and the improved descent
  :class:`MetricDescent`; :class:`RunGraphFeatures`, the ideal slow
  features of a run (a reference for what SFA can at best learn).
* **Evaluation** (7.1.2): :func:`sample_trials`, :func:`evaluate_trials`
  (success rate, efficiency = optimal / travelled length), :func:`astar` on
  an occupancy grid (:func:`shortest_path` for worlds, weighted for velocity
  regions).
* **Velocity regions** (7.2.2): :func:`halfplane_optimal`,
  :func:`travel_time`, :func:`fit_coordinate_sfa`.
* **Plots**: :func:`plot_cost_surface` (fig. 7.7), :func:`plot_trajectories`
  (figs. 7.3, 7.6, 7.9, 7.10); each writes a PNG and returns its path.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

__all__ = [
    "SlowFeatureCost",
    "ScaledCost",
    "run_spread",
    "beta_weights",
    "difference_quotient",
    "plane_gradient",
    "PlaneGradient",
    "StepInfo",
    "Descent",
    "ThesisDescent",
    "RobustDescent",
    "MetricDescent",
    "MapTracker",
    "ImageFeatures",
    "CoordinateFeatures",
    "MetricFeatures",
    "GeodesicField",
    "RunGraphFeatures",
    "PointSimulator",
    "Navigator",
    "NavigationResult",
    "TrialSummary",
    "sample_trials",
    "evaluate_trials",
    "astar",
    "occupancy_grid",
    "shortest_path",
    "path_length",
    "halfplane_optimal",
    "travel_time",
    "fit_coordinate_sfa",
    "plot_cost_surface",
    "plot_trajectories",
]


def _vec2(v: Any, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.shape != (2,) or not np.isfinite(a).all():
        raise ValueError(f"{name} must be a finite (x, y) pair, got {v!r}")
    return a


# --------------------------------------------------------------------- cost


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


# --------------------------------------------------------------------- gradient


def difference_quotient(p_left: Any, p_right: Any, c_left: float, c_right: float) -> np.ndarray:
    """Gradient estimate from two cost values (thesis 7.1.1, first step): the
    difference quotient along the baseline from the right to the left camera,
    as a vector along that baseline. Its component across the baseline is
    unknown and set to zero."""
    a, b = _vec2(p_left, "p_left"), _vec2(p_right, "p_right")
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


# --------------------------------------------------------------------- descents


@dataclass
class StepInfo:
    """What the navigator tells a descent at each stop.

    Attributes: ``iteration`` (0-based), ``blocked`` (the last move was cut
    short by an obstacle or the border), ``last_move`` (metres actually
    driven), ``stuck`` (the navigator's stuck detector fired at this stop),
    ``heading`` (robot heading, odometry frame), ``method`` (how the
    gradient was estimated: ``"difference"`` or ``"plane"``), ``jacobian``
    (n, 2: each weighted output's gradient, from the same plane fits),
    ``residual`` (n: weighted features minus the target's, mean of the two
    cameras), ``history`` (odometry camera positions (2k, 2) and their
    residuals (2k, n) at all stops so far) and ``target`` (the cost's
    target features)."""

    iteration: int = 0
    blocked: bool = False
    last_move: float = 0.0
    stuck: bool = False
    heading: float = 0.0
    method: str = ""
    jacobian: np.ndarray | None = None
    residual: np.ndarray | None = None
    history: tuple[np.ndarray, np.ndarray] | None = None
    target: np.ndarray | None = None


class Descent(Protocol):
    """A descent rule: turns gradient estimates into displacements."""

    name: str

    def reset(self) -> None: ...

    def step(self, gradient: np.ndarray, cost: float, position: np.ndarray, info: StepInfo) -> np.ndarray: ...


class ThesisDescent:
    """Gradient descent with momentum (thesis 7.1.1):
    ``d_k = -eta * g_k + gamma * d_{k-1}``, the robot then drives ``d_k``.

    Parameters
    ----------
    eta : float
        Step scale (thesis: 1.0 for raw outputs, 0.0015 for 1/beta-weighted).
    gamma : float
        Momentum (thesis: 0.5).
    max_step : float, optional
        Cap on a step's length (m); the thesis has none.
    """

    name = "thesis rule"

    def __init__(self, eta: float = 1.0, gamma: float = 0.5, max_step: float | None = None) -> None:
        if not eta > 0:
            raise ValueError(f"eta must be positive, got {eta}")
        if not 0 <= gamma < 1:
            raise ValueError(f"gamma must be in [0, 1), got {gamma}")
        if max_step is not None and not max_step > 0:
            raise ValueError(f"max_step must be positive, got {max_step}")
        self.eta, self.gamma, self.max_step = float(eta), float(gamma), max_step
        self.reset()

    def reset(self) -> None:
        self._d = np.zeros(2)

    def step(self, gradient: np.ndarray, cost: float, position: np.ndarray, info: StepInfo) -> np.ndarray:
        d = -self.eta * np.asarray(gradient, float) + self.gamma * self._d
        if self.max_step is not None:
            L = float(np.hypot(*d))
            if L > self.max_step:
                d = d * (self.max_step / L)
        self._d = d
        return d.copy()


def _rot(v: np.ndarray, a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _unit(v: np.ndarray) -> np.ndarray | None:
    n = float(np.hypot(*v))
    return v / n if n > 1e-12 else None


class RobustDescent:
    """A descent for the thesis's open problem (flat regions, local minima).

    * **Normalised steps along the estimated direction**: the direction is
      the Gauss-Newton direction (below) or the unit negative gradient,
      optionally smoothed by a momentum on directions (``momentum``, default
      0); the step's length does not depend on the gradient's size, so flat
      regions are crossed at full speed.
    * **Gauss-Newton direction and length** (``gauss_newton``): the same
      plane fits applied to every weighted output give the local Jacobian
      ``J`` (n x 2) of the slow features; the damped Gauss-Newton step
      ``-(J^T J + lam I)^-1 J^T r`` on the residual ``r`` to the target's
      features points at where the linearised features match the target's,
      and its length estimates the distance left. It straightens the
      curved paths of plain gradient descent where the outputs change at
      different rates. Used when it is a descent direction of the cost
      (``lam = damping * trace(J^T J) / 2``) within ``max_angle`` degrees
      of the negative gradient (default 90: any descent direction);
      otherwise the gradient.
    * **Step length from the cost's own distance estimate** (without a
      Gauss-Newton step): near a target a distance cost is a cone, ``C ~
      |grad C| * distance``, so ``C / |g|`` estimates the distance left; the
      step is ``clip(fraction * C / |g|, min_step, max_step)`` (long in flat
      regions, short at the target).
    * **Step control by the measured cost**: when the cost rose since the
      last stop the step is shortened (``shrink``); after decreases it grows
      back (``grow``) to the estimate.
    * **A look around at the start** (``probe_first``): the robot turns on
      the spot by 90 degrees before its first step, so the plane through the
      four camera positions (a cross) gives the full gradient instead of
      the difference quotient along one baseline. Turning costs no distance.
    * **Wall following on bumps** (a bug algorithm with a bump sensor): when
      a move is cut short by an obstacle or the border and the gradient
      still points into it, the robot follows the wall on the side the
      gradient prefers, turning ``follow_away`` degrees away after a bump
      and ``follow_toward`` degrees back towards the wall after a free
      step of ``follow_step`` m, until the cost is ``leave_drop`` below its
      value where it hit the wall and the gradient no longer points into
      the wall. After ``max_follow`` steps it turns round (twice as long).
    * **Plateau / local-minimum escape**: when the best cost has not
      improved by ``rel_improvement`` for ``patience`` stops in open space
      (or the navigator reports being stuck), the robot drives
      ``escape_distance`` across its last direction (alternating sides,
      growing each time), then resumes the descent.

    Parameters are in metres and degrees; the defaults suit a robot of
    0.7 m with cameras 0.7 m apart and were tuned on other trials (and
    worlds) than the reported ones.
    """

    name = "robust descent"

    def __init__(
        self,
        *,
        fraction: float = 0.7,
        min_step: float = 0.15,
        max_step: float = 1.0,
        momentum: float = 0.0,
        grow: float = 1.5,
        shrink: float = 0.5,
        follow_step: float = 0.4,
        follow_away: float = 45.0,
        follow_toward: float = 30.0,
        leave_drop: float = 0.05,
        max_follow: int = 40,
        patience: int = 12,
        rel_improvement: float = 0.02,
        escape_distance: float = 2.0,
        escape_steps: int = 3,
        max_escapes: int = 6,
        probe_first: bool = True,
        gauss_newton: bool = True,
        damping: float = 0.01,
        max_angle: float = 90.0,
    ) -> None:
        for name, v in (("fraction", fraction), ("min_step", min_step), ("max_step", max_step),
                        ("escape_distance", escape_distance), ("follow_step", follow_step)):
            if not v > 0:
                raise ValueError(f"{name} must be positive, got {v}")
        if min_step > max_step:
            raise ValueError("min_step must not exceed max_step")
        if not 0 <= momentum < 1:
            raise ValueError(f"momentum must be in [0, 1), got {momentum}")
        if not (grow >= 1 and 0 < shrink <= 1):
            raise ValueError("need grow >= 1 and 0 < shrink <= 1")
        self.fraction, self.min_step, self.max_step = float(fraction), float(min_step), float(max_step)
        self.momentum, self.grow, self.shrink = float(momentum), float(grow), float(shrink)
        self.follow_step = float(follow_step)
        self.follow_away, self.follow_toward = float(np.radians(follow_away)), float(np.radians(follow_toward))
        self.leave_drop, self.max_follow = float(leave_drop), int(max_follow)
        self.patience, self.rel_improvement = int(patience), float(rel_improvement)
        self.escape_distance, self.escape_steps, self.max_escapes = float(escape_distance), int(escape_steps), int(max_escapes)
        self.probe_first = bool(probe_first)
        self.gauss_newton, self.damping = bool(gauss_newton), float(damping)
        self.max_angle = float(np.radians(max_angle))
        if not self.damping >= 0:
            raise ValueError(f"damping must be >= 0, got {damping}")
        self.reset()

    def _gauss_newton(self, g: np.ndarray, info: StepInfo) -> np.ndarray | None:
        """Damped Gauss-Newton displacement ``-(J^T J + lam I)^-1 J^T r`` on
        the weighted feature residual, or None when unavailable or not a
        descent direction of the cost."""
        J, r = info.jacobian, info.residual
        if not self.gauss_newton or J is None or r is None or info.method != "plane":
            return None
        J = np.asarray(J, float)
        r = np.asarray(r, float)
        A = J.T @ J
        lam = self.damping * float(np.trace(A)) / 2 + 1e-12
        try:
            d = -np.linalg.solve(A + lam * np.eye(2), J.T @ r)
        except np.linalg.LinAlgError:
            return None
        nd, ng = float(np.hypot(*d)), float(np.hypot(*g))
        if not np.isfinite(d).all() or nd <= 1e-12 or ng <= 1e-15:
            return None
        if float(d @ -g) / (nd * ng) <= (np.cos(self.max_angle) if self.max_angle < np.pi / 2 else 0.0):
            return None
        return d

    def reset(self) -> None:
        self._dir = np.zeros(2)       # smoothed descent direction
        self._last = np.zeros(2)      # last displacement asked for
        self._scale = 1.0             # multiplier from cost control (<= 1)
        self._prev_cost: float | None = None
        self._best = np.inf
        self._since_best = 0
        self._escape: list[np.ndarray] = []
        self._n_escapes = 0
        self._follow: dict[str, Any] | None = None
        self._n_follows = 0
        self.escapes = 0
        self.follows = 0

    # -- plateau escape
    def _start_escape(self) -> None:
        base = _unit(self._dir)
        base = base if base is not None else np.array([1.0, 0.0])
        side = 1.0 if self._n_escapes % 2 == 0 else -1.0
        perp = side * np.array([-base[1], base[0]])
        L = self.escape_distance * (1 + self._n_escapes // 2)
        self._escape = [perp * (L / self.escape_steps)] * self.escape_steps
        self._n_escapes += 1
        self.escapes += 1
        self._since_best = 0

    # -- wall following
    def _start_follow(self, bump: np.ndarray, u: np.ndarray, cost: float) -> None:
        cross = bump[0] * u[1] - bump[1] * u[0]
        if abs(cross) < 0.05:  # gradient straight into the wall: alternate sides
            side = 1.0 if self._n_follows % 2 == 0 else -1.0
        else:
            side = 1.0 if cross > 0 else -1.0
        self._follow = {"side": side, "heading": _rot(bump, side * np.pi / 2), "bump": bump, "hit": cost,
                        "n": 0, "max": self.max_follow, "turned": False}
        self._n_follows += 1
        self.follows += 1

    def _follow_step(self, u: np.ndarray, cost: float, info: StepInfo) -> np.ndarray | None:
        F = self._follow
        assert F is not None
        if info.blocked:
            F["bump"] = _unit(self._last) if _unit(self._last) is not None else F["bump"]
        if (not info.blocked and cost < F["hit"] * (1 - self.leave_drop) and float(u @ F["bump"]) < 0.3):
            self._follow = None  # leave the wall: descend again
            self._since_best = 0
            return None
        F["n"] += 1
        if F["n"] > F["max"]:
            if F["turned"]:
                self._follow = None
                self._since_best = self.patience  # let the escape take over
                return None
            F["side"] = -F["side"]
            F["heading"] = -F["heading"]
            F["n"], F["max"], F["turned"] = 0, 2 * F["max"], True
        elif info.blocked:
            F["heading"] = _rot(F["heading"], F["side"] * self.follow_away)
        else:
            F["heading"] = _rot(F["heading"], -F["side"] * self.follow_toward)
        return F["heading"] * self.follow_step

    def step(self, gradient: np.ndarray, cost: float, position: np.ndarray, info: StepInfo) -> np.ndarray:
        g = np.asarray(gradient, float)
        cost = float(cost)
        gn = float(np.hypot(*g))
        d_gn = self._gauss_newton(g, info)
        if d_gn is not None:
            u = d_gn / float(np.hypot(*d_gn))
        elif gn > 1e-15:
            u = -g / gn
        else:
            u = _unit(self._dir) if _unit(self._dir) is not None else np.array([1.0, 0.0])
        if np.hypot(*self._dir) > 0:
            v = _unit(self.momentum * self._dir + (1 - self.momentum) * u)
            u = v if v is not None else u
        # plateau / local minimum bookkeeping
        if cost < self._best * (1 - self.rel_improvement):
            self._best = cost
            self._since_best = 0
        else:
            self._since_best += 1
        d = None
        if self._escape:
            d = self._escape.pop(0)
            if info.blocked:
                self._escape = []
        if d is None and self._follow is None and info.blocked:
            bump = _unit(self._last)
            if bump is not None and float(u @ bump) > 0.0:
                self._start_follow(bump, u, cost)
        if d is None and self._follow is not None:
            d = self._follow_step(u, cost, info)
        if d is None and self._follow is None and self._n_escapes < self.max_escapes and (
            info.stuck or self._since_best >= self.patience
        ):
            self._start_escape()
            d = self._escape.pop(0)
        if d is not None:
            self._prev_cost = cost
            self._last = np.asarray(d, float)
            return self._last.copy()
        # descent step
        if self._prev_cost is not None:
            if cost > self._prev_cost:
                self._scale = max(self._scale * self.shrink, 1e-3)
            else:
                self._scale = min(self._scale * self.grow, 1.0)
        self._prev_cost = cost
        est = self.fraction * cost / gn if gn > 1e-15 else self.max_step
        if d_gn is not None:  # the linearised distance to the target
            est = float(np.hypot(*d_gn))
        if info.method == "difference":  # only the component along the cameras' baseline is known
            est = self.min_step
        L = float(np.clip(est * self._scale, self.min_step, self.max_step))
        self._dir = u
        self._last = u * L
        return self._last.copy()


def _rigid_fit(P: np.ndarray, Q: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
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
            rot, t = _rigid_fit(A, B, w)
            r = np.hypot(*(A @ rot.T + t - B).T)
            w = np.minimum(1.0, self.huber / np.maximum(r, 1e-12))
        F[:, :2] = P @ rot.T + t
        return F


class MetricDescent:
    """Steps towards the target in a learned metric space (beyond the
    thesis; docs/navigation.md).

    For features that are position estimates (:class:`MetricFeatures`;
    the navigator's cost on ``n_outputs=2`` without weights), each stop's
    residual is a camera's estimated position relative to the target's,
    and the navigator knows the same cameras' positions by odometry. A 2-D
    rigid transform (least squares, Umeyama 1991 without scale) from the
    odometry frame to the target-centred map, fitted over the last
    ``window`` stops, places the robot and its heading in the map; the step
    heads straight for the target, or with a :class:`GeodesicField`, when
    the run's shortest path to it is longer than ``detour`` times the
    straight distance plus ``slack`` m and the straight line is not
    :meth:`GeodesicField.visible` with ``clearance`` (which gaps in the
    run's coverage of open ground also trigger) or, with ``jump`` (m),
    crosses a wall by :meth:`GeodesicField.crosses_wall` (the geodesic
    distance jumps by more than ``jump`` along it: open ground rarely
    triggers it, but near a wall's end, where the way round is short, it
    lets the robot head into the wall; opt-in, see docs/navigation.md)
    (something in the way;
    tested only beyond ``near`` m of the target, where the estimates'
    errors are small against the distances), for the farthest visible
    point within ``lookahead`` m along that path
    (:meth:`GeodesicField.waypoint`); at most ``max_step`` m long. Until the cameras have spread over
    ``min_spread`` m (the first stops), or when the fit is poor: a
    normalised step along the estimated negative gradient. After a bump the
    wanted direction is turned by ``bump_turn`` degrees to one side, after
    the next bump to the other, then by twice the angle, ..., until a move
    is free (short steps of ``bump_step`` m meanwhile). Within ``near`` metres of the target (by the
    cost) the position estimates' errors are as large as the distance
    left, so the last metres are a :class:`RobustDescent` on the measured
    costs.
    """

    name = "metric descent"

    def __init__(self, *, field: "GeodesicField | None" = None, max_step: float = 1.0, lookahead: float = 3.0,
                 window: int = 20, min_spread: float = 0.5, bump_turn: float = 45.0, bump_step: float = 0.4, near: float = 1.5,
                 detour: float = 1.2, slack: float = 0.0, clearance: float = 0.4, jump: float | None = None,
                 probe_first: bool = True) -> None:
        for nm, v, lo in (("max_step", max_step, 0.0), ("lookahead", lookahead, 0.0), ("min_spread", min_spread, 0.0),
                          ("bump_turn", bump_turn, 0.0), ("bump_step", bump_step, 0.0), ("clearance", clearance, 0.0)):
            if not (np.isfinite(v) and v > lo):
                raise ValueError(f"{nm} must be positive, got {v}")
        for nm, v, lo in (("detour", detour, 1.0), ("slack", slack, 0.0), ("near", near, 0.0)):
            if not (np.isfinite(v) and v >= lo):
                raise ValueError(f"{nm} must be >= {lo:g}, got {v}")
        if int(window) < 2:
            raise ValueError(f"window must be at least 2 stops, got {window}")
        self.field = field
        self.max_step, self.lookahead, self.window = float(max_step), float(lookahead), int(window)
        self.min_spread, self.bump_turn, self.bump_step = float(min_spread), float(np.radians(bump_turn)), float(bump_step)
        self.detour, self.slack, self.clearance, self.near = float(detour), float(slack), float(clearance), float(near)
        if jump is not None and not (np.isfinite(jump) and jump > 0):
            raise ValueError(f"jump must be a positive number of metres or None, got {jump}")
        self.jump = None if jump is None else float(jump)
        self.probe_first = bool(probe_first)
        self._local = RobustDescent(probe_first=False)
        self.reset()

    def reset(self) -> None:
        self._bumps = 0
        self.escapes = 0
        self.follows = 0
        self._local.reset()

    @staticmethod
    def align(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotation ``Rot`` (2, 2) and translation ``t`` minimising
        ``sum |Rot p + t - q|^2`` over rows of ``P``, ``Q`` (k, 2)."""
        return _rigid_fit(P, Q)

    def step(self, gradient: np.ndarray, cost: float, position: np.ndarray, info: StepInfo) -> np.ndarray:
        d = None
        blocked_view = False  # the run's paths say something lies between robot and target
        if info.history is not None:
            P, R = info.history
            k = min(len(P), 2 * self.window)
            P, R = np.asarray(P[-k:], float), np.asarray(R[-k:, :2], float)
            if R.shape[1] == 2 and np.hypot(*(P - P.mean(axis=0)).T).max() * 2 >= self.min_spread:
                rot, t = self.align(P, R)
                m = rot @ np.asarray(position, float) + t  # robot in the target-centred map
                goal = np.zeros(2)
                if self.field is not None and info.target is not None:
                    tgt = np.asarray(info.target, float)[:2]
                    geo = float(self.field(m + tgt, tgt))
                    dist = float(np.hypot(*m))
                    if (dist >= self.near and geo > self.detour * dist + self.slack
                            and (not self.field.visible(m + tgt, tgt, self.clearance) if self.jump is None
                                 else self.field.crosses_wall(m + tgt, tgt, tgt, self.jump))):  # something in the way
                        blocked_view = True
                        goal = self.field.waypoint(m + tgt, tgt, self.lookahead, jump=self.jump) - tgt
                d = rot.T @ (goal - m)
        if float(cost) < self.near and not blocked_view:
            d = np.asarray(self._local.step(gradient, cost, position, info), float)
            self.escapes = self._local.escapes
            return d
        if d is None:
            u = _unit(-np.asarray(gradient, float))
            if u is None:
                u = np.array([np.cos(info.heading), np.sin(info.heading)])
            d = u * min(self.max_step, max(0.15, 0.7 * float(cost)))
        L = float(np.hypot(*d))
        if L > self.max_step:
            d = d * (self.max_step / L)
        if info.blocked:
            self._bumps += 1
            self.follows += 1
            k = self._bumps
            angle = ((k + 1) // 2) * self.bump_turn * (1.0 if k % 2 else -1.0)  # +a, -a, +2a, -2a, ...
            u = _unit(d)
            if u is not None and k <= 2 * int(np.pi / self.bump_turn):
                d = _rot(u * self.bump_step, angle)
        else:
            self._bumps = 0
        return d


# --------------------------------------------------------------------- features


class ImageFeatures:
    """Slow features of camera poses: renders each pose with ``renderer``
    and ``camera`` and transforms the images with a trained ``network``.

    ``rows``: an :class:`sfanav.ImageRows` applied to the rendered images
    before the network (e.g. a fitted Localizer's ``rows``: the sfanav
    default's horizon band).

    ``features(poses (k, 3)) -> (k, n_outputs)``; ``images`` counts the
    images processed."""

    def __init__(self, network: Any, renderer: Any, camera: Any, *, lighting: Any = None, rows: Any = None) -> None:
        self.network, self.renderer, self.camera, self.lighting = network, renderer, camera, lighting
        self.rows = None if rows is None or getattr(rows, "identity", False) else rows
        self.images = 0

    def render(self, poses: Any) -> np.ndarray:
        """The camera's images (k, H, W[, C]) at ``poses`` (k, 3); counted in ``images``."""
        P = np.atleast_2d(np.asarray(poses, float))
        imgs = np.stack([self.renderer.render(self.camera, p, 0.0, self.lighting) for p in P])
        self.images += len(P)
        return imgs

    def __call__(self, poses: Any) -> np.ndarray:
        imgs = self.render(poses)
        if self.rows is not None:
            imgs = self.rows(imgs)
        return np.asarray(self.network.transform(imgs), float)


class CoordinateFeatures:
    """Slow features computed from positions (thesis 7.2.2: SFA learned on
    the coordinates of a trajectory): ``features(poses) = model(x, y)``.

    ``model`` is a callable on (k, 2) positions (see :func:`fit_coordinate_sfa`)."""

    def __init__(self, model: Callable[[np.ndarray], np.ndarray]) -> None:
        self.model = model
        self.images = 0

    def __call__(self, poses: Any) -> np.ndarray:
        P = np.atleast_2d(np.asarray(poses, float))
        self.images += len(P)
        return np.asarray(self.model(P[:, :2]), float)


class MetricFeatures(ImageFeatures):
    """Positions in a learned metric space as navigation features: each
    camera pose is rendered and localized by a fitted
    :class:`sfanav.Localizer` (image rows, network, readout), so
    ``features(poses (k, 3)) -> (k, 2)`` estimated x, y in metres.

    With ``n_outputs=2`` the thesis's cost becomes the Euclidean distance
    between the estimated positions of the robot's cameras and of the
    target's image (images -> slow features -> metric space ->
    navigation); with :class:`GeodesicField` the exploration run's
    geodesic distance. ``images`` counts the images processed."""

    def __init__(self, localizer: Any, renderer: Any, camera: Any, *, lighting: Any = None) -> None:
        if not getattr(localizer, "is_fitted_", False):
            raise ValueError("MetricFeatures needs a fitted sfanav.Localizer")
        super().__init__(localizer._network(), renderer, camera, lighting=lighting)
        self.localizer = localizer

    def __call__(self, poses: Any) -> np.ndarray:
        return np.asarray(self.localizer.predict(self.render(poses)), float)


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


def _run_positions(positions: Any) -> np.ndarray:
    P = np.asarray(positions, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or len(P) < 2:
        raise ValueError(f"positions must be (N >= 2, 2) metres, got shape {P.shape}")
    if not np.isfinite(P).all():
        raise ValueError("positions contain NaN or inf")
    return P


def _thin_run(P: np.ndarray, thin: float) -> tuple[np.ndarray, np.ndarray]:
    """One node per occupied cell of ``thin`` metres (the first frame in it):
    (node positions (n, 2), each frame's node (N,))."""
    ij = np.floor((P - P.min(axis=0)) / thin).astype(np.int64)
    _, first, node = np.unique(ij, axis=0, return_index=True, return_inverse=True)
    return P[first], node.ravel()


class GeodesicField:
    """Shortest-path distances through the space an exploration run covered
    (beyond the thesis; docs/navigation.md).

    The thesis expects slow features to "flow" around obstacles because the
    robot's temporal distance between the two sides of an obstacle is
    large (7.1). This makes that distance explicit. The run's positions
    (N, 2) in metres (ground truth in the simulator, or the metric map a
    robot learned from odometry, :mod:`sfanav.metric`) mark the space known
    to be free: the cells of a grid of ``thin`` metres within ``radius / 2``
    of the run's path (its positions and, with ``temporal``, the straight
    pieces between consecutive ones up to ``5 * radius`` long: the robot
    drove there), so gaps of up to ``radius`` between the run's lines are
    bridged. Distances are
    shortest paths between free cells, 16-connected (straight, diagonal and
    knight moves, the cells a move passes over free too; at most 2.7 %
    longer than the straight line in open ground, where the run's own
    frames joined by their neighbours zig-zag 10-25 % longer). An obstacle
    the robot kept clear of by at least its radius on each side (more than
    ``radius / 2``) leaves blocked cells along it, so paths go round it. A
    place's cost to a target is the smallest, over the place's
    ``neighbours`` nearest free cells, of that cell's distance plus the
    straight offset to it (and the target's own offset to its cell); places
    the run's free space does not connect to the target cost the largest
    finite distance plus their straight distance.

    ``GeodesicField(run_xy).cost`` is a ``cost=`` for :class:`Navigator`
    on :class:`MetricFeatures` (``n_outputs=2``)."""

    _MOVES = ((0, 1, ()), (1, 0, ()), (1, 1, ((0, 1), (1, 0))), (1, -1, ((0, -1), (1, 0))),
              (1, 2, ((0, 1), (1, 1))), (2, 1, ((1, 0), (1, 1))), (2, -1, ((1, 0), (1, -1))),
              (1, -2, ((0, -1), (1, -1))))

    def __init__(self, positions: Any, *, radius: float = 0.5, thin: float = 0.1, temporal: bool = True,
                 neighbours: int = 8) -> None:
        from scipy.sparse import coo_matrix
        from scipy.spatial import cKDTree

        P = _run_positions(positions)
        for name, v in (("radius", radius), ("thin", thin)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of metres, got {v}")
        if isinstance(neighbours, bool) or int(neighbours) != neighbours or int(neighbours) < 1:
            raise ValueError(f"neighbours must be a positive integer, got {neighbours!r}")
        self.radius, self.thin = float(radius), float(thin)
        if self.radius < 1.5 * self.thin:
            raise ValueError(f"radius ({radius} m) must be at least 1.5 x the cell size thin ({thin} m), "
                             "or the run's own cells may not count as covered")
        self.neighbours = int(neighbours)
        self.centres, _ = _thin_run(P, self.thin)  # the run's places (for visible())
        self.tree = cKDTree(self.centres)
        path = P
        if temporal:
            seg = np.diff(P, axis=0)
            step = np.hypot(*seg.T)
            keep = step <= 5.0 * self.radius  # longer jumps join separate runs, not a drive
            seg, start = seg[keep], P[:-1][keep]
            k = np.maximum(1, np.ceil(step[keep] / (0.5 * self.thin)).astype(int))
            idx = np.repeat(np.arange(len(seg)), k)
            frac = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k, k)
            path = np.vstack([start[idx] + frac[:, None] * seg[idx], P])
        lo = P.min(axis=0) - self.radius
        shape = (np.ceil((P.max(axis=0) + self.radius - lo) / self.thin).astype(int) + 1)[::-1]  # (ny, nx)
        if int(shape[0]) * int(shape[1]) > 4_000_000:
            raise ValueError(f"a grid of {shape[1]} x {shape[0]} cells of {self.thin} m is too large: "
                             "the run spans too far for this cell size")
        ny, nx = int(shape[0]), int(shape[1])
        gy, gx = np.mgrid[0:ny, 0:nx]
        cell_xy = np.column_stack([lo[0] + gx.ravel() * self.thin, lo[1] + gy.ravel() * self.thin])
        near = cKDTree(path).query(cell_xy, distance_upper_bound=self.radius / 2)[0]
        free = np.isfinite(near).reshape(ny, nx)
        index = np.full((ny, nx), -1, dtype=np.int64)
        index[free] = np.arange(int(free.sum()))
        self.cells = cell_xy[free.ravel()]
        self._cell_tree = cKDTree(self.cells)
        rows, cols, lens = [], [], []
        for di, dj, over in self._MOVES:
            i0, i1 = max(0, -di), ny - max(0, di)
            j0, j1 = max(0, -dj), nx - max(0, dj)
            ok = free[i0:i1, j0:j1] & free[i0 + di : i1 + di, j0 + dj : j1 + dj]
            for oi, oj in over:
                ok &= free[i0 + oi : i1 + oi, j0 + oj : j1 + oj]
            a = index[i0:i1, j0:j1][ok]
            b = index[i0 + di : i1 + di, j0 + dj : j1 + dj][ok]
            rows.append(a)
            cols.append(b)
            lens.append(np.full(len(a), self.thin * float(np.hypot(di, dj))))
        r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(lens)
        n = len(self.cells)
        self.graph = coo_matrix((np.r_[w, w], (np.r_[r, c], np.r_[c, r])), shape=(n, n)).tocsr()
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def n_nodes(self) -> int:
        """Free cells (the graph's nodes)."""
        return len(self.cells)

    def _source(self, target: Any) -> tuple[int, np.ndarray]:
        t = _vec2(target, "target")
        k = int(self._cell_tree.query(t)[1])
        if k not in self._cache:
            from scipy.sparse.csgraph import dijkstra

            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[k] = dijkstra(self.graph, directed=False, indices=k, return_predecessors=True)
        return k, t

    def distances_from(self, target: Any) -> np.ndarray:
        """Shortest-path distance (m) from the target to every free cell
        (:attr:`cells`)."""
        k, t = self._source(target)
        D = self._cache[k][0].copy()
        finite = np.isfinite(D)
        D[~finite] = (D[finite].max() if finite.any() else 0.0) + np.hypot(*(self.cells[~finite] - t).T)
        return D + float(np.hypot(*(self.cells[k] - t)))

    def evaluate(self, D: np.ndarray, xy: Any) -> np.ndarray:
        """Geodesic distances of places ``xy`` (..., 2) given the cell
        distances ``D`` (from :meth:`distances_from`): the minimum over the
        ``neighbours`` nearest free cells of cell distance plus offset."""
        xy = np.asarray(xy, dtype=float)
        flat = xy.reshape(-1, 2)
        k = min(self.neighbours, self.n_nodes)
        d, i = self._cell_tree.query(flat, k=k)
        d, i = np.asarray(d).reshape(len(flat), k), np.asarray(i).reshape(len(flat), k)
        return (D[i] + d).min(axis=1).reshape(xy.shape[:-1])

    def visible(self, a: Any, b: Any, clearance: float | None = None) -> bool:
        """Whether the straight segment from ``a`` to ``b`` stays within
        ``clearance`` metres (default ``0.6 * radius``) of the run's
        positions everywhere (sampled every 0.1 m): known free space."""
        a, b = _vec2(a, "a"), _vec2(b, "b")
        c = 0.6 * self.radius if clearance is None else float(clearance)
        n = max(2, int(np.ceil(np.hypot(*(b - a)) / 0.1)) + 1)
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        return bool((self.tree.query(pts)[0] <= c).all())

    def crosses_wall(self, a: Any, b: Any, target: Any, jump: float = 3.0) -> bool:
        """Whether the straight segment from ``a`` to ``b`` passes between
        places the run connects only the long way round: the geodesic
        distance to ``target``, sampled every 0.1 m along the segment,
        jumps by more than ``jump`` metres between neighbouring samples (a
        wall the run never crossed). Unlike :meth:`visible`, gaps in the
        run's coverage of open ground do not count."""
        a, b = _vec2(a, "a"), _vec2(b, "b")
        if not (np.isfinite(jump) and jump > 0):
            raise ValueError(f"jump must be a positive number of metres, got {jump}")
        n = max(2, int(np.ceil(np.hypot(*(b - a)) / 0.1)) + 1)
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        g = self.evaluate(self.distances_from(target), pts)
        return bool(np.abs(np.diff(g)).max() > jump)

    def waypoint(self, xy: Any, target: Any, lookahead: float = 3.0, *, jump: float | None = None) -> np.ndarray:
        """Where to head from ``xy`` (2,) towards ``target``: the farthest
        point of the shortest path within ``lookahead`` metres (path length)
        that ``xy`` sees in a straight line through known free space
        (:meth:`visible`; with ``jump``: no :meth:`crosses_wall` on the way;
        the path's first cell if none); the target itself when it is that
        near, visible, or unreachable."""
        x = _vec2(xy, "xy")
        k, t = self._source(target)
        pred = self._cache[k][1]
        i = int(self._cell_tree.query(x)[1])
        travelled, cur = 0.0, x
        path: list[np.ndarray] = []
        for _ in range(self.n_nodes):
            j = int(pred[i])
            if j < 0:  # the target's cell (or unreachable)
                path.append(t)
                break
            nxt = self.cells[j]
            travelled += float(np.hypot(*(nxt - cur)))
            if travelled > lookahead:
                break
            path.append(nxt)
            cur, i = nxt, j
        if not path:
            return self.cells[int(pred[i])].copy() if pred[i] >= 0 else t
        for q in reversed(path):
            if self.visible(x, q) if jump is None else not self.crosses_wall(x, q, t, jump):
                return np.array(q, float)
        return np.array(path[0], float)

    def __call__(self, xy: Any, target: Any) -> np.ndarray:
        """Geodesic distance (m) of places ``xy`` (..., 2) to ``target``."""
        return _GeodesicCost(self, target)(xy)

    def cost(self, target_features: Any, n_outputs: int = 2, weights: Any = None) -> "SlowFeatureCost":
        """The cost of a run to a target (its estimated position, from
        :class:`MetricFeatures`); the signature of :class:`Navigator`'s ``cost``."""
        if int(n_outputs) != 2:
            raise ValueError(f"a geodesic cost works on metric positions: n_outputs must be 2, got {n_outputs}")
        if weights is not None:
            raise ValueError("a geodesic cost takes no per-output weights")
        return _GeodesicCost(self, np.asarray(target_features, float).ravel()[:2])


class _GeodesicCost(SlowFeatureCost):
    def __init__(self, field: GeodesicField, target: Any) -> None:
        super().__init__(target, 2)
        self.field = field
        self._D = field.distances_from(self.target)

    def __call__(self, features: Any) -> np.ndarray:
        f = np.asarray(features, dtype=float)
        if f.shape[-1] < 2:
            raise ValueError(f"features have {f.shape[-1]} outputs, the geodesic cost needs x, y")
        return self.field.evaluate(self._D, f[..., :2])


class RunGraphFeatures:
    """The slowest features of an exploration run with no limit on the
    function class: a reference for what SFA can at best learn from the run
    (beyond the thesis; docs/navigation.md).

    SFA minimises the mean squared change of unit-variance, decorrelated
    outputs along the run. Over *all* functions of position, with the
    transitions of a random exploration standing in by a graph joining the
    run's places (nodes: one per ``thin`` m cell the run visited, weighted
    by its number of frames ``c``; edges: places at most ``radius`` m
    apart, weight ``exp(-d^2 / 2 sigma^2)``), this is the generalized
    eigenproblem ``L f = lambda C f`` of the graph Laplacian ``L`` (Laplacian
    eigenmaps; Sprekeler 2011 relates SFA's slowest functions of a random
    walk to them). Its smallest non-trivial solutions are exactly zero-mean,
    unit-variance and decorrelated over the run's frames, ordered by
    slowness; in an open rectangle they are the half-cosine modes of x and
    y (the thesis's ideal x / y codes, flat at the borders), and they flow
    around obstacles the run kept clear of, since no edge crosses them.

    Parameters
    ----------
    positions : array (N, 2)
        The run's positions (m), in time order.
    n_components : int
        Number of features.
    radius, sigma, thin : float
        Edge radius, edge width and node cell size (m).

    Attributes
    ----------
    centres_ : (n, 2) node positions; ``values_`` : (n, n_components)
    features of the nodes; ``run_features_`` : (N, n_components) features of
    the run's frames (their nodes'); ``delta_values_`` : mean squared change
    of ``run_features_`` between consecutive frames (SFA's Delta, ascending
    up to the graph's approximation); ``beta_values_`` = sqrt(Delta) / 2 pi;
    ``n_dropped_`` : nodes outside the graph's largest connected part (they
    take the values of their nearest node in it).

    ``features(poses (k, >= 2)) -> (k, n_components)``: the mean of the 8
    nearest nodes' values weighted by inverse distance (a
    :class:`CoordinateFeatures`-style callable for :class:`Navigator`).
    """

    def __init__(self, positions: Any, n_components: int = 8, *, radius: float = 0.5, sigma: float = 0.25,
                 thin: float = 0.1) -> None:
        from scipy.sparse import coo_matrix, diags
        from scipy.sparse.csgraph import connected_components
        from scipy.sparse.linalg import eigsh
        from scipy.spatial import cKDTree

        P = _run_positions(positions)
        if isinstance(n_components, bool) or int(n_components) != n_components or int(n_components) < 1:
            raise ValueError(f"n_components must be a positive integer, got {n_components!r}")
        for name, v in (("radius", radius), ("sigma", sigma), ("thin", thin)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of metres, got {v}")
        k = int(n_components)
        centres, node = _thin_run(P, float(thin))
        counts = np.bincount(node, minlength=len(centres)).astype(float)
        tree = cKDTree(centres)
        pairs = tree.query_pairs(float(radius), output_type="ndarray")
        n = len(centres)
        d = np.hypot(*(centres[pairs[:, 0]] - centres[pairs[:, 1]]).T)
        w = np.exp(-(d * d) / (2.0 * float(sigma) ** 2))
        W = coo_matrix((np.r_[w, w], (np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]])),
                       shape=(n, n)).tocsr()
        _, label = connected_components(W, directed=False)
        main = np.flatnonzero(label == np.bincount(label).argmax())
        if len(main) < k + 2:
            raise ValueError(f"the run's graph has too few connected places ({len(main)}) for "
                             f"{k} features: a longer run or a larger radius")
        Wm = W[main][:, main]
        L = diags(np.asarray(Wm.sum(axis=1)).ravel()) - Wm
        M = diags(counts[main])
        shift = -1e-8 * float(L.diagonal().max() / counts[main].min())
        vals, vecs = eigsh(L.tocsc(), k=k + 1, M=M.tocsc(), sigma=shift, which="LM")
        order = np.argsort(vals)
        vecs = vecs[:, order[1:]]  # drop the constant
        V = np.empty((n, k))
        V[main] = vecs
        self.n_dropped_ = int(n - len(main))
        if self.n_dropped_:
            other = np.setdiff1d(np.arange(n), main)
            V[other] = vecs[cKDTree(centres[main]).query(centres[other])[1]]
        frames = V[node]
        mu, sd = frames.mean(axis=0), frames.std(axis=0)
        V = (V - mu) / sd
        sign = np.sign(V[np.abs(V).argmax(axis=0), np.arange(k)])
        V *= np.where(sign == 0, 1.0, sign)
        self.centres_, self.values_, self.tree_ = centres, V, tree
        self.run_features_ = V[node]
        self.delta_values_ = np.mean(np.diff(self.run_features_, axis=0) ** 2, axis=0)
        self.beta_values_ = np.sqrt(self.delta_values_) / (2 * np.pi)
        self.n_components = k

    def __call__(self, poses: Any) -> np.ndarray:
        P = np.asarray(poses, dtype=float)
        if P.ndim != 2 or P.shape[1] < 2:
            raise ValueError(f"poses must be (k, >= 2), got shape {P.shape}")
        m = min(8, len(self.centres_))
        d, i = self.tree_.query(P[:, :2], k=m)
        d, i = np.asarray(d).reshape(len(P), m), np.asarray(i).reshape(len(P), m)
        wt = 1.0 / (d + 0.05)
        return np.einsum("km,kmc->kc", wt, self.values_[i]) / wt.sum(axis=1, keepdims=True)


class PointSimulator:
    """A simulator without rendering, for features from coordinates: the
    same interface as :class:`sfanav.sim.Simulator` (``pose``,
    ``odometry_pose``, ``robot``, ``reset``, ``step``) with exact odometry
    and moves refused outside the area or into ``world``'s obstacles."""

    def __init__(self, area: Sequence[float] | None = None, robot: Any = None, *, world: Any = None,
                 pose: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        from .sim.robot import Robot

        if world is None and area is None:
            raise ValueError("give an area (width, height) or a world")
        self.world = world
        self.area = tuple(float(a) for a in (world.area if world is not None else area))
        self.robot = robot or Robot.two_cameras(0.7)
        self.reset(pose)

    def reset(self, pose: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        self.pose = np.asarray(pose, float).copy()
        self.odometry_pose = self.pose.copy()
        self.time = 0.0

    def _free(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        r = self.robot.size / 2
        if self.world is not None:
            return self.world.free(x, y, r)
        return (np.abs(x) <= self.area[0] / 2 - r) & (np.abs(y) <= self.area[1] / 2 - r)

    def step(self, v: float, omega: float, dt: float) -> bool:
        from .sim.robot import unicycle_step

        new = unicycle_step(self.pose, v, omega, dt)
        self.time += dt
        n = max(1, int(np.ceil(abs(v) * dt / 0.05)))
        path = np.array([unicycle_step(self.pose, v, omega, dt * k / n) for k in range(1, n + 1)])
        if not bool(self._free(path[:, 0], path[:, 1]).all()):
            return False
        self.pose = new
        self.odometry_pose = new.copy()
        return True


# --------------------------------------------------------------------- closed loop


@dataclass
class NavigationResult:
    """One navigation run.

    Attributes
    ----------
    path : ndarray (k, 2)
        True robot positions at every stop (start first).
    success : bool
        Ended within the success radius of the target.
    reason : str
        ``"reached"``, ``"max_iterations"`` or ``"stuck"``.
    iterations : int
    travelled : float
        True path length (m).
    costs : ndarray (k,)
        Cost at each stop (mean of the two cameras).
    start, target : ndarray (2,)
    images : int
        Images (or feature evaluations) processed.
    escapes : int
        Plateau escapes taken (robust descent).
    blocked : int
        Moves cut short by an obstacle or the border.
    follows : int
        Wall-following episodes (robust descent).
    """

    path: np.ndarray
    success: bool
    reason: str
    iterations: int
    travelled: float
    costs: np.ndarray
    start: np.ndarray
    target: np.ndarray
    images: int = 0
    escapes: int = 0
    blocked: int = 0
    follows: int = 0

    @property
    def direct(self) -> float:
        return float(np.hypot(*(self.target - self.start)))


class Navigator:
    """Closed-loop navigation in a simulator (thesis 7.1).

    At each stop the robot evaluates ``features`` at its two cameras' true
    poses (rendering + SFA, or coordinates), computes their costs to the
    target, estimates the gradient (:class:`PlaneGradient`, in the
    odometry frame: the robot only knows its own motion), asks the descent
    for a displacement, turns on the spot to face it and drives straight.
    Obstacles are physical: the drive goes in pieces of ``drive_piece`` m
    and ends at the first piece the simulator refuses (a bump).

    Parameters
    ----------
    simulator : sfanav.sim.Simulator or PointSimulator
        Its robot needs the cameras ``"left"`` and ``"right"``
        (:meth:`sfanav.sim.Robot.two_cameras`).
    features : callable
        ``features(poses (k, 3)) -> (k, m)`` slow features at camera poses
        (:class:`ImageFeatures`, :class:`CoordinateFeatures`).
    descent : ThesisDescent, RobustDescent or any :class:`Descent`
    n_outputs : int
        Outputs used in the cost (thesis: 2).
    weights : array, optional
        Per-output cost weights (e.g. :func:`beta_weights`).
    success_radius : float
        Success when the robot's centre is this close to the target (thesis 0.5 m).
    max_iterations : int
        Stops per run (thesis 400).
    stuck_window, stuck_distance : int, float
        Stuck detector: the robot's (odometry) position moved less than
        ``stuck_distance`` m over the last ``stuck_window`` stops. The
        descent is told (``StepInfo.stuck``); with ``stop_when_stuck`` the
        run ends as ``"stuck"``.
    stop_when_stuck : bool
        End a run when stuck (default False: run to ``max_iterations``,
        as the thesis did).
    cost : callable, optional
        ``cost(target_features, n_outputs, weights) -> SlowFeatureCost``
        (or a subclass): how a run's cost is built from the target's
        features; default :class:`SlowFeatureCost` (the thesis's distance
        in slow-feature space). :meth:`GeodesicField.cost` gives the
        geodesic distance of the exploration run in a metric space.
    tracker : MapTracker, optional
        Fuses every stop's position estimates with odometry before the
        cost (features whose first two outputs are x, y in metres).
    """

    def __init__(
        self,
        simulator: Any,
        features: Callable[[np.ndarray], np.ndarray],
        descent: Any = None,
        *,
        n_outputs: int = 2,
        weights: Any = None,
        success_radius: float = 0.5,
        max_iterations: int = 400,
        stuck_window: int = 40,
        stuck_distance: float = 0.25,
        stop_when_stuck: bool = False,
        drive_piece: float = 0.1,
        gradient: PlaneGradient | None = None,
        cost: Callable[..., SlowFeatureCost] | None = None,
        tracker: "MapTracker | None" = None,
    ) -> None:
        cams = getattr(getattr(simulator, "robot", None), "cameras", {})
        if "left" not in cams or "right" not in cams:
            raise ValueError("the simulator's robot needs cameras 'left' and 'right' (sim.Robot.two_cameras())")
        self.simulator = simulator
        self.features = features
        self.descent = descent if descent is not None else ThesisDescent()
        self.n_outputs = int(n_outputs)
        self.weights = weights
        if not success_radius > 0:
            raise ValueError(f"success_radius must be positive, got {success_radius}")
        if int(max_iterations) < 1:
            raise ValueError(f"max_iterations must be >= 1, got {max_iterations}")
        self.success_radius = float(success_radius)
        self.max_iterations = int(max_iterations)
        self.stuck_window, self.stuck_distance = int(stuck_window), float(stuck_distance)
        self.stop_when_stuck = bool(stop_when_stuck)
        self.drive_piece = float(drive_piece)
        self.gradient = gradient or PlaneGradient()
        self.cost = cost if cost is not None else SlowFeatureCost
        self.tracker = tracker

    def target_features(self, target: Any) -> np.ndarray:
        """SFA outputs of an image taken at the target (a camera at the target position)."""
        t = _vec2(target, "target")
        return np.asarray(self.features(np.array([[t[0], t[1], 0.0]])), float)[0]

    def _drive(self, d: np.ndarray) -> tuple[float, bool]:
        """Turns to face displacement ``d`` (odometry frame) and drives its
        length; returns (true metres driven, blocked)."""
        sim = self.simulator
        L = float(np.hypot(*d))
        if L <= 1e-9:
            return 0.0, False
        turn = float((np.arctan2(d[1], d[0]) - sim.odometry_pose[2] + np.pi) % (2 * np.pi) - np.pi)
        if abs(turn) > 1e-9:
            sim.step(0.0, turn, 1.0)
        n = max(1, int(np.ceil(L / self.drive_piece)))
        piece = L / n
        start = np.array(sim.pose[:2], float)
        moved = 0.0
        blocked = False
        for _ in range(n):
            before = np.array(sim.pose[:2], float)
            if not sim.step(piece, 0.0, 1.0):
                blocked = True
                break
            moved += float(np.hypot(*(np.array(sim.pose[:2]) - before)))
        del start
        return moved, blocked

    def _measure(self, cost: SlowFeatureCost) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Costs at the two cameras (features at their true poses), the
        cameras' positions as the robot believes them (odometry) and the
        weighted residuals (2, n) of their features to the target's."""
        sim = self.simulator
        true_cams = sim.robot.camera_poses(np.asarray(sim.pose, float)[None, :])
        odo_cams = sim.robot.camera_poses(np.asarray(sim.odometry_pose, float)[None, :])
        F = np.asarray(self.features(np.vstack([true_cams["left"], true_cams["right"]])), float)
        pos = np.vstack([odo_cams["left"][0, :2], odo_cams["right"][0, :2]])
        if self.tracker is not None:
            F = self.tracker.update(pos, F)
        R = F[:, : cost.n] - cost.target
        if cost.weights is not None:
            R = R * cost.weights
        return cost(F), pos, R

    def run(self, start: Any, target: Any, *, heading: float = 0.0, target_features: Any = None) -> NavigationResult:
        """Drives from ``start`` (x, y) towards ``target`` (x, y); the target's
        representation comes from an image at the target unless
        ``target_features`` is given."""
        s, t = _vec2(start, "start"), _vec2(target, "target")
        tf = self.target_features(t) if target_features is None else np.asarray(target_features, float)
        cost = self.cost(tf, self.n_outputs, self.weights)
        sim = self.simulator
        sim.reset((s[0], s[1], float(heading)))
        self.descent.reset()
        self.gradient.reset()
        if self.tracker is not None:
            self.tracker.reset()
        images0 = getattr(self.features, "images", 0)
        path = [np.array(sim.pose[:2], float)]
        odo_path = [np.array(sim.odometry_pose[:2], float)]
        costs: list[float] = []
        travelled = 0.0
        info = StepInfo()
        reason = "max_iterations"
        n_blocked = 0
        hist_P: list[np.ndarray] = []
        hist_R: list[np.ndarray] = []
        it = 0
        for it in range(self.max_iterations + 1):
            if np.hypot(*(np.array(sim.pose[:2]) - t)) <= self.success_radius:
                reason = "reached"
                break
            if it == self.max_iterations:
                break
            c, pos, R = self._measure(cost)
            costs.append(float(c.mean()))
            g = self.gradient.update(pos, c, R)
            if it == 0 and getattr(self.descent, "probe_first", False):
                # turn on the spot by 90 degrees and look again: the four camera
                # positions form a cross and the plane gives the full gradient
                sim.step(0.0, np.pi / 2, 1.0)
                c, pos, R = self._measure(cost)
                g = self.gradient.update(pos, c, R)
            info.iteration = it
            w = self.stuck_window
            info.stuck = len(odo_path) > w and float(np.hypot(*(odo_path[-1] - odo_path[-1 - w]))) < self.stuck_distance
            if info.stuck and self.stop_when_stuck:
                reason = "stuck"
                break
            info.heading = float(sim.odometry_pose[2])
            info.method = self.gradient.last_method
            info.jacobian = self.gradient.jacobian
            info.residual = R.mean(axis=0)
            info.target = cost.target
            hist_P.append(pos)
            hist_R.append(R)
            info.history = (np.concatenate(hist_P), np.concatenate(hist_R))
            d = self.descent.step(g, float(c.mean()), np.array(sim.odometry_pose[:2], float), info)
            moved, blocked = self._drive(np.asarray(d, float))
            n_blocked += int(blocked)
            info.blocked, info.last_move = blocked, moved
            travelled += moved
            path.append(np.array(sim.pose[:2], float))
            odo_path.append(np.array(sim.odometry_pose[:2], float))
        success = reason == "reached"
        return NavigationResult(
            path=np.array(path), success=success, reason=reason, iterations=it, travelled=travelled,
            costs=np.array(costs), start=s, target=t,
            images=getattr(self.features, "images", 0) - images0,
            escapes=int(getattr(self.descent, "escapes", 0)), blocked=n_blocked,
            follows=int(getattr(self.descent, "follows", 0)),
        )


# --------------------------------------------------------------------- evaluation


def sample_trials(
    n: int,
    area: Sequence[float],
    *,
    free: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    min_distance: float = 15.0,
    margin: float = 0.35,
    target: Any = None,
    start_region: Callable[[float, float], bool] | None = None,
    target_region: Callable[[float, float], bool] | None = None,
    rng: Any = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Random start and target positions (thesis 7.1.2): uniform in the area
    (``margin`` m from the border), where ``free(x, y)`` holds, at least
    ``min_distance`` apart; ``target`` fixes the target; ``start_region`` /
    ``target_region`` restrict the draws. Returns (starts (n, 2), targets (n, 2))."""
    rng = np.random.default_rng(rng)
    w, h = (float(a) for a in area)
    hx, hy = w / 2 - margin, h / 2 - margin
    if hx <= 0 or hy <= 0:
        raise ValueError(f"margin {margin} leaves no room in area {area}")

    def draw(region: Callable[[float, float], bool] | None) -> np.ndarray:
        for _ in range(100000):
            x, y = rng.uniform(-hx, hx), rng.uniform(-hy, hy)
            if (free is None or bool(free(np.array(x), np.array(y)))) and (region is None or region(x, y)):
                return np.array([x, y])
        raise ValueError("found no free position in the region")

    starts, targets = [], []
    for _ in range(int(n)):
        for _ in range(100000):
            tg = _vec2(target, "target") if target is not None else draw(target_region)
            st = draw(start_region)
            if np.hypot(*(st - tg)) >= min_distance:
                break
        else:
            raise ValueError(f"found no start and target {min_distance} m apart")
        starts.append(st)
        targets.append(tg)
    return np.array(starts), np.array(targets)


@dataclass
class TrialSummary:
    """Outcome of :func:`evaluate_trials`.

    ``success_rate``: fraction of runs that reached the target;
    ``efficiency``: mean over successful runs of optimal / travelled length
    (the thesis's measure; NaN without successes); ``efficiencies``: per
    run (NaN for failures); ``results``: the :class:`NavigationResult` s;
    ``optimal``: the optimal lengths used."""

    success_rate: float
    efficiency: float
    efficiencies: np.ndarray
    results: list[NavigationResult]
    optimal: np.ndarray
    mean_iterations: float = 0.0
    reasons: dict[str, int] = field(default_factory=dict)


def evaluate_trials(
    navigator: Navigator,
    starts: Any,
    targets: Any,
    *,
    optimal_lengths: Any = None,
    headings: Any = None,
    progress: bool = False,
    desc: str = "trials",
) -> TrialSummary:
    """Runs ``navigator`` from each start to its target.

    ``optimal_lengths`` (per trial) defaults to the direct distance; with
    obstacles pass :func:`shortest_path` lengths (thesis: A* on a 0.1 grid).
    ``headings`` default to random ones from a fixed seed."""
    S = np.asarray(starts, float).reshape(-1, 2)
    T = np.asarray(targets, float).reshape(-1, 2)
    if S.shape != T.shape:
        raise ValueError("starts and targets must have the same length")
    n = len(S)
    opt = np.hypot(*(T - S).T) if optimal_lengths is None else np.asarray(optimal_lengths, float).reshape(n)
    if headings is None:
        headings = np.random.default_rng(12345).uniform(-np.pi, np.pi, n)
    headings = np.asarray(headings, float).reshape(n)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, desc=desc, unit="run", leave=False)
    results = []
    cache: dict[tuple[float, float], np.ndarray] = {}
    for i in range(n):
        key = (float(T[i, 0]), float(T[i, 1]))
        if key not in cache:
            cache[key] = navigator.target_features(T[i])
        results.append(navigator.run(S[i], T[i], heading=float(headings[i]), target_features=cache[key]))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    ok = np.array([r.success for r in results])
    eff = np.array([opt[i] / r.travelled if r.success and r.travelled > 0 else (1.0 if r.success else np.nan)
                    for i, r in enumerate(results)])
    reasons: dict[str, int] = {}
    for r in results:
        reasons[r.reason] = reasons.get(r.reason, 0) + 1
    return TrialSummary(
        success_rate=float(ok.mean()) if n else float("nan"),
        efficiency=float(np.nanmean(eff[ok])) if ok.any() else float("nan"),
        efficiencies=eff,
        results=results,
        optimal=opt,
        mean_iterations=float(np.mean([r.iterations for r in results])) if n else 0.0,
        reasons=reasons,
    )


# --------------------------------------------------------------------- A*

_N8 = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def astar(grid: Any, start: Sequence[int], goal: Sequence[int], weights: Any = None,
          *, connectivity: int = 8) -> tuple[list[tuple[int, int]], float]:
    """Shortest path on an occupancy grid with A*.

    Parameters
    ----------
    grid : bool array (rows, cols)
        True where a cell is free.
    start, goal : (row, col)
    weights : float array (rows, cols), optional
        Cost per unit length of each cell (>= 1 keeps the Euclidean
        heuristic admissible when the smallest weight is 1; in general the
        heuristic is scaled by the smallest weight). A move costs its length
        (1 or sqrt 2 cells) times the mean weight of the two cells.
    connectivity : 4 or 8

    Returns
    -------
    (path, cost): the cells from start to goal and the path cost in cells
    (times weights); ``([], inf)`` when the goal cannot be reached.
    """
    G = np.asarray(grid, bool)
    if G.ndim != 2:
        raise ValueError(f"grid must be 2-D, got shape {G.shape}")
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
    R, C = G.shape
    W = None
    if weights is not None:
        W = np.asarray(weights, float)
        if W.shape != G.shape or not np.isfinite(W).all() or (W <= 0).any():
            raise ValueError("weights must be positive finite numbers with the grid's shape")
    s, g = (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1]))
    for name, p in (("start", s), ("goal", g)):
        if not (0 <= p[0] < R and 0 <= p[1] < C):
            raise ValueError(f"{name} {p} is outside the grid {G.shape}")
        if not G[p]:
            return [], float("inf")
    hscale = float(W[G].min()) if W is not None else 1.0
    nbrs = _N8 if connectivity == 8 else [(-1, 0), (0, -1), (0, 1), (1, 0)]
    steps = [(dr, dc, float(np.hypot(dr, dc))) for dr, dc in nbrs]

    def h(p: tuple[int, int]) -> float:
        return hscale * float(np.hypot(p[0] - g[0], p[1] - g[1]))

    best = {s: 0.0}
    parent: dict[tuple[int, int], tuple[int, int]] = {}
    heap = [(h(s), 0.0, s)]
    closed = set()
    while heap:
        f, cost, p = heapq.heappop(heap)
        if p in closed:
            continue
        if p == g:
            path = [p]
            while p in parent:
                p = parent[p]
                path.append(p)
            return path[::-1], cost
        closed.add(p)
        for dr, dc, L in steps:
            q = (p[0] + dr, p[1] + dc)
            if not (0 <= q[0] < R and 0 <= q[1] < C) or not G[q] or q in closed:
                continue
            if dr and dc and not (G[p[0] + dr, p[1]] and G[p[0], p[1] + dc]):
                continue  # no corner cutting
            step = L if W is None else L * 0.5 * (W[p] + W[q])
            nc = cost + step
            if nc < best.get(q, np.inf):
                best[q] = nc
                parent[q] = p
                heapq.heappush(heap, (nc + h(q), nc, q))
    return [], float("inf")


@dataclass
class GridMap:
    """A grid over the area: cell (row, col) has its centre at
    ``(x0 + col * res, y0 + row * res)``."""

    free: np.ndarray
    x0: float
    y0: float
    res: float

    def cell(self, xy: Any) -> tuple[int, int]:
        x, y = _vec2(xy, "position")
        r = int(round((y - self.y0) / self.res))
        c = int(round((x - self.x0) / self.res))
        return min(max(r, 0), self.free.shape[0] - 1), min(max(c, 0), self.free.shape[1] - 1)

    def xy(self, cells: Sequence[tuple[int, int]]) -> np.ndarray:
        a = np.asarray(cells, float).reshape(-1, 2)
        return np.column_stack([self.x0 + a[:, 1] * self.res, self.y0 + a[:, 0] * self.res])

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        R, C = self.free.shape
        return np.meshgrid(self.x0 + np.arange(C) * self.res, self.y0 + np.arange(R) * self.res)


def occupancy_grid(area: Sequence[float], free: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
                   *, resolution: float = 0.1, margin: float = 0.35) -> GridMap:
    """Occupancy grid of ``resolution`` m over the area (thesis: 0.1): a cell
    is free when its centre is ``margin`` m inside the border and
    ``free(x, y)`` holds there (pass ``lambda x, y: world.free(x, y, r)`` to
    inflate obstacles by the robot radius ``r``)."""
    w, h = (float(a) for a in area)
    res = float(resolution)
    if not res > 0:
        raise ValueError(f"resolution must be positive, got {resolution}")
    nx, ny = int(np.floor(w / res)) + 1, int(np.floor(h / res)) + 1
    x0, y0 = -(nx - 1) * res / 2, -(ny - 1) * res / 2
    m = GridMap(np.zeros((ny, nx), bool), x0, y0, res)
    X, Y = m.centres()
    ok = (np.abs(X) <= w / 2 - margin + 1e-9) & (np.abs(Y) <= h / 2 - margin + 1e-9)
    if free is not None:
        ok &= np.asarray(free(X, Y), bool)
    m.free = ok
    return m


def path_length(path: Any) -> float:
    """Length of a polyline (k, 2) (m)."""
    P = np.asarray(path, float).reshape(-1, 2)
    return float(np.hypot(*np.diff(P, axis=0).T).sum()) if len(P) > 1 else 0.0


def _line_free(m: GridMap, a: np.ndarray, b: np.ndarray) -> bool:
    L = float(np.hypot(*(b - a)))
    k = max(2, int(np.ceil(L / (m.res * 0.5))) + 1)
    for t in np.linspace(0.0, 1.0, k):
        if not m.free[m.cell(a + t * (b - a))]:
            return False
    return True


def shortest_path(
    grid: GridMap,
    start: Any,
    goal: Any,
    *,
    weights: Any = None,
    smooth: bool = False,
    connectivity: int = 8,
) -> tuple[np.ndarray, float]:
    """A* between two positions on a :class:`GridMap` (:func:`occupancy_grid`).

    Returns (path (k, 2) in m, length or weighted cost in m). With
    ``smooth`` the grid path is shortened by line-of-sight (string pulling;
    unweighted grids only), which removes the 8-neighbourhood's detours of
    up to 8 % on oblique segments."""
    s, g = _vec2(start, "start"), _vec2(goal, "goal")
    cells, cost = astar(grid.free, grid.cell(s), grid.cell(g), weights, connectivity=connectivity)
    if not cells:
        return np.zeros((0, 2)), float("inf")
    P = grid.xy(cells)
    P[0], P[-1] = s, g
    if smooth and weights is None:
        out = [P[0]]
        i = 0
        while i < len(P) - 1:
            j = len(P) - 1
            while j > i + 1 and not _line_free(grid, P[i], P[j]):
                j -= 1
            out.append(P[j])
            i = j
        P = np.array(out)
        return P, path_length(P)
    # cost in cells -> metres; the ends are snapped to cell centres, add the offsets
    return P, float(cost * grid.res)


# --------------------------------------------------------------------- velocity regions


def halfplane_optimal(start: Any, target: Any, *, x0: float = 0.0, speed_left: float = 1.0,
                      speed_right: float = 3.0) -> tuple[np.ndarray, float]:
    """The time-optimal path between two half-planes of different speed
    (thesis 7.2.2, fig. 7.9): two straight pieces meeting at the transition
    point ``(x0, y)`` that minimises the travel time (Snell's law); found by
    a ternary search on the convex travel time. With start and target on the
    same side the straight line is optimal. Returns (path (k, 2), time)."""
    s, t = _vec2(start, "start"), _vec2(target, "target")
    vl, vr = float(speed_left), float(speed_right)

    def v(p: np.ndarray) -> float:
        return vl if p[0] < x0 else vr

    if (s[0] - x0) * (t[0] - x0) >= 0:
        return np.array([s, t]), float(np.hypot(*(t - s))) / v(s if s[0] != x0 else t)

    def T(y: float) -> float:
        m = np.array([x0, y])
        return float(np.hypot(*(m - s))) / v(s) + float(np.hypot(*(t - m))) / v(t)

    lo, hi = min(s[1], t[1]), max(s[1], t[1])
    for _ in range(200):
        a, b = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        if T(a) < T(b):
            hi = b
        else:
            lo = a
    y = 0.5 * (lo + hi)
    return np.array([s, [x0, y], t]), T(y)


def travel_time(path: Any, speed: Callable[[float, float], float], *, piece: float = 0.02) -> float:
    """Travel time along a polyline (k, 2) with the speed field
    ``speed(x, y)`` (e.g. :class:`sfanav.sim.VelocityRegions`), integrated
    in pieces of ``piece`` m (midpoint rule)."""
    P = np.asarray(path, float).reshape(-1, 2)
    total = 0.0
    for a, b in zip(P[:-1], P[1:]):
        L = float(np.hypot(*(b - a)))
        if L <= 0:
            continue
        k = max(1, int(np.ceil(L / piece)))
        for i in range(k):
            m = a + (i + 0.5) / k * (b - a)
            total += (L / k) / float(speed(float(m[0]), float(m[1])))
    return total


def fit_coordinate_sfa(
    positions: Any,
    area: Sequence[float],
    *,
    n_components: int = 8,
    expansion: str = "rbf",
    spacing: float = 1.5,
    degree: int = 7,
) -> Callable[[np.ndarray], np.ndarray]:
    """SFA learned on the coordinates of a trajectory (thesis 7.2.2).

    The positions (N, 2) along the trajectory (in time order) are expanded
    nonlinearly and linear SFA extracts the ``n_components`` slowest
    features; the returned callable maps positions (k, 2) to them. Its
    attribute ``sfa`` is the fitted :class:`sfanav.SFA` (``beta_values_``
    for the 1/beta weights).

    ``expansion="rbf"`` (default): Gaussian bumps of width ``spacing`` on a
    grid of ``spacing`` m over the area, a function space flexible enough
    for the local distortions that velocity regions cause (a 1.5 m grid
    over 18 x 22 m: 195 functions). ``"poly"``: all monomials up to
    ``degree`` of the coordinates scaled to [-1, 1] (smooth, global; it
    cannot concentrate variance in a small region).
    """
    from .sfa import SFA, expand

    P = np.asarray(positions, float).reshape(-1, 2)
    w, h = float(area[0]), float(area[1])
    if expansion == "rbf":
        sp = float(spacing)
        if not sp > 0:
            raise ValueError(f"spacing must be positive, got {spacing}")
        cx = np.arange(-w / 2, w / 2 + 1e-9, sp)
        cy = np.arange(-h / 2, h / 2 + 1e-9, sp)
        C = np.array([(x, y) for x in cx for y in cy])

        def feat(X: np.ndarray) -> np.ndarray:
            d2 = ((X[:, None, :] - C[None, :, :]) ** 2).sum(-1)
            return np.exp(-d2 / (2 * sp * sp))
    elif expansion == "poly":
        scale = np.array([w / 2, h / 2])

        def feat(X: np.ndarray) -> np.ndarray:
            return expand(X / scale, int(degree))
    else:
        raise ValueError(f"expansion must be 'rbf' or 'poly', got {expansion!r}")
    sfa = SFA(int(n_components)).fit(feat(P))

    def model(X: np.ndarray) -> np.ndarray:
        return sfa.transform(feat(np.asarray(X, float).reshape(-1, 2)))

    model.sfa = sfa  # type: ignore[attr-defined]
    return model


# --------------------------------------------------------------------- plots


def _draw_world(ax: Any, world: Any, area: Sequence[float] | None) -> None:
    from matplotlib.patches import Circle, Polygon, Rectangle

    if area is not None:
        w, h = area
        ax.add_patch(Rectangle((-w / 2, -h / 2), w, h, fill=False, ec="0.3", lw=1.0))
    if world is None:
        return
    for o in getattr(world, "obstacles", []):
        for p in o.parts:
            if p.shape != "box":
                ax.add_patch(Circle((p.x, p.y), p.radius, fc="0.15", ec="0.15"))
                continue
            c, s = np.cos(p.yaw), np.sin(p.yaw)
            hl, hw = p.length / 2, p.width / 2
            corners = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
            xy = np.column_stack([p.x + c * corners[:, 0] - s * corners[:, 1],
                                  p.y + s * corners[:, 0] + c * corners[:, 1]])
            ax.add_patch(Polygon(xy, closed=True, fc="0.15", ec="0.15"))


def plot_cost_surface(
    xs: Any,
    ys: Any,
    features: Any,
    target_features: Any,
    path: Any,
    *,
    ns: Sequence[int] = (2,),
    weights: Any = None,
    target: Any = None,
    n_firing: int | None = None,
    world: Any = None,
    cmap: str = "viridis",
    title: str | None = None,
    dpi: int = 110,
) -> Path:
    """Spatial firing maps and cost surfaces (thesis fig. 7.7).

    ``features`` (len(ys), len(xs), m): SFA outputs on a grid of positions
    ``xs`` x ``ys`` (m); NaN rows mark places that cannot be visited. Rows:
    the firing maps of outputs ``1..n_firing`` (default ``max(ns)``; 0 for
    none), the cost to ``target_features`` for each ``n`` in ``ns``
    with the raw outputs, and (when ``weights`` is given) with the weighted
    outputs. ``target`` (x, y) is marked with a white cross."""
    from .analysis import _figure, _save

    X = np.asarray(xs, float)
    Y = np.asarray(ys, float)
    F = np.asarray(features, float)
    if F.ndim != 3 or F.shape[:2] != (len(Y), len(X)):
        raise ValueError(f"features must have shape (len(ys), len(xs), m) = ({len(Y)}, {len(X)}, m), got {F.shape}")
    ns = [int(n) for n in ns]
    m = F.shape[2]
    if not ns or min(ns) < 1 or max(ns) > m:
        raise ValueError(f"ns must be in 1..{m}, got {ns}")
    nf = max(ns) if n_firing is None else int(n_firing)
    if not 0 <= nf <= m:
        raise ValueError(f"n_firing must be in 0..{m}, got {n_firing}")
    rowsets: list[list[tuple[str, np.ndarray]]] = []
    if nf:
        rowsets.append([(f"s{j + 1}", F[:, :, j]) for j in range(nf)])
    rowsets.append([(f"C, n={n}", SlowFeatureCost(target_features, n)(F)) for n in ns])
    if weights is not None:
        rowsets.append([(f"C 1/beta, n={n}", SlowFeatureCost(target_features, n, weights)(F)) for n in ns])
    ncol = max(len(r) for r in rowsets)
    aspect = (Y[-1] - Y[0]) / max(X[-1] - X[0], 1e-9) if len(X) > 1 and len(Y) > 1 else 1.0
    fig = _figure(1.9 * ncol + 0.4, (1.9 * aspect + 0.35) * len(rowsets) + (0.4 if title else 0))
    axes = fig.subplots(len(rowsets), ncol, squeeze=False)
    for r, rs in enumerate(rowsets):
        for c in range(ncol):
            ax = axes[r, c]
            if c >= len(rs):
                ax.set_axis_off()
                continue
            name, V = rs[c]
            ax.pcolormesh(X, Y, np.ma.masked_invalid(V), cmap=cmap, shading="nearest")
            _draw_world(ax, world, None)
            if target is not None and name.startswith("C"):
                tx, ty = _vec2(target, "target")
                ax.plot([tx], [ty], "x", color="white", ms=7, mew=2)
            ax.set_title(name, fontsize="small")
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
    if title:
        fig.suptitle(title)
    return _save(fig, path, dpi)


def plot_trajectories(
    results: Sequence[NavigationResult],
    path: Any,
    *,
    world: Any = None,
    area: Sequence[float] | None = None,
    background: tuple[Any, Any, Any] | None = None,
    optimal: Sequence[Any] | None = None,
    regions: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    titles: Sequence[str] | None = None,
    title: str | None = None,
    cols: int = 4,
    dpi: int = 110,
) -> Path:
    """Navigation trajectories (thesis figs. 7.3, 7.6, 7.9c, 7.10c): one
    panel per run, start as a black cross, target as a white circle, the
    driven path in red (success) or orange (failure), the optimal path
    (when ``optimal`` gives one per run) dashed blue, or white over a
    ``background``; obstacles in black.
    ``background`` = (xs, ys, values) is drawn under the paths (e.g. a cost
    surface); ``regions(X, Y)`` shades slow-velocity regions."""
    from .analysis import _figure, _save

    n = len(results)
    if n == 0:
        raise ValueError("no results to plot")
    cols = max(1, min(int(cols), n))
    rows = (n + cols - 1) // cols
    if area is None and world is not None:
        area = world.area
    aspect = area[1] / area[0] if area is not None else 1.0
    fig = _figure(2.6 * cols + 0.2, 2.6 * aspect * rows + 0.3 + (0.4 if title else 0))
    axes = fig.subplots(rows, cols, squeeze=False)
    for i in range(rows * cols):
        ax = axes[i // cols, i % cols]
        if i >= n:
            ax.set_axis_off()
            continue
        r = results[i]
        if background is not None:
            bx, by, bv = background
            ax.pcolormesh(np.asarray(bx), np.asarray(by), np.ma.masked_invalid(np.asarray(bv, float)),
                          cmap="viridis", shading="nearest")
        elif regions is not None and area is not None:
            gx = np.linspace(-area[0] / 2, area[0] / 2, 181)
            gy = np.linspace(-area[1] / 2, area[1] / 2, 221)
            GX, GY = np.meshgrid(gx, gy)
            ax.pcolormesh(gx, gy, np.asarray(regions(GX, GY), float), cmap="Greys", vmin=0, vmax=3,
                          shading="nearest")
        _draw_world(ax, world, area)
        if optimal is not None and optimal[i] is not None and len(optimal[i]):
            op = np.asarray(optimal[i], float)
            if background is not None:  # the thesis's white line on the colour map
                ax.plot(op[:, 0], op[:, 1], "-", color="white", lw=1.6, zorder=2)
            else:
                ax.plot(op[:, 0], op[:, 1], "--", color="tab:blue", lw=1.2, zorder=2)
        P = r.path
        ax.plot(P[:, 0], P[:, 1], "-", color="tab:red" if r.success else "tab:orange", lw=1.3, zorder=3)
        ax.plot(P[:, 0], P[:, 1], ".", color="tab:red" if r.success else "tab:orange", ms=2, zorder=3)
        ax.plot([r.start[0]], [r.start[1]], "x", color="black", ms=8, mew=2, zorder=4)
        ax.plot([r.target[0]], [r.target[1]], "o", mfc="white", mec="black", ms=7, zorder=4)
        if area is not None:
            ax.set_xlim(-area[0] / 2, area[0] / 2)
            ax.set_ylim(-area[1] / 2, area[1] / 2)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        label = titles[i] if titles is not None else ("reached" if r.success else r.reason)
        ax.set_title(label, fontsize="small")
    if title:
        fig.suptitle(title)
    return _save(fig, path, dpi)
