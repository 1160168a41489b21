"""Recording conditions of the garden simulator: light and season.

A :class:`Lighting` is one condition under which the renderer
(:mod:`sfanav.sim.render`) draws the garden: how bright, what colour, where
the sun stands, how much sky light fills the shade, whether objects cast
shadows, and optionally the :class:`Season`: the colours of lawn, foliage
and sky and how bare the deciduous crowns are. Presets
(:mod:`sfanav.sim.presets`) map condition names to Lightings, and datasets
store them in their metadata (:meth:`Lighting.to_dict`,
:meth:`Lighting.from_dict`).

>>> from sfanav.sim import Lighting, Season
>>> winter = Lighting(intensity=0.8, sun_elevation_deg=12.0, season=Season.winter())
>>> Lighting.from_dict(winter.to_dict()) == winter
True
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

#: kinds of world objects (:data:`sfanav.sim.world.OBJECT_TYPES`) whose leaves
#: change with the seasons; conifers are evergreen
DECIDUOUS_KINDS = ("tree", "bush", "hedge")


#: edge of the world-space cells (m) in which a thinned crown has a leaf or a gap
LEAF_CELL = 0.08

#: the vegetation textures a season's ``texture_seed`` moves (:meth:`Season.texture_offset`)
TEXTURE_PARTS = ("foliage", "lawn")

#: range (m) of the offsets drawn by :meth:`Season.texture_offset`; far larger than any texture tile
TEXTURE_SHIFT_RANGE = 1000.0


def _rgb(value: Any, what: str) -> tuple[float, float, float]:
    try:
        rgb = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be three non-negative numbers (R, G, B), got {value!r}") from None
    if len(rgb) != 3 or not all(np.isfinite(rgb)) or min(rgb) < 0:
        raise ValueError(f"{what} must be three non-negative numbers (R, G, B), got {value!r}")
    return rgb  # type: ignore[return-value]


@dataclass(frozen=True)
class Season:
    """How the garden looks in a season: colour multipliers and leaf cover.

    The world's own colours are summer's: :meth:`summer` changes nothing,
    and a :class:`Lighting` without a season renders exactly as one with
    ``Season.summer()``. Named seasons: :meth:`spring`, :meth:`summer`,
    :meth:`autumn`, :meth:`winter`, or ``SEASONS[name]``.

    Attributes
    ----------
    name : str
        A label stored with the condition (``"winter"``, ``"custom"``).
    ground : (R, G, B)
        Multiplies the lawn's colour (not the patio, gravel path or flower
        beds painted on it).
    foliage : (R, G, B)
        Multiplies the colour of deciduous foliage: the leaves of trees,
        bushes and hedges (objects of ``DECIDUOUS_KINDS``) and the distant
        tree line. Conifers are evergreen and keep their colour.
    sky : (R, G, B)
        Multiplies the sky (gradient and clouds) and the horizon colour far
        surfaces fade to.
    leaf_cover : float in [0, 1]
        How much of its leaves a deciduous crown (trees and bushes; hedges
        stay dense) still has. The renderer thins crowns rather than shrink
        them, which costs one hash per crown pixel: a ray meeting a crown
        stops there with probability ``leaf_cover`` and otherwise passes
        through to what lies behind (the trunk, other objects, sky or
        ground). The draw is a fixed hash of the hit point's
        ``LEAF_CELL``-metre cell in world coordinates (:meth:`leafy`), so a
        bare crown is a stipple fixed in the world: the same pose renders
        the same image. The crowns' shadows on the lawn weaken to
        ``leaf_cover`` of full shadow, and the distant tree line lets
        ``(1 - leaf_cover) / 2`` of the sky through (half of it evergreen).
        At 1 crowns are solid.
    texture_seed : int >= 0 or None
        Changes the fine structure of the vegetation with the season (leaves
        grow, fall and move, grass is mown or grows), not only its colour:
        the renderer samples the leaf texture of deciduous foliage (the
        parts recoloured by ``foliage``) and the lawn's grass detail (on the
        lawn share of the ground, not patio, paths or beds) shifted by a
        pseudo-random offset drawn from this seed (:meth:`texture_offset`,
        up to ``TEXTURE_SHIFT_RANGE`` metres, wrapping in the tiled
        textures). The same world point then shows a different leaf or
        grass pattern in seasons with different seeds, while the textures'
        colour and gray-level statistics stay the same. Bark, stone, wood,
        paving, painted patches, markers, conifers, the distant tree line
        and transient objects keep their texture. None (default): no shift,
        the season renders pixel-identically to one without this option.
        :func:`season_of_year` blends give None.
    sun_elevation_deg : (low, high)
        Typical elevations of the daytime sun in the season (degrees, for
        central Europe, about 51 deg N), for drawing a :class:`Lighting`'s
        ``sun_elevation_deg`` (the presets do); rendering uses the
        Lighting's sun only.

    Raises
    ------
    ValueError
        A colour that is not three finite non-negative numbers, a
        ``leaf_cover`` outside [0, 1], a sun elevation range outside
        (0, 90] or with low > high, an empty name, a ``texture_seed`` that
        is not None or a non-negative integer.

    Examples
    --------
    >>> Season.autumn().leaf_cover
    0.65
    >>> Season("late winter", ground=(1.15, 0.85, 1.2), leaf_cover=0.2, sun_elevation_deg=(10, 25)).name
    'late winter'
    >>> Season.spring().texture_seed is None
    True
    >>> from dataclasses import replace
    >>> replace(Season.autumn(), texture_seed=3).texture_seed
    3
    """

    name: str = "custom"
    ground: tuple[float, float, float] = (1.0, 1.0, 1.0)
    foliage: tuple[float, float, float] = (1.0, 1.0, 1.0)
    sky: tuple[float, float, float] = (1.0, 1.0, 1.0)
    leaf_cover: float = 1.0
    sun_elevation_deg: tuple[float, float] = (25.0, 60.0)
    texture_seed: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"season name must be a non-empty string, got {self.name!r}")
        for f in ("ground", "foliage", "sky"):
            object.__setattr__(self, f, _rgb(getattr(self, f), f"season {f} colour multiplier"))
        try:
            cover = float(self.leaf_cover)
        except (TypeError, ValueError):
            cover = float("nan")
        if not 0 <= cover <= 1:
            raise ValueError(f"season leaf_cover must be in [0, 1], got {self.leaf_cover!r}")
        object.__setattr__(self, "leaf_cover", cover)
        try:
            lo, hi = (float(v) for v in self.sun_elevation_deg)
        except (TypeError, ValueError):
            lo, hi = float("nan"), float("nan")
        if not (0 < lo <= hi <= 90):
            raise ValueError("season sun_elevation_deg must be (low, high) degrees with 0 < low <= high <= 90, "
                             f"got {self.sun_elevation_deg!r}")
        object.__setattr__(self, "sun_elevation_deg", (lo, hi))
        if self.texture_seed is not None:
            seed = self.texture_seed
            if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
                raise ValueError(f"season texture_seed must be None or an integer >= 0, got {seed!r}")
            object.__setattr__(self, "texture_seed", int(seed))

    # ------------------------------------------------------------ named seasons

    @classmethod
    def spring(cls) -> "Season":
        """Fresh light-green leaves, not all out yet; a lusher lawn."""
        return cls("spring", ground=(0.92, 1.08, 0.90), foliage=(1.15, 1.15, 0.85), leaf_cover=0.9,
                   sun_elevation_deg=(20.0, 50.0))

    @classmethod
    def summer(cls) -> "Season":
        """The world's own colours, full crowns, a high sun."""
        return cls("summer", sun_elevation_deg=(30.0, 60.0))

    @classmethod
    def autumn(cls) -> "Season":
        """Orange-brown leaves, a third of them fallen; a browner lawn, hazier sky."""
        return cls("autumn", ground=(1.12, 0.92, 0.85), foliage=(2.5, 0.85, 0.75), sky=(1.05, 1.0, 0.95),
                   leaf_cover=0.65, sun_elevation_deg=(12.0, 38.0))

    @classmethod
    def winter(cls) -> "Season":
        """Bare grey-brown twigs, a grey-green to brownish lawn, a pale sky, a low sun."""
        return cls("winter", ground=(1.05, 0.85, 1.1), foliage=(1.5, 0.7, 0.9), sky=(1.08, 1.04, 0.94),
                   leaf_cover=0.15, sun_elevation_deg=(6.0, 16.0))

    # ------------------------------------------------------------ rendering

    def leafy(self, x: Any, y: Any, z: Any) -> np.ndarray:
        """Whether a thinned crown has a leaf (stops a ray) at world points
        ``x, y, z`` (m, arrays of one shape): a fixed hash of each point's
        ``LEAF_CELL`` cell below ``leaf_cover``. Returns a bool array of
        that shape; all True at ``leaf_cover`` 1."""
        x, y, z = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float), np.asarray(z, float))
        if self.leaf_cover >= 1:
            return np.ones(x.shape, bool)
        c = [np.floor(v / LEAF_CELL).astype(np.int64).astype(np.uint64) for v in (x, y, z)]
        h = (c[0] * np.uint64(0x9E3779B97F4A7C15)) ^ (c[1] * np.uint64(0xC2B2AE3D27D4EB4F)) ^ (
            c[2] * np.uint64(0x165667B19E3779F9))
        h ^= h >> np.uint64(33)
        h *= np.uint64(0xFF51AFD7ED558CCD)
        h ^= h >> np.uint64(33)
        h *= np.uint64(0xC4CEB9FE1A85EC53)
        h ^= h >> np.uint64(33)
        u = (h >> np.uint64(11)).astype(np.float64) * (1.0 / 2**53)
        return u < self.leaf_cover

    def texture_offset(self, part: str) -> tuple[float, float]:
        """The shift (du, dv) in metres with which the renderer samples the
        vegetation texture ``part`` (one of ``TEXTURE_PARTS``: ``"foliage"``
        for deciduous leaves, ``"lawn"`` for the grass detail) in this
        season: (0, 0) without a ``texture_seed``, otherwise two numbers in
        [0, ``TEXTURE_SHIFT_RANGE``) drawn from the seed and the part.
        ValueError for an unknown part.

        >>> Season().texture_offset("lawn")
        (0.0, 0.0)
        >>> Season(texture_seed=1).texture_offset("lawn") != Season(texture_seed=2).texture_offset("lawn")
        True
        """
        if part not in TEXTURE_PARTS:
            raise ValueError(f"unknown texture part {part!r}; available: {', '.join(TEXTURE_PARTS)}")
        if self.texture_seed is None:
            return (0.0, 0.0)
        rng = np.random.default_rng([self.texture_seed, TEXTURE_PARTS.index(part)])
        du, dv = rng.uniform(0.0, TEXTURE_SHIFT_RANGE, 2)
        return (float(du), float(dv))

    # ------------------------------------------------------------ JSON

    def to_dict(self) -> dict[str, Any]:
        """JSON-able fields; ``"texture_seed"`` only when there is one."""
        d: dict[str, Any] = {
            "name": self.name,
            "ground": list(self.ground),
            "foliage": list(self.foliage),
            "sky": list(self.sky),
            "leaf_cover": self.leaf_cover,
            "sun_elevation_deg": list(self.sun_elevation_deg),
        }
        if self.texture_seed is not None:
            d["texture_seed"] = self.texture_seed
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Season":
        """The season of :meth:`to_dict`; ValueError for a non-dict or unknown fields."""
        return cls(**_fields_of(cls, d, "season"))


