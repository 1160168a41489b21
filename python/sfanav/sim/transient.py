"""Objects that come and go with the seasons (thesis 6.1: "some objects
that come and go"): garden furniture and a parasol in summer, a wheelbarrow
in spring, leaf piles in autumn, a snowman and snow patches in winter.

A transient object is an ordinary :class:`~sfanav.sim.primitives.WorldObject`
whose ``seasons`` names the seasons it is there in; the renderer draws it
(and its shadow) only under a lighting in one of them. Worlds get them from
``World.generate(transient=[...])``, one spec per object::

    {"kind": "parasol", "seasons": ["summer"], "x": 3.0, "y": 3.0, "yaw": 30.0}

``kind`` one of :data:`TRANSIENT_KINDS`; ``seasons`` a non-empty list of
named seasons (``spring``, ``summer``, ``autumn``, ``winter``); ``x``, ``y``
(m, both or neither) where it stands, by default a random free spot inside
the area at least :data:`BORDER` m (plus its radius) from the border;
``yaw`` (degrees, default random) its orientation. Colours are drawn
(jittered) from the world's transient random stream, so the rest of the
world is the same with and without them.

They stand on the lawn inside the free area and, except for the flat snow
patches, are obstacles: :meth:`World.collides` keeps clear of them in every
season (a trajectory is planned once for all seasons).

Units: metres, yaw in degrees in the spec (radians in the primitives);
colours RGB in [0, 1].

>>> from sfanav.sim import World
>>> w = World.generate(0, area=(10.0, 10.0), n_objects=0,
...                    transient=[{"kind": "snowman", "seasons": ["winter"], "x": 1.0, "y": 2.0}])
>>> [(o.kind, o.seasons) for o in w.objects]
[('snowman', ('winter',))]
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .objects import ObjectBuilder
from .primitives import Primitive, WorldObject, posed, season_names

if TYPE_CHECKING:
    from .world import World

TRANSIENT_KINDS = ("furniture", "parasol", "paddling_pool", "toys", "wheelbarrow", "leaf_pile", "tarp", "snowman",
                   "snow_patch")

#: transient kinds the robot can drive over (not obstacles)
FLAT_KINDS = ("snow_patch",)

#: a randomly placed transient object keeps this distance (m) plus its radius from the area's border
BORDER = 2.0

SPEC_KEYS = ("kind", "seasons", "x", "y", "yaw")

_PLASTIC = ((0.85, 0.15, 0.12), (0.12, 0.35, 0.78), (0.95, 0.78, 0.10), (0.15, 0.60, 0.25), (0.90, 0.45, 0.10))


class TransientBuilder(ObjectBuilder):
    """Builds the transient objects of :data:`TRANSIENT_KINDS`; used by
    :meth:`sfanav.sim.world.World.generate`, not meant to be used on its own.

    Every kind's method returns ``(radius, parts)`` built around the origin
    facing +x; :meth:`build` moves them to their place."""

    def __init__(self, world: World, rng: np.random.Generator):
        super().__init__(world, rng, prefix="tr")

    def _plastic(self) -> tuple[float, float, float]:
        return self.jitter(_PLASTIC[int(self.rng.integers(len(_PLASTIC)))], 0.04)

    def furniture(self) -> tuple[float, list[Primitive]]:
        """A garden table with two chairs (teak or white plastic)."""
        if self.rng.random() < 0.5:
            wood = self.tex("planks", self.jitter((0.55, 0.36, 0.20)), 0.8, (0.8, 0.8), boards=6, gap=0.0)
        else:
            wood = self.tex("noise", self.jitter((0.92, 0.92, 0.90), 0.02), 0.2, (0.5, 0.5))
        parts = [Primitive("box", 0, 0, 0.70, 0.75, wood, length=1.4, width=0.8)]
        parts += [Primitive("box", sx * 0.62, sy * 0.32, 0.0, 0.70, wood, length=0.06, width=0.06)
                  for sx in (-1, 1) for sy in (-1, 1)]
        for sy in (-1, 1):  # chairs on both long sides, backs away from the table
            cy = sy * 0.85
            parts += [Primitive("box", 0, cy, 0.42, 0.46, wood, length=0.48, width=0.45),
                      Primitive("box", 0, cy + sy * 0.22, 0.46, 0.92, wood, length=0.48, width=0.04)]
            parts += [Primitive("box", sx * 0.22, cy, 0.0, 0.42, wood, length=0.04, width=0.42) for sx in (-1, 1)]
        return 1.25, parts

    def parasol(self) -> tuple[float, list[Primitive]]:
        """A striped sunshade on a pole with a heavy base."""
        r = self.u(1.1, 1.4)
        cloth = self.tex("stripes", self._plastic(), 0.5, (2 * np.pi * r, 0.25), n=8, color2=(0.95, 0.94, 0.9))
        metal = self.tex("noise", (0.75, 0.75, 0.72), 0.2, (0.5, 0.5))
        base = self.tex("noise", (0.25, 0.25, 0.27), 0.4, (0.5, 0.5))
        return r, [Primitive("cylinder", 0, 0, 0.0, 0.08, base, radius=0.25),
                   Primitive("cylinder", 0, 0, 0.0, 2.3, metal, radius=0.025),
                   Primitive("cylinder", 0, 0, 2.0, 2.25, cloth, radius=r)]

    def paddling_pool(self) -> tuple[float, list[Primitive]]:
        """A round inflatable pool, white and blue (or another plastic colour)."""
        r = self.u(0.8, 1.3)
        side = self.tex("stripes", self.jitter((0.15, 0.45, 0.85), 0.05), 0.4, (2 * np.pi * r, 0.3), n=10,
                        color2=self._plastic())
        return r, [Primitive("cylinder", 0, 0, 0.0, self.u(0.25, 0.35), side, radius=r)]

    def toys(self) -> tuple[float, list[Primitive]]:
        """A plastic slide, a ball and a bucket in bright colours."""
        slide = self.tex("noise", self._plastic(), 0.3, (0.5, 0.5))
        ball = self.tex("noise", self._plastic(), 0.3, (0.3, 0.3))
        bucket = self.tex("noise", self._plastic(), 0.3, (0.3, 0.3))
        return 1.0, [Primitive("box", 0, 0, 0.0, 0.6, slide, length=1.2, width=0.45),
                     Primitive("ellipsoid", 0.3, 0.7, 0.0, 0.3, ball, radius=0.15),
                     Primitive("cylinder", -0.5, -0.6, 0.0, 0.22, bucket, radius=0.12)]

    def wheelbarrow(self) -> tuple[float, list[Primitive]]:
        """A metal tray on a wheel and two legs, with two handles."""
        tray = self.tex("noise", self.jitter((0.20, 0.48, 0.25) if self.rng.random() < 0.5 else (0.75, 0.2, 0.15)),
                        0.4, (0.5, 0.5))
        dark = self.tex("noise", (0.12, 0.12, 0.12), 0.3, (0.3, 0.3))
        wood = self.tex("noise", self.jitter((0.55, 0.40, 0.25)), 0.5, (0.5, 0.5))
        return 1.0, [Primitive("box", 0, 0, 0.3, 0.6, tray, length=0.9, width=0.6),
                     Primitive("box", 0.55, 0, 0.0, 0.36, dark, length=0.36, width=0.08),
                     Primitive("box", -0.3, 0.2, 0.0, 0.3, wood, length=0.05, width=0.05),
                     Primitive("box", -0.3, -0.2, 0.0, 0.3, wood, length=0.05, width=0.05),
                     Primitive("box", -0.75, 0.25, 0.5, 0.55, wood, length=0.7, width=0.04),
                     Primitive("box", -0.75, -0.25, 0.5, 0.55, wood, length=0.7, width=0.04)]

    def leaf_pile(self) -> tuple[float, list[Primitive]]:
        """A heap of raked orange-brown leaves."""
        r = self.u(0.6, 1.0)
        rz = self.u(0.3, 0.45)
        leaves = self.tex("leaves", self.jitter((0.62, 0.34, 0.12), 0.1), 1.0, (0.8, 0.8))
        return r, [Primitive("ellipsoid", 0, 0, -0.9 * rz, 1.1 * rz, leaves, radius=r)]

    def tarp(self) -> tuple[float, list[Primitive]]:
        """A plastic cover over something stored for the winter (furniture, a compost heap)."""
        cover = self.tex("noise", self.jitter((0.15, 0.30, 0.60) if self.rng.random() < 0.5 else (0.20, 0.36, 0.20)),
                         0.6, (0.8, 0.8), beta=1.6)
        length, width = self.u(1.4, 1.8), self.u(1.0, 1.3)
        return 0.5 * float(np.hypot(length, width)), [
            Primitive("box", 0, 0, 0.0, self.u(0.8, 1.0), cover, length=length, width=width)]

    def snowman(self) -> tuple[float, list[Primitive]]:
        """Three balls of snow with a black hat."""
        snow = self.tex("noise", (0.93, 0.94, 0.97), 0.15, (0.5, 0.5))
        hat = self.tex("noise", (0.08, 0.08, 0.09), 0.2, (0.3, 0.3))
        return 0.4, [Primitive("ellipsoid", 0, 0, 0.0, 0.75, snow, radius=0.4),
                     Primitive("ellipsoid", 0, 0, 0.65, 1.15, snow, radius=0.28),
                     Primitive("ellipsoid", 0, 0, 1.1, 1.45, snow, radius=0.2),
                     Primitive("cylinder", 0, 0, 1.4, 1.62, hat, radius=0.14)]

    def snow_patch(self) -> tuple[float, list[Primitive]]:
        """A flat patch of left-over snow on the lawn."""
        r = self.u(0.8, 1.6)
        snow = self.tex("noise", (0.92, 0.93, 0.96), 0.25, (1.0, 1.0))
        return r, [Primitive("ellipsoid", 0, 0, -0.12, 0.1, snow, radius=r)]

    # ------------------------------------------------------------ placement

    def build(self, specs: Any, placed: list[WorldObject]) -> list[WorldObject]:
        """The transient objects of ``specs`` (see the module docstring),
        placed clear of the obstacles in ``placed`` and of each other when
        their position is drawn.

        Raises
        ------
        ValueError
            A spec that is not a dict, unknown keys or kind, bad seasons,
            only one of ``x`` / ``y``, a non-finite position or yaw, no
            room for a randomly placed object.
        """
        if isinstance(specs, (str, dict)) or not isinstance(specs, (list, tuple)):
            raise ValueError(f"transient must be a list of dicts, got {specs!r}")
        out: list[WorldObject] = []
        for i, spec in enumerate(specs):
            if not isinstance(spec, dict):
                raise ValueError(f"transient object {i} must be a dict with 'kind' and 'seasons', got {spec!r}")
            bad = sorted(set(map(str, spec)) - set(SPEC_KEYS))
            if bad:
                raise ValueError(f"transient object {i}: unknown keys {bad}; allowed: {', '.join(SPEC_KEYS)}")
            kind = spec.get("kind")
            if kind not in TRANSIENT_KINDS:
                raise ValueError(f"transient object {i}: unknown kind {kind!r}; available: {', '.join(TRANSIENT_KINDS)}")
            seasons = season_names(spec.get("seasons"), f"transient object {i} ({kind}) seasons")
            if ("x" in spec) != ("y" in spec):
                raise ValueError(f"transient object {i} ({kind}): give both x and y (m) or neither")
            radius, parts = getattr(self, kind)()
            yaw = np.radians(_finite(spec["yaw"], f"transient object {i} yaw")) if "yaw" in spec else self.u(0, 2 * np.pi)
            if "x" in spec:
                x, y = _finite(spec["x"], f"transient object {i} x"), _finite(spec["y"], f"transient object {i} y")
            else:
                x, y = self._free_spot(radius, [o for o in placed if o.obstacle] + out, f"{kind} (transient {i})")
            out.append(WorldObject(kind, float(x), float(y), float(radius), posed(parts, x, y, yaw),
                                   kind not in FLAT_KINDS,
                                   seasons=seasons))
        return out

    def _free_spot(self, radius: float, others: list[WorldObject], what: str) -> tuple[float, float]:
        w, h = self.w.area
        lim_x, lim_y = w / 2 - BORDER - radius, h / 2 - BORDER - radius
        if lim_x > 0 and lim_y > 0:
            for _ in range(2000):
                x, y = self.u(-lim_x, lim_x), self.u(-lim_y, lim_y)
                if all(np.hypot(x - o.x, y - o.y) >= radius + o.radius + 0.5 for o in others):
                    return x, y
        raise ValueError(f"no room for {what} in the {w} x {h} m area ({BORDER} m from its border)")


def _finite(v: Any, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v):
        raise ValueError(f"{what} must be a finite number, got {v!r}")
    return float(v)
