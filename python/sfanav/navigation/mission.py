"""One navigation to a goal with a trained localizer, in a simulated world:
:func:`navigate` builds the closed loop (the robot's two cameras render the
world, the localizer turns every image into a position in its map, a
:class:`MetricDescent` steers along the exploration run's
:class:`GeodesicField`) and reports the trajectory, success and efficiency
as a :class:`Mission`.

The map is the localizer's: metres in the frame it was trained in (the world
for a model trained on ground truth, the training run's odometry frame for
one trained without). The goal is a position in that map, or an image: the
robot then goes where the localizer places that image. The geodesic field
is built from the positions the localizer's readout was fitted to
(``Localizer.training_positions_``: its exploration run in its own map, the
positions learned from odometry for a model trained without ground truth),
so it lives in the same map and needs no ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .cost import as_vector2
from .descent import MetricDescent
from .features import MetricFeatures
from .geodesic import GeodesicField
from .navigator import NavigationResult, Navigator
from .planning import occupancy_grid, shortest_path


@dataclass
class Mission:
    """The outcome of :func:`navigate`.

    Attributes
    ----------
    result : NavigationResult
        The run: true path (world frame), success, stops, travelled length.
    map_goal : ndarray (2,)
        The goal in the localizer's map (metres).
    world_goal : ndarray (2,)
        The goal in the world, where success is measured.
    optimal : float
        Length of the shortest collision-free path from start to goal (m):
        A* (8-connected) on a 0.1 m grid with obstacles inflated by the
        robot's radius (thesis 7.1.2), or the straight distance in a world
        without obstacles.
    optimal_path : ndarray (k, 2) or None
        The any-angle shortest path, for plots (None without obstacles).
    field : GeodesicField or None
        The exploration run's field the descent used.
    """

    result: NavigationResult
    map_goal: np.ndarray
    world_goal: np.ndarray
    optimal: float
    optimal_path: np.ndarray | None
    field: GeodesicField | None

    @property
    def efficiency(self) -> float:
        """Optimal over travelled length for a success (thesis 7.1.2), NaN for a failure."""
        r = self.result
        if not r.success:
            return float("nan")
        return 1.0 if r.travelled <= 0 else min(1.0, self.optimal / r.travelled)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able summary (no path)."""
        r = self.result
        return {"success": bool(r.success), "reason": r.reason, "stops": int(r.iterations),
                "travelled (m)": float(r.travelled), "optimal (m)": float(self.optimal),
                "efficiency": None if not r.success else float(self.efficiency),
                "start": [float(v) for v in r.start], "map goal": [float(v) for v in self.map_goal],
                "world goal": [float(v) for v in self.world_goal],
                "end": [float(v) for v in r.path[-1]], "images": int(r.images), "blocked moves": int(r.blocked)}


def image_goal(localizer: Any, image: Any) -> np.ndarray:
    """The position (2,) in the localizer's map of one panorama (H, W[, C])
    in the localizer's input format."""
    xy = np.asarray(localizer.predict(np.asarray(image)[None]), float)
    return xy[0]


MAP_MARGIN = 0.25
"""How far beyond the exploration run a goal may lie, as a fraction of the
larger side of the box around the run's positions (at least
``MIN_MAP_MARGIN`` m): the localizer knows the places the run saw, and
nothing far outside them."""


MIN_MAP_MARGIN = 1.0


def check_goal_in_map(goal: Any, exploration: Any, what: str = "goal") -> np.ndarray:
    """``goal`` (x, y) as an array, checked to lie in the map: the box around
    the exploration run's positions (N, 2), widened on every side by
    ``MAP_MARGIN`` of its larger side (at least ``MIN_MAP_MARGIN`` m).

    Raises
    ------
    ValueError
        For a goal that is not two finite numbers, or one outside the map
        (the message gives the map's extent), named ``what``.
    """
    g = as_vector2(goal, what)
    P = np.asarray(exploration, float).reshape(-1, 2)
    P = P[np.isfinite(P).all(axis=1)]
    if not len(P):
        return g
    lo, hi = P.min(axis=0), P.max(axis=0)
    margin = max(MIN_MAP_MARGIN, MAP_MARGIN * float((hi - lo).max()))
    if ((g < lo - margin) | (g > hi + margin)).any():
        raise ValueError(f"{what} ({g[0]:.6g}, {g[1]:.6g}) is outside the map: the exploration run spans "
                         f"x {lo[0]:.2f}..{hi[0]:.2f} m, y {lo[1]:.2f}..{hi[1]:.2f} m, and a goal may lie up to "
                         f"{margin:.2f} m beyond it")
    return g


