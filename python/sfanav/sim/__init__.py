"""The built-in garden simulator: pure NumPy, nothing to download.

* :class:`World` (``world.py``): seeded garden generation (thesis 4.1), JSON.
* :class:`Renderer` (``render.py``), :class:`PanoramicCamera`,
  :class:`OmniCamera` (``cameras.py``): the ray caster.
* :class:`Lighting`, :class:`Season` (``conditions.py``): recording
  conditions, light and season; ``transient.py``: objects that come and go
  with the seasons (``World.generate(transient=...)``).
* :class:`GardenChanges` (``changes.py``): a garden whose objects are
  moved, removed or added between runs (``RunSpec(changes=...)``).
* :class:`Robot`, :class:`OdometryNoise`, :func:`simulate_odometry`,
  :class:`GyroNoise`, :func:`simulate_gyro`, :class:`Simulator`
  (``robot.py``): kinematics, camera mounts, odometry, a yaw gyro,
  closed-loop stepping.
* ``surveys``: surveys as robot mowers drive them (serpentine, perimeter
  then serpentine, spiral, crossing grid, random bounce).
* ``trajectories``: grid exploration, random lines, border loop, line
  segments, random walks, velocity regions.
* :class:`UnevenGround`, :class:`HeightField`, :class:`Attitude`
  (``terrain.py``): uneven ground that tilts and bobs the camera.
* ``presets``: the thesis's scenes; ``recording``: :func:`simulate` writes a preset's dataset.
"""

from . import presets, recording, surveys, trajectories
from .cameras import (
    OmniCamera,
    PanoramicCamera,
    bearings,
    camera_from_dict,
    column_of_bearing,
)
from .changes import GardenChanges
from .conditions import SEASONS, Lighting, Season, season_of_year
from .presets import PRESETS
from .recording import simulate
from .render import Renderer
from .robot import (
    GyroNoise,
    OdometryNoise,
    Robot,
    Simulator,
    reframed_odometry,
    simulate_gyro,
    simulate_odometry,
    unicycle_step,
    wrap_angle,
)
from .terrain import Attitude, HeightField, UnevenGround
from .textures import Texture
from .trajectories import Trajectory, VelocityRegions
from .primitives import Primitive, WorldObject
from .world import DynamicCylinder, MarkerOcclusion, World

__all__ = [
    "World",
    "WorldObject",
    "Primitive",
    "DynamicCylinder",
    "MarkerOcclusion",
    "GardenChanges",
    "Texture",
    "Lighting",
    "Season",
    "SEASONS",
    "season_of_year",
    "PanoramicCamera",
    "OmniCamera",
    "Renderer",
    "Robot",
    "OdometryNoise",
    "Simulator",
    "simulate_odometry",
    "GyroNoise",
    "reframed_odometry", "simulate_gyro",
    "surveys",
    "unicycle_step",
    "wrap_angle",
    "Trajectory",
    "VelocityRegions",
    "trajectories",
    "presets",
    "recording",
    "PRESETS",
    "simulate",
    "bearings",
    "column_of_bearing",
    "camera_from_dict",
    "Attitude",
    "HeightField",
    "UnevenGround",
]