#: the named seasons, in the order of the year from spring
SEASONS: dict[str, Season] = {s.name: s for s in (Season.spring(), Season.summer(), Season.autumn(),
                                                   Season.winter())}


def season_of_year(fraction: float) -> Season:
    """The garden's look ``fraction`` of a year after the start of spring.

    The named seasons (:data:`SEASONS`) hold at the middle of their quarter
    (0.125 spring, 0.375 summer, 0.625 autumn, 0.875 winter); in between
    colours, leaf cover and sun elevation range blend linearly, and the year
    wraps (0.99 lies between winter and spring). The result is named after
    the quarter ``fraction`` falls in.

    Parameters
    ----------
    fraction : float
        Time of year as a fraction; any finite number (taken modulo 1).

    Returns
    -------
    Season

    Raises
    ------
    ValueError
        A non-finite or non-numeric ``fraction``.

    Examples
    --------
    >>> season_of_year(0.375) == SEASONS["summer"]
    True
    >>> season_of_year(0.5).name
    'autumn'
    """
    try:
        f = float(fraction)
    except (TypeError, ValueError):
        f = float("nan")
    if not np.isfinite(f):
        raise ValueError(f"fraction of the year must be a finite number, got {fraction!r}")
    f %= 1.0
    order = list(SEASONS.values())
    pos = (f - 0.125) * 4 % 4  # 0 at mid-spring, 1 at mid-summer, ...
    i = int(np.floor(pos)) % 4
    w = pos - np.floor(pos)
    a, b = order[i], order[(i + 1) % 4]
    if w == 0:
        return a

    def mix(u: Any, v: Any) -> Any:
        return tuple(float((1 - w) * x + w * y) for x, y in zip(u, v))

    return Season(order[int(f * 4) % 4].name, ground=mix(a.ground, b.ground), foliage=mix(a.foliage, b.foliage),
                  sky=mix(a.sky, b.sky), leaf_cover=float((1 - w) * a.leaf_cover + w * b.leaf_cover),
                  sun_elevation_deg=mix(a.sun_elevation_deg, b.sun_elevation_deg))


