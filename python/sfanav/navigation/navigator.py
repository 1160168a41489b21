"""The closed loop (thesis 7.1): :class:`Navigator` drives a simulated
two-camera robot towards a target image, stop by stop (features, cost,
gradient, descent), and returns a :class:`NavigationResult`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .cost import SlowFeatureCost, as_vector2
from .descent import StepInfo, ThesisDescent
from .gradient import PlaneGradient

if TYPE_CHECKING:
    from ..odometry.tracker import MapTracker


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
        t = as_vector2(target, "target")
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
        residuals = getattr(cost, "residuals", None)
        if residuals is not None:  # a cost that is not a distance of features (e.g. an image difference)
            return cost(F), pos, np.asarray(residuals(F), float)
        R = F[:, : cost.n] - cost.target
        if cost.weights is not None:
            R = R * cost.weights
        return cost(F), pos, R

    def run(self, start: Any, target: Any, *, heading: float = 0.0, target_features: Any = None) -> NavigationResult:
        """Drives from ``start`` (x, y) towards ``target`` (x, y); the target's
        representation comes from an image at the target unless
        ``target_features`` is given."""
        s, t = as_vector2(start, "start"), as_vector2(target, "target")
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


