"""The built-in garden simulator (worlds, cameras, robot, odometry,
trajectories, presets): pure NumPy, nothing to download."""

from .render import Lighting, OmniCamera, PanoramicCamera, Renderer, bearings, camera_from_dict, column_of_bearing
from .textures import Texture
from .world import DynamicCylinder, Primitive, World, WorldObject

__all__ = [
    "World",
    "WorldObject",
    "Primitive",
    "DynamicCylinder",
    "Texture",
    "Lighting",
    "PanoramicCamera",
    "OmniCamera",
    "Renderer",
    "bearings",
    "column_of_bearing",
    "camera_from_dict",
]
