"""The building blocks of a garden world (:mod:`sfanav.sim.world`): the
vertical primitives the ray caster intersects exactly (``"cylinder"``,
``"box"``, ``"ellipsoid"``), the garden objects made of them, and the
constants that say which objects may stand inside the free area and which
parts block the robot. Coordinates and angles as in :mod:`sfanav.sim.world`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INNER_TYPES = ("tree", "bush", "pole", "shed")  # objects that can stand inside the area


PATCH_KINDS = ("patio", "path", "bed")


# parts whose bottom is at least this high (m) do not block the robot (a mower
# drives under a tree's crown, not through its trunk)
BLOCK_HEIGHT = 0.6


SHAPES = ("cylinder", "box", "ellipsoid")


@dataclass
class Primitive:
    """One vertical solid.

    Attributes
    ----------
    shape : ``"cylinder"``, ``"box"`` or ``"ellipsoid"``
    x, y : float
        Centre of the footprint (m).
    z0, z1 : float
        Vertical extent (m). For an ellipsoid: centre ``(z0 + z1) / 2``,
        vertical semi-axis ``(z1 - z0) / 2``.
    radius : float
        Cylinder radius or the ellipsoid's horizontal semi-axis (m).
    length, width : float
        Box size along its ``yaw`` direction and across it (m).
    yaw : float
        Box orientation (rad, counter-clockwise from +x).
    texture : str
        Key of ``World.textures`` for the sides.
    front : str or None
        Box only: a texture stretched over the face whose outward normal
        points along ``yaw - pi/2`` (e.g. a marker).
    """

    shape: str
    x: float
    y: float
    z0: float
    z1: float
    texture: str
    radius: float = 0.0
    length: float = 0.0
    width: float = 0.0
    yaw: float = 0.0
    front: str | None = None

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ValueError(f"unknown primitive shape {self.shape!r}; available: {', '.join(SHAPES)}")
        if not self.z1 > self.z0:
            raise ValueError(f"primitive needs z1 > z0, got z0={self.z0}, z1={self.z1}")
        if self.shape in ("cylinder", "ellipsoid") and not self.radius > 0:
            raise ValueError(f"{self.shape} needs a positive radius, got {self.radius}")
        if self.shape == "box" and not (self.length > 0 and self.width > 0):
            raise ValueError(f"box needs positive length and width, got {self.length} x {self.width}")

    @property
    def bound_radius(self) -> float:
        """Radius of a circle around (x, y) that contains the footprint (m)."""
        if self.shape == "box":
            return 0.5 * float(np.hypot(self.length, self.width))
        return self.radius


@dataclass
class WorldObject:
    """A garden object: a kind, an anchor, a footprint radius and its parts.

    ``obstacle`` objects stand inside the free area and block the robot;
    ``marker_id`` is set on marker boards."""

    kind: str
    x: float
    y: float
    radius: float
    parts: list[Primitive]
    obstacle: bool = False
    marker_id: int | None = None