def navigate(localizer: Any, world: Any, camera: Any, start: Any, goal: Any, *, exploration: Any = None,
             heading: float = 0.0, world_goal: Any = None, robot: Any = None, geodesic: bool = True,
             success_radius: float = 0.5, max_iterations: int = 400, seed: int = 0) -> Mission:
    """Drives a simulated two-camera robot from ``start`` to ``goal`` with a
    fitted :class:`sfanav.Localizer`.

    Parameters
    ----------
    localizer : sfanav.Localizer
        Fitted; its input format is ``camera``'s.
    world : sfanav.sim.World
    camera : sfanav.sim.PanoramicCamera
        The camera both mounts render with (the localizer's input size).
    start : (x, y)
        Start position in the world (m).
    goal : (x, y)
        Goal in the localizer's map (m): a position, or :func:`image_goal`
        of a target image.
    exploration : array (N, 2), optional
        The exploration run's positions in the map: the geodesic field's
        run. Default ``localizer.training_positions_``; a localizer without
        them (a model file written before they were stored) needs them
        given, e.g. its estimates of its training images.
    heading : float
        Start heading (rad).
    world_goal : (x, y), optional
        Where success is measured (default ``goal``: map and world agree,
        as for a model trained on ground truth, or on the simulator's
        odometry, which starts at the true first pose).
    robot : sfanav.sim.Robot, optional
        Default ``Robot.two_cameras()`` with the default odometry noise.
    geodesic : bool
        Steer along the exploration run's geodesic field (default) or
        straight at the goal.
    success_radius, max_iterations
        As :class:`Navigator` (thesis 0.5 m, 400 stops).
    seed : int
        Odometry noise seed.

    Returns
    -------
    Mission

    Raises
    ------
    ValueError
        A start or goal that is not two finite numbers, a start inside an
        obstacle, a goal outside the map (:func:`check_goal_in_map`, when
        the exploration positions are known), a localizer that is not
        fitted, no exploration positions.
    """
    from ..sim.robot import Robot, Simulator

    s = as_vector2(start, "start")
    g = as_vector2(goal, "goal")
    wg = g if world_goal is None else as_vector2(world_goal, "world_goal")
    robot = robot if robot is not None else Robot.two_cameras()
    r = float(getattr(robot, "size", 0.7)) / 2
    if not bool(world.free(np.array(s[0]), np.array(s[1]), r)):
        raise ValueError(f"start {tuple(float(v) for v in s)} is not free ground for the robot (an obstacle, or "
                         f"closer than {r:g} m to the border or an object)")
    if exploration is None and geodesic:
        exploration = getattr(localizer, "training_positions_", None)
        if exploration is None:
            raise ValueError("the localizer does not store the positions it was fitted to (a model file written "
                             "before sfanav stored them): pass exploration=, e.g. its estimates of its training "
                             "images, or geodesic=False")
    known = exploration if exploration is not None else getattr(localizer, "training_positions_", None)
    if known is not None:
        check_goal_in_map(g, known)
    field = GeodesicField(np.asarray(exploration, float)) if geodesic else None
    sim = Simulator(world, camera, robot, seed=int(seed))
    feats = MetricFeatures(localizer, sim.renderer, camera)
    navi = Navigator(sim, feats, MetricDescent(field=field), n_outputs=2, success_radius=success_radius,
                     max_iterations=max_iterations)
    result = navi.run(s, wg, heading=float(heading), target_features=g)
    path = None
    if getattr(world, "obstacles", None):
        grid = occupancy_grid(world.area, lambda x, y: world.free(x, y, r), resolution=0.1, margin=r)
        optimal = shortest_path(grid, s, wg)[1]  # the thesis's optimum: A* on the grid
        path = shortest_path(grid, s, wg, smooth=True)[0]
    else:
        optimal = float(np.hypot(*(wg - s)))
    return Mission(result, g, wg, float(optimal), None if path is None else np.asarray(path), field)
