"""The garden objects of the simulator's worlds: how each type is built
from primitives, and where it stands.

:class:`ObjectBuilder` draws one object of a type at a time (``tree``,
``conifer``, ``bush``, ``house``, ``shed``, ``fence``, ``hedge``, ``rock``,
marker boards; inside the area ``small_tree``, ``small_bush``, ``pole`` and
sheds against the border), registering its textures in the world, and
:meth:`ObjectBuilder.place` puts it at a free polar position beyond the free
area (thesis 4.1). It also draws obstacles and ground patches.
:meth:`sfanav.sim.world.World.generate` drives it; the builder is not meant
to be used on its own.

Units: metres, radians (yaw counter-clockwise from +x); colours RGB in [0, 1].
"""

from __future__ import annotations

from dataclasses import asdict
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from .primitives import BLOCK_HEIGHT, INNER_TYPES, PATCH_KINDS, Primitive, WorldObject
from .textures import Texture

if TYPE_CHECKING:
    from .world import World


class ObjectBuilder:
    """Draws objects of each type; :meth:`place` puts the last one at a free
    polar position."""

    def __init__(self, world: World, rng: np.random.Generator, prefix: str = ""):
        self.w = world
        self.rng = rng
        self.prefix = prefix
        self.pending: tuple[str, float, list[Primitive], int | None, bool] | None = None
        self._tex_count = 0

    def tex(self, kind: str, color: Sequence[float], contrast: float, tile: tuple[float, float], **params: Any) -> str:
        name = f"{self.prefix}{kind}{self._tex_count}"
        self._tex_count += 1
        self.w.textures[name] = Texture(kind, tuple(color), contrast, int(self.rng.integers(2**31)), tile, params)
        return name

    def u(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    def jitter(self, color: Sequence[float], amount: float = 0.06) -> tuple[float, float, float]:
        c = np.clip(np.asarray(color) * (1 + self.rng.uniform(-amount, amount, 3) * 2), 0, 1)
        return tuple(float(v) for v in c)

    # Parts are built around the origin with the object's "facing" yaw = 0 and
    # moved/rotated by place(): (x, y) offsets are rotated by the yaw.

    def _set(self, kind: str, radius: float, parts: list[Primitive], marker_id: int | None = None,
             tangential: bool = False) -> None:
        self.pending = (kind, radius, parts, marker_id, tangential)

    def tree(self) -> None:
        trunk_h = self.u(1.4, 2.8)
        rz = self.u(1.0, 2.3)
        r = self.u(1.1, 2.6)
        bark = self.tex("bark", self.jitter((0.36, 0.27, 0.18)), 0.9, (1.0, 1.0))
        leaves = self.tex("leaves", self.jitter((0.22, 0.40, 0.13), 0.12), 0.9, (1.5, 1.5))
        zc = trunk_h + 0.7 * rz
        parts = [
            Primitive("cylinder", 0, 0, 0.0, trunk_h + 0.5 * rz, bark, radius=self.u(0.12, 0.3)),
            Primitive("ellipsoid", 0, 0, zc - rz, zc + rz, leaves, radius=r),
        ]
        self._set("tree", r, parts)

    def conifer(self) -> None:
        trunk_h = self.u(0.4, 1.0)
        rz = self.u(2.2, 4.0)
        r = self.u(0.9, 1.6)
        bark = self.tex("bark", self.jitter((0.30, 0.22, 0.15)), 0.9, (1.0, 1.0))
        needles = self.tex("leaves", self.jitter((0.10, 0.26, 0.12), 0.1), 1.0, (1.0, 1.0))
        parts = [
            Primitive("cylinder", 0, 0, 0.0, trunk_h + rz, bark, radius=self.u(0.1, 0.2)),
            Primitive("ellipsoid", 0, 0, trunk_h, trunk_h + 2 * rz, needles, radius=r),
        ]
        self._set("conifer", r, parts)

    def bush(self) -> None:
        leaves = self.tex("leaves", self.jitter((0.20, 0.36, 0.12), 0.15), 1.0, (1.0, 1.0))
        parts = []
        n = int(self.rng.integers(1, 4))
        extent = 0.0
        for _ in range(n):
            r = self.u(0.5, 1.1)
            rz = self.u(0.4, 0.9)
            ox, oy = (self.u(-0.6, 0.6), self.u(-0.6, 0.6)) if n > 1 else (0.0, 0.0)
            zc = 0.55 * rz
            parts.append(Primitive("ellipsoid", ox, oy, zc - rz, zc + rz, leaves, radius=r))
            extent = max(extent, float(np.hypot(ox, oy)) + r)
        self._set("bush", extent, parts)

    def rock(self) -> None:
        stone = self.tex("gravel", self.jitter((0.52, 0.50, 0.47), 0.1), 0.8, (0.5, 0.5))
        r = self.u(0.35, 1.1)
        rz = self.u(0.25, 0.75)
        parts = [Primitive("ellipsoid", 0, 0, -0.3 * rz - rz, -0.3 * rz + rz, stone, radius=r)]
        self._set("rock", r, parts)

    def house(self) -> None:
        length, width = self.u(5.0, 9.0), self.u(4.0, 7.0)
        wall_h = self.u(2.6, 3.6)
        if self.rng.random() < 0.6:
            wall = self.jitter((0.62, 0.36, 0.28))  # red brick
            contrast = 0.7
        else:
            wall = self.jitter((0.86, 0.84, 0.78), 0.03)  # plastered
            contrast = 0.15
        facade = self.tex("facade", wall, contrast, (3.0, wall_h))
        roof_c = self.jitter((0.40, 0.18, 0.14) if self.rng.random() < 0.6 else (0.25, 0.25, 0.27))
        roof = self.tex("roof", roof_c, 0.8, (1.0, 1.0), rows=4)
        ov = 0.3
        parts = [
            Primitive("box", 0, 0, 0.0, wall_h, facade, length=length, width=width),
            Primitive("box", 0, 0, wall_h, wall_h + 0.35, roof, length=length + 2 * ov, width=width + 2 * ov),
            Primitive("box", 0, 0, wall_h + 0.35, wall_h + 1.1, roof, length=length + ov, width=0.55 * width),
            Primitive("box", 0, 0, wall_h + 1.1, wall_h + 1.6, roof, length=length, width=0.2 * width),
        ]
        self._set("house", 0.5 * float(np.hypot(length + 2 * ov, width + 2 * ov)), parts)

    def shed(self) -> None:
        length, width = self.u(2.0, 3.5), self.u(1.6, 2.6)
        h = self.u(1.9, 2.4)
        wood = self.tex("planks", self.jitter((0.45, 0.32, 0.20)), 0.8, (1.2, 2.0), boards=8, gap=0.0)
        roof = self.tex("roof", self.jitter((0.20, 0.20, 0.22)), 0.6, (1.0, 1.0), rows=3)
        parts = [
            Primitive("box", 0, 0, 0.0, h, wood, length=length, width=width),
            Primitive("box", 0, 0, h, h + 0.15, roof, length=length + 0.3, width=width + 0.3),
        ]
        self._set("shed", 0.5 * float(np.hypot(length + 0.3, width + 0.3)), parts)

    def fence(self) -> None:
        length = self.u(3.0, 8.0)
        h = self.u(0.9, 1.5)
        wood = self.tex("planks", self.jitter((0.60, 0.50, 0.36)), 0.8, (1.0, h), boards=8, gap=0.35)
        parts = [Primitive("box", 0, 0, 0.0, h, wood, length=length, width=0.05)]
        self._set("fence", length / 2, parts, tangential=True)

    def hedge(self) -> None:
        length = self.u(3.0, 7.0)
        width = self.u(0.7, 1.2)
        h = self.u(1.2, 2.0)
        leaves = self.tex("leaves", self.jitter((0.16, 0.32, 0.11), 0.1), 1.0, (1.0, 1.0))
        parts = [Primitive("box", 0, 0, 0.0, h, leaves, length=length, width=width)]
        self._set("hedge", 0.5 * float(np.hypot(length, width)), parts, tangential=True)

    def marker(self, marker_id: int, size: float, dictionary: str) -> None:
        if not size > 0:
            raise ValueError(f"marker_size must be positive (m), got {size}")
        face = self.tex("marker", (0.95, 0.95, 0.95), 1.0, (size, size), id=int(marker_id), dictionary=dictionary)
        wood = self.tex("noise", (0.40, 0.30, 0.20), 0.5, (0.5, 0.5))
        z0 = 0.6
        parts = [
            Primitive("box", 0, 0.05, 0.0, z0, wood, length=0.08, width=0.08),
            Primitive("box", 0, 0, z0, z0 + size, wood, length=size + 0.04, width=0.04, front=face),
        ]
        # local -y face carries the marker; place() turns it towards the centre
        self._set("marker", size / 2 + 0.1, parts, marker_id, tangential=True)

    # ---------------------------------------------------- inside the area

    def pole(self) -> None:
        paint = self.rng.choice([(0.92, 0.92, 0.90), (0.35, 0.36, 0.38), (0.18, 0.32, 0.20), (0.55, 0.40, 0.25)])
        tex = self.tex("noise", self.jitter(paint, 0.04), 0.3, (0.5, 0.5))
        r = self.u(0.04, 0.08)
        parts = [Primitive("cylinder", 0, 0, 0.0, self.u(1.6, 2.6), tex, radius=r)]
        self._set("pole", r, parts)

    def small_tree(self) -> None:
        trunk_h = self.u(1.5, 2.2)
        rz = self.u(0.7, 1.2)
        r = self.u(0.8, 1.5)
        bark = self.tex("bark", self.jitter((0.36, 0.27, 0.18)), 0.9, (1.0, 1.0))
        leaves = self.tex("leaves", self.jitter((0.24, 0.42, 0.14), 0.12), 0.9, (1.2, 1.2))
        zc = trunk_h + 0.7 * rz
        parts = [
            Primitive("cylinder", 0, 0, 0.0, trunk_h + 0.5 * rz, bark, radius=self.u(0.08, 0.16)),
            Primitive("ellipsoid", 0, 0, zc - rz, zc + rz, leaves, radius=r),
        ]
        self._set("tree", r, parts)

    def small_bush(self) -> None:
        leaves = self.tex("leaves", self.jitter((0.20, 0.36, 0.12), 0.15), 1.0, (0.8, 0.8))
        r = self.u(0.35, 0.75)
        rz = self.u(0.3, 0.6)
        zc = 0.55 * rz
        self._set("bush", r, [Primitive("ellipsoid", 0, 0, zc - rz, zc + rz, leaves, radius=r)])

    def inner(self, counts: dict[str, int], placed: list[WorldObject]) -> list[WorldObject]:
        """Objects inside the free area, ``counts`` per type of ``INNER_TYPES``."""
        bad = set(counts) - set(INNER_TYPES)
        if bad:
            raise ValueError(f"unknown inner object types {sorted(bad)}; available: {', '.join(INNER_TYPES)}")
        w, h = self.w.area
        out: list[WorldObject] = []
        for _ in range(int(counts.get("shed", 0))):
            length, width = self.u(2.0, 3.0), self.u(1.5, 2.2)
            wood = self.tex("planks", self.jitter((0.45, 0.32, 0.20)), 0.8, (1.2, 2.0), boards=8, gap=0.0)
            roof = self.tex("roof", self.jitter((0.20, 0.20, 0.22)), 0.6, (1.0, 1.0), rows=3)
            hgt = self.u(1.9, 2.3)
            side = int(self.rng.integers(4))  # 0: east, 1: north, 2: west, 3: south border
            along = self.u(-0.3, 0.3) * (h if side in (0, 2) else w)
            depth = 0.5 * width
            if side == 0:
                x, y, yaw = w / 2 - depth, along, np.pi / 2
            elif side == 2:
                x, y, yaw = -w / 2 + depth, along, np.pi / 2
            elif side == 1:
                x, y, yaw = along, h / 2 - depth, 0.0
            else:
                x, y, yaw = along, -h / 2 + depth, 0.0
            parts = [Primitive("box", x, y, 0.0, hgt, wood, length=length, width=width, yaw=yaw),
                     Primitive("box", x, y, hgt, hgt + 0.15, roof, length=length + 0.3, width=width + 0.3, yaw=yaw)]
            out.append(WorldObject("shed", float(x), float(y), 0.5 * float(np.hypot(length, width)), parts, True))
        makers = {"tree": self.small_tree, "bush": self.small_bush, "pole": self.pole}
        for kind in ("tree", "bush", "pole"):
            for _ in range(int(counts.get(kind, 0))):
                makers[kind]()
                assert self.pending is not None
                _, radius, parts, _, _ = self.pending
                self.pending = None
                low = max(p.bound_radius for p in parts if p.z0 < BLOCK_HEIGHT)
                for attempt in range(10000):
                    if attempt < 5000:
                        # room for the robot between objects, crowns apart, 1 m from the border
                        gap = 1.6 if attempt < 3000 else 1.0
                        rad, border = radius, 1.0
                    else:  # crowded (small areas): only the blocking parts keep the robot's room
                        gap, rad, border = 1.0, low, 0.5
                    lim_x, lim_y = w / 2 - rad - border, h / 2 - rad - border
                    if lim_x <= 0 or lim_y <= 0:
                        continue
                    x, y = self.u(-lim_x, lim_x), self.u(-lim_y, lim_y)
                    if all(np.hypot(x - o.x, y - o.y) >= rad + (o.radius if attempt < 5000 else max(
                            q.bound_radius for q in o.parts if q.z0 < BLOCK_HEIGHT)) + gap
                           for o in out + [q for q in placed if q.obstacle]):
                        break
                else:
                    raise ValueError(f"no room for {sum(counts.values())} inner objects in {w} x {h} m")
                moved = [Primitive(**{**asdict(p), "x": x + p.x, "y": y + p.y}) for p in parts]
                out.append(WorldObject(kind, float(x), float(y), float(radius), moved, True))
        return out

    def patches(self, counts: dict[str, int]) -> list[dict[str, Any]]:
        """Ground patches inside the free area, ``counts`` per kind of ``PATCH_KINDS``."""
        bad = set(counts) - set(PATCH_KINDS)
        if bad:
            raise ValueError(f"unknown ground patch kinds {sorted(bad)}; available: {', '.join(PATCH_KINDS)}")
        w, h = self.w.area
        out: list[dict[str, Any]] = []
        for _ in range(int(counts.get("patio", 0))):
            length, width = self.u(2.5, 4.0), self.u(2.0, 3.2)
            # against a border, as a terrace in front of the house would be
            side = int(self.rng.integers(4))
            along = self.u(-0.3, 0.3)
            if side in (0, 2):
                x = (1 if side == 0 else -1) * (w / 2 - width / 2)
                y, yaw = along * h, np.pi / 2
            else:
                y = (1 if side == 1 else -1) * (h / 2 - width / 2)
                x, yaw = along * w, 0.0
            out.append({"kind": "patio", "x": float(x), "y": float(y), "length": float(length), "width": float(width),
                        "yaw": float(yaw), "tile": float(self.rng.choice([0.4, 0.5, 0.6])),
                        "seed": int(self.rng.integers(2**31))})
        for _ in range(int(counts.get("path", 0))):
            # from one border across the area to another, with a bend
            a0 = self.u(0, 2 * np.pi)
            a1 = a0 + np.pi + self.u(-0.8, 0.8)
            R = 0.5 * float(np.hypot(w, h)) + 1.0
            p0 = np.array([R * np.cos(a0), R * np.sin(a0)])
            p2 = np.array([R * np.cos(a1), R * np.sin(a1)])
            mid = 0.5 * (p0 + p2) + np.array([self.u(-0.2, 0.2) * w, self.u(-0.2, 0.2) * h])
            out.append({"kind": "path", "points": [[float(v) for v in q] for q in (p0, mid, p2)],
                        "width": self.u(0.6, 1.0), "seed": int(self.rng.integers(2**31))})
        for _ in range(int(counts.get("bed", 0))):
            rx, ry = self.u(0.6, 1.5), self.u(0.4, 0.9)
            out.append({"kind": "bed", "x": self.u(-w / 2 + rx, w / 2 - rx), "y": self.u(-h / 2 + rx, h / 2 - rx),
                        "rx": rx, "ry": ry, "yaw": self.u(0, np.pi), "seed": int(self.rng.integers(2**31))})
        return out

    def place(self, placed: list[WorldObject], near: bool = False) -> WorldObject:
        assert self.pending is not None
        kind, radius, parts, marker_id, tangential = self.pending
        self.pending = None
        r_free, r_out = self.w.free_radius, self.w.outer_radius
        lo = r_free + radius
        hi = min(r_out, lo + 3.0) if near else r_out
        if hi <= lo:
            hi = lo + radius
        for attempt in range(100000):
            if attempt and attempt % 200 == 0:
                hi += 1.0  # crowded: let the ring grow outwards
            r = float(np.sqrt(self.rng.uniform(lo**2, hi**2)))
            a = float(self.rng.uniform(0, 2 * np.pi))
            x, y = r * np.cos(a), r * np.sin(a)
            if all(np.hypot(x - o.x, y - o.y) >= radius + o.radius + 0.3 for o in placed if not o.obstacle):
                break
        self.w.outer_radius = max(self.w.outer_radius, r + radius)
        if tangential:
            # facing the centre: the local -y face (outward normal yaw - pi/2) looks at the origin
            yaw = a - np.pi / 2 + (self.rng.uniform(-0.35, 0.35) if kind in ("fence", "hedge") else 0.0)
        else:
            yaw = float(self.rng.uniform(0, 2 * np.pi))
        c, s = np.cos(yaw), np.sin(yaw)
        moved = []
        for p in parts:
            px, py = c * p.x - s * p.y, s * p.x + c * p.y
            moved.append(Primitive(**{**asdict(p), "x": x + px, "y": y + py, "yaw": p.yaw + yaw}))
        return WorldObject(kind, float(x), float(y), float(radius), moved, False, marker_id)

    def obstacle(self, spec: str | dict[str, Any]) -> list[WorldObject]:
        if isinstance(spec, str):
            spec = {"kind": spec}
        if not isinstance(spec, dict) or "kind" not in spec:
            raise ValueError(f"an obstacle is 'v-wall' or a dict with a 'kind', got {spec!r}")
        spec = dict(spec)
        kind = spec.pop("kind")
        wall_tex = self.tex("noise", (0.62, 0.60, 0.56), 0.6, (1.0, 1.0), beta=1.5)
        if kind == "v-wall":
            allowed = {"x", "y", "arm", "angle", "yaw", "height", "thickness"}
            bad = set(spec) - allowed
            if bad:
                raise ValueError(f"v-wall: unknown keys {sorted(bad)}; allowed: {sorted(allowed)}")
            ax, ay = float(spec.get("x", 0.0)), float(spec.get("y", -0.15 * self.w.area[1]))
            arm = float(spec.get("arm", 0.3 * min(self.w.area)))
            half = np.radians(float(spec.get("angle", 90.0))) / 2
            yaw = np.radians(float(spec.get("yaw", 90.0)))  # direction the V opens to
            height, th = float(spec.get("height", 1.0)), float(spec.get("thickness", 0.2))
            objs = []
            for sgn in (-1, 1):
                d = yaw + sgn * half
                cx, cy = ax + 0.5 * arm * np.cos(d), ay + 0.5 * arm * np.sin(d)
                p = Primitive("box", cx, cy, 0.0, height, wall_tex, length=arm + th, width=th, yaw=float(d))
                objs.append(WorldObject("wall", float(cx), float(cy), p.bound_radius, [p], True))
            return objs
        if kind == "box":
            allowed = {"x", "y", "length", "width", "height", "yaw"}
            bad = set(spec) - allowed
            if bad:
                raise ValueError(f"box obstacle: unknown keys {sorted(bad)}; allowed: {sorted(allowed)}")
            box_tex = self.tex("noise", (0.55, 0.42, 0.30), 0.7, (0.6, 0.6))
            p = Primitive(
                "box", float(spec.get("x", 0.0)), float(spec.get("y", 0.0)), 0.0, float(spec.get("height", 0.8)),
                box_tex, length=float(spec.get("length", 1.0)), width=float(spec.get("width", 1.0)),
                yaw=float(np.radians(spec.get("yaw", 0.0))),
            )
            return [WorldObject("box", p.x, p.y, p.bound_radius, [p], True)]
        raise ValueError(f"unknown obstacle kind {kind!r}; available: 'v-wall', 'box'")
