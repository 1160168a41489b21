""":class:`PointSimulator`: a robot without a body or images, whose features
are any function of its camera poses; for navigation on coordinate
features (thesis 7.2.2) and for fast tests of the closed loop."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np


class PointSimulator:
    """A simulator without rendering, for features from coordinates: the
    same interface as :class:`sfanav.sim.Simulator` (``pose``,
    ``odometry_pose``, ``robot``, ``reset``, ``step``) with exact odometry
    and moves refused outside the area or into ``world``'s obstacles."""

    def __init__(self, area: Sequence[float] | None = None, robot: Any = None, *, world: Any = None,
                 pose: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        from .robot import Robot

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
        from .robot import unicycle_step

        new = unicycle_step(self.pose, v, omega, dt)
        self.time += dt
        n = max(1, int(np.ceil(abs(v) * dt / 0.05)))
        path = np.array([unicycle_step(self.pose, v, omega, dt * k / n) for k in range(1, n + 1)])
        if not bool(self._free(path[:, 0], path[:, 1]).all()):
            return False
        self.pose = new
        self.odometry_pose = new.copy()
        return True
