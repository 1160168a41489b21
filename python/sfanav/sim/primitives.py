"""The building blocks of a garden world (:mod:`sfanav.sim.world`): the
vertical primitives the ray caster intersects exactly (``"cylinder"``,
``"box"``, ``"ellipsoid"``), the garden objects made of them, and the
constants that say which objects may stand inside the free area and which
parts block the robot. Coordinates and angles as in :mod:`sfanav.sim.world`."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

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
    ``marker_id`` is set on marker boards.

    ``seasons``: None (default) for an object that is always there, or the
    names of the seasons (keys of :data:`sfanav.sim.conditions.SEASONS`:
    ``"spring"``, ``"summer"``, ``"autumn"``, ``"winter"``) in which it is
    there: a *transient* object, such as garden furniture in summer or a
    snowman in winter (:mod:`sfanav.sim.transient`). The renderer draws it,
    and its shadow, only under a :class:`~sfanav.sim.conditions.Lighting`
    whose season has one of these names (a Lighting without a season counts
    as summer; a season with another name, e.g. a custom one, shows no
    transient object). Stored as a sorted tuple in the order of the year.

    Raises
    ------
    ValueError
        ``seasons`` empty, a bare string, or holding a name that is not a
        named season, or a duplicate.

    Examples
    --------
    >>> pool = WorldObject("paddling_pool", 1.0, 2.0, 1.0,
    ...                    [Primitive("cylinder", 1.0, 2.0, 0.0, 0.35, "pool", radius=1.0)],
    ...                    seasons=["summer"])
    >>> pool.present("summer"), pool.present("winter"), pool.present(None)
    (True, False, True)
    """

    kind: str
    x: float
    y: float
    radius: float
    parts: list[Primitive]
    obstacle: bool = False
    marker_id: int | None = None
    seasons: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if self.seasons is not None:
            self.seasons = season_names(self.seasons, f"object {self.kind!r} seasons")

    @property
    def transient(self) -> bool:
        """Whether the object is there in some seasons only."""
        return self.seasons is not None

    def present(self, season: str | None) -> bool:
        """Whether the object is there in the season named ``season``
        (None: no season, counted as summer)."""
        return self.seasons is None or (season if season is not None else "summer") in self.seasons


def posed(parts: list[Primitive], x: float, y: float, yaw: float,
          about: tuple[float, float] = (0.0, 0.0)) -> list[Primitive]:
    """An object's parts turned by ``yaw`` (rad, counter-clockwise) about
    ``about`` (its anchor, m) and put down with that anchor at ``(x, y)``
    (m): new :class:`Primitive` objects, the given ones unchanged.

    >>> float(posed([Primitive("box", 1.0, 0.0, 0.0, 1.0, "t", length=1.0, width=1.0)], 5.0, 0.0, np.pi / 2)[0].y)
    1.0
    """
    ax, ay = about
    c, s = np.cos(yaw), np.sin(yaw)
    return [Primitive(**{**asdict(p), "x": x + c * (p.x - ax) - s * (p.y - ay),
                         "y": y + s * (p.x - ax) + c * (p.y - ay), "yaw": p.yaw + yaw}) for p in parts]


def season_names(value: Any, what: str = "seasons") -> tuple[str, ...]:
    """The named seasons in ``value`` (a non-empty sequence of names from
    :data:`sfanav.sim.conditions.SEASONS`) as a tuple in the order of the
    year; ValueError for an empty sequence, a bare string, an unknown name
    or a duplicate."""
    from .conditions import SEASONS

    if isinstance(value, str) or not isinstance(value, (list, tuple)) or not value:
        raise ValueError(f"{what} must be a non-empty list of season names ({', '.join(SEASONS)}), got {value!r}")
    bad = [v for v in value if v not in SEASONS]
    if bad:
        raise ValueError(f"{what}: unknown season names {bad!r}; available: {', '.join(SEASONS)}")
    if len(set(value)) != len(value):
        raise ValueError(f"{what} names a season twice: {list(value)!r}")
    return tuple(s for s in SEASONS if s in value)
