"""Descents: how a robot steps along the estimated gradient, with one
interface (``reset()``, ``step(gradient, cost, position, info) ->
displacement``). :class:`ThesisDescent` (step scale ``eta``, momentum
``gamma``, thesis 7.1), :class:`RobustDescent` (normalised steps sized by the
cost's distance estimate, wall sliding, plateau escape) and
:class:`MetricDescent` (straight for the target in the learned metric
space, round obstacles along a :class:`~sfanav.navigation.GeodesicField`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..odometry.tracker import rigid_fit

if TYPE_CHECKING:
    from .geodesic import GeodesicField


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
        return rigid_fit(P, Q)

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