@dataclass(frozen=True)
class Lighting:
    """A lighting condition, optionally in a season.

    Attributes
    ----------
    intensity : float
        Overall light (1: a bright overcast-to-sunny day); scales every pixel.
    tint : (R, G, B)
        Colour of the light, multiplies the channels (e.g. red 0.5..1 as in
        thesis 6.2.2).
    sun_azimuth_deg, sun_elevation_deg : float
        Sun direction in degrees (azimuth counter-clockwise from +x). Sides of
        objects facing the sun are brighter; objects cast shadows on the ground.
    ambient : float
        Share of sky light that reaches every surface, in [0, 1].
    sun_intensity : float
        Strength of the direct sunlight relative to the sky light (1: the
        default balance). It scales only the direct term of the shading, so
        sunlit surfaces brighten while the sky and the shade keep their
        light: a lamp turned up in a scene whose sky stays (thesis 6.2.1),
        which no gain on the whole image undoes, unlike ``intensity``.
    shadows : bool
        Ground shadows of the static objects.
    season : Season or None
        The garden's look in a season (colours, leaf cover); None renders the
        world's own colours (as ``Season.summer()``). The sun stays this
        Lighting's: pick ``sun_elevation_deg`` in the season's
        ``sun_elevation_deg`` range for a typical day.

    Raises
    ------
    ValueError
        A negative or non-finite intensity or sun intensity, a bad tint, a
        sun elevation outside (0, 90], an ambient outside [0, 1].
    TypeError
        A season that is not a :class:`Season`.
    """

    intensity: float = 1.0
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    sun_azimuth_deg: float = 135.0
    sun_elevation_deg: float = 40.0
    ambient: float = 0.6
    shadows: bool = True
    season: Season | None = None
    sun_intensity: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.intensity) and self.intensity >= 0):
            raise ValueError(f"light intensity must be finite and >= 0, got {self.intensity}")
        if not (np.isfinite(self.sun_intensity) and self.sun_intensity >= 0):
            raise ValueError(f"sun_intensity must be finite and >= 0, got {self.sun_intensity}")
        tint = tuple(float(t) for t in self.tint)
        if len(tint) != 3 or min(tint) < 0:
            raise ValueError(f"light tint must be three non-negative numbers, got {self.tint!r}")
        object.__setattr__(self, "tint", tint)
        if not 0 < self.sun_elevation_deg <= 90:
            raise ValueError(f"sun_elevation_deg must be in (0, 90], got {self.sun_elevation_deg}")
        if not 0 <= self.ambient <= 1:
            raise ValueError(f"ambient must be in [0, 1], got {self.ambient}")
        if self.season is not None and not isinstance(self.season, Season):
            raise TypeError(f"season must be a Season or None, got {type(self.season).__name__}")

    @property
    def sun(self) -> np.ndarray:
        """Unit vector towards the sun (x, y, z)."""
        az, el = np.radians(self.sun_azimuth_deg), np.radians(self.sun_elevation_deg)
        return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])

    @property
    def rgb(self) -> np.ndarray:
        return (self.intensity * np.asarray(self.tint)).astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able fields; ``"season"`` only when there is one,
        ``"sun_intensity"`` only when it is not 1."""
        d = {
            "intensity": self.intensity,
            "tint": list(self.tint),
            "sun_azimuth_deg": self.sun_azimuth_deg,
            "sun_elevation_deg": self.sun_elevation_deg,
            "ambient": self.ambient,
            "shadows": self.shadows,
        }
        if self.season is not None:
            d["season"] = self.season.to_dict()
        if self.sun_intensity != 1.0:
            d["sun_intensity"] = self.sun_intensity
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Lighting":
        """The lighting of :meth:`to_dict`; ValueError for a non-dict or unknown fields."""
        kw = _fields_of(cls, d, "lighting")
        if kw.get("season") is not None:
            kw["season"] = Season.from_dict(kw["season"])
        return cls(**kw)


def _fields_of(cls: type, d: Any, what: str) -> dict[str, Any]:
    if not isinstance(d, dict):
        raise ValueError(f"a {what} must be read from a dict, got {type(d).__name__}")
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(d) - known)
    if unknown:
        raise ValueError(f"unknown {what} fields {unknown}; known: {sorted(known)}")
    return dict(d)
