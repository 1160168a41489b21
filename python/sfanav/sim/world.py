"""Garden worlds: seeded generation and JSON files (thesis section 4.1).

A world is a flat textured ground plane under a sky with clouds and a
distant tree line, with garden objects (trees, conifers, bushes, houses,
sheds, fences, hedges, rocks, ArUco marker boards) placed at random polar
coordinates whose radii lie beyond the free area where the robot moves: the
construction of the thesis's Blender gardens. Optional obstacles (the
v-shaped wall of section 7.1.2, boxes) stand inside the area, and an optional
dynamic object (a textured cylinder circling the area, section 6.2.1) moves
with time.

Coordinates: x east, y north, z up, metres; the free area is the rectangle
``|x| <= area[0]/2, |y| <= area[1]/2`` centred on the origin. Angles
(``yaw``, headings) are radians counter-clockwise from +x.

Every object is made of vertical *primitives* the ray caster intersects
exactly: ``"cylinder"`` (trunks, posts), ``"box"`` (walls, roofs, fences,
boards; oriented by ``yaw``) and ``"ellipsoid"`` (crowns, bushes, rocks).
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .textures import Texture

FORMAT = "sfanav-world"


VERSION = 1


OBJECT_TYPES = ("tree", "conifer", "bush", "house", "shed", "fence", "hedge", "rock")


INNER_TYPES = ("tree", "bush", "pole", "shed")  # objects that can stand inside the area


PATCH_KINDS = ("patio", "path", "bed")


# parts whose bottom is at least this high (m) do not block the robot (a mower
# drives under a tree's crown, not through its trunk)
BLOCK_HEIGHT = 0.6


DEFAULT_WEIGHTS = {
    "tree": 0.28,
    "conifer": 0.1,
    "bush": 0.2,
    "house": 0.08,
    "shed": 0.06,
    "fence": 0.08,
    "hedge": 0.07,
    "rock": 0.13,
}


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


@dataclass
class DynamicCylinder:
    """A textured vertical cylinder moving on a circle (thesis 6.2.1).

    At time ``t`` (s) its centre is at ``center + orbit * (cos a, sin a)``
    with ``a = phase + direction * 2 pi t / period``."""

    orbit: float
    period: float
    radius: float = 0.6
    height: float = 2.5
    texture: str = "dynamic"
    center: tuple[float, float] = (0.0, 0.0)
    phase: float = 0.0
    direction: int = 1

    def __post_init__(self) -> None:
        if not self.period > 0:
            raise ValueError(f"dynamic object period must be positive (s), got {self.period}")
        if not (self.orbit > 0 and self.radius > 0 and self.height > 0):
            raise ValueError("dynamic object orbit, radius and height must be positive (m)")
        self.center = (float(self.center[0]), float(self.center[1]))

    def primitive_at(self, t: float) -> Primitive:
        a = self.phase + self.direction * 2 * np.pi * t / self.period
        return Primitive(
            "cylinder",
            self.center[0] + self.orbit * np.cos(a),
            self.center[1] + self.orbit * np.sin(a),
            0.0,
            self.height,
            self.texture,
            radius=self.radius,
        )


@dataclass
class GroundSpec:
    """The lawn: a photographic detail texture (``detail``, tiling every
    ``detail_tile`` metres) times a large-scale colour map (two greens mixed
    by fractal noise, with drier patches) sampled every ``resolution`` m.

    ``patches``: dicts painted over the lawn's colour map (the realistic gardens'
    realistic gardens), each with a ``kind`` from ``PATCH_KINDS``:
    ``{"kind": "patio", "x", "y", "length", "width", "yaw", "tile"}`` (grey
    stone slabs of ``tile`` m with dark joints), ``{"kind": "path",
    "points": [[x, y], ...], "width"}`` (a gravel path along a polyline),
    ``{"kind": "bed", "x", "y", "rx", "ry", "yaw"}`` (an elliptic flower bed:
    dark soil, leaves and coloured flowers). Metres, yaw in radians."""

    seed: int = 0
    detail: str = "grass"
    detail_tile: float = 0.5
    contrast: float = 0.6
    green: tuple[float, float, float] = (0.30, 0.45, 0.16)
    green2: tuple[float, float, float] = (0.20, 0.36, 0.12)
    dry: tuple[float, float, float] = (0.50, 0.47, 0.30)
    dry_fraction: float = 0.12
    resolution: float = 0.1
    patches: tuple = ()  # ground patches painted over the lawn (see PATCH_KINDS)


LAWNS = ("patchy", "uniform")


@dataclass
class SkySpec:
    """Sky gradient with clouds and a distant tree line at the horizon
    (both at infinity: they carry heading, not position)."""

    seed: int = 0
    cloud_cover: float = 0.45
    horizon: tuple[float, float, float] = (0.78, 0.84, 0.90)
    zenith: tuple[float, float, float] = (0.32, 0.50, 0.80)
    treeline: tuple[float, float, float] = (0.22, 0.30, 0.24)
    treeline_deg: tuple[float, float] = (0.4, 3.0)


def _rect_distance(px: np.ndarray, py: np.ndarray, p: Primitive) -> np.ndarray:
    """Distance from points to a primitive's footprint (0 inside), metres."""
    dx, dy = px - p.x, py - p.y
    if p.shape == "box":
        c, s = np.cos(p.yaw), np.sin(p.yaw)
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        ex = np.maximum(np.abs(lx) - p.length / 2, 0)
        ey = np.maximum(np.abs(ly) - p.width / 2, 0)
        return np.hypot(ex, ey)
    return np.maximum(np.hypot(dx, dy) - p.radius, 0)


@dataclass
class World:
    """A garden world. Build one with :meth:`generate`; save and load it
    as JSON with :meth:`save` / :meth:`load`.

    Attributes
    ----------
    area : (width, height)
        Free area where the robot moves, centred on the origin (m).
    free_radius : float
        Objects stay beyond this radius (m); at least the half diagonal of
        the area.
    outer_radius : float
        Objects stay within this radius (m): the free radius plus ``depth``,
        grown where a crowded ring needed more room.
    objects : list of WorldObject
        Garden objects and obstacles.
    textures : dict of str to Texture
    ground, sky : GroundSpec, SkySpec
    dynamic : list of DynamicCylinder
    seed : int or None
        The seed it was generated from.
    """

    area: tuple[float, float]
    free_radius: float
    outer_radius: float
    objects: list[WorldObject] = field(default_factory=list)
    textures: dict[str, Texture] = field(default_factory=dict)
    ground: GroundSpec = field(default_factory=GroundSpec)
    sky: SkySpec = field(default_factory=SkySpec)
    dynamic: list[DynamicCylinder] = field(default_factory=list)
    seed: int | None = None

    def __post_init__(self) -> None:
        self.area = (float(self.area[0]), float(self.area[1]))
        if min(self.area) <= 0:
            raise ValueError(f"area must be two positive sizes in metres, got {self.area}")
        for o in self.objects:
            for p in o.parts:
                for t in (p.texture, p.front):
                    if t is not None and t not in self.textures:
                        raise ValueError(f"object {o.kind!r} uses texture {t!r}, which the world does not define")
        for d in self.dynamic:
            if d.texture not in self.textures:
                raise ValueError(f"dynamic object uses texture {d.texture!r}, which the world does not define")

    # ------------------------------------------------------------ generation

    @classmethod
    def generate(
        cls,
        seed: int = 0,
        area: tuple[float, float] = (16.0, 18.0),
        n_objects: int = 30,
        *,
        margin: float = 1.0,
        depth: float = 10.0,
        weights: dict[str, float] | None = None,
        markers: Sequence[int] = (),
        marker_size: float = 0.8,
        marker_dictionary: str = "DICT_ARUCO_ORIGINAL",
        obstacles: Sequence[str | dict[str, Any]] = (),
        dynamic: DynamicCylinder | dict[str, Any] | None = None,
        cloud_cover: float = 0.45,
        inner: dict[str, int] | None = None,
        patches: dict[str, int] | None = None,
        lawn: str = "patchy",
    ) -> "World":
        """Generates a garden, deterministically from ``seed``.

        Parameters
        ----------
        seed : int
            Same seed and arguments, same world (and same JSON).
        area : (width, height)
            Free area in metres, centred on the origin.
        n_objects : int
            Number of garden objects drawn from the object types.
        margin : float
            Objects keep this distance (m) beyond the half diagonal of the area.
        depth : float
            Width (m) of the ring beyond the free radius where objects stand.
        weights : dict, optional
            Relative frequency of each object type (keys from ``OBJECT_TYPES``);
            each type gets ``floor(p * n_objects)`` objects and the remainder is
            drawn at random with these weights.
        markers : sequence of int
            ArUco ids; each becomes a marker board facing the area centre,
            just outside the free area (thesis 5.4 used ids 136 and 144).
        marker_size : float
            Side of a marker's black square plus quiet zone (m).
        marker_dictionary : str
            ``cv2.aruco`` dictionary name.
        obstacles : sequence of str or dict
            ``"v-wall"`` (section 7.1.2) or dicts
            ``{"kind": "v-wall", "x", "y", "arm", "angle", "yaw", "height", "thickness"}``,
            ``{"kind": "box", "x", "y", "length", "width", "height", "yaw"}`` (m, degrees).
        dynamic : DynamicCylinder or dict, optional
            A moving textured cylinder; a dict is passed to DynamicCylinder
            (``orbit`` defaults to the free radius).
        cloud_cover : float
            Fraction of the sky under clouds, in [0, 1].
        inner : dict, optional
            Objects standing *inside* the free area (the realistic
            gardens), counts per type from ``INNER_TYPES``: ``tree`` (small
            garden trees; the robot drives under the crown, around the
            trunk), ``bush``, ``pole`` (thin painted posts: washing-line and
            lamp posts), ``shed`` (against the area border). They are
            obstacles (``world.free`` keeps clear of their parts lower than
            ``BLOCK_HEIGHT``). Drawn from their own random stream, so a
            world's outer objects do not depend on them.
        patches : dict, optional
            Ground patches inside the area, counts per kind from
            ``PATCH_KINDS`` (``patio``, ``path``, ``bed``); see
            :class:`GroundSpec`. Also their own random stream.
        lawn : {"patchy", "uniform"}
            ``"patchy"`` (default): the lawn's colour varies over metres (two
            greens mixed by fractal noise, with drier patches), as real lawns
            do. ``"uniform"``: one green everywhere, only the tiled grass
            detail and the objects' shadows vary (the thesis's Blender
            garden: "a textured ground plane"). A hierarchical SFA network
            trained on a patchy lawn codes the lawn's colour around the robot
            in its slowest outputs (docs/navigation.md).
        """
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise TypeError(f"seed must be an integer, got {type(seed).__name__}")
        try:
            w, h = (float(a) for a in area)
        except (TypeError, ValueError):
            raise ValueError(f"area must be (width, height) in metres, got {area!r}") from None
        if not (w > 0 and h > 0):
            raise ValueError(f"area must be two positive sizes in metres, got {area!r}")
        if isinstance(n_objects, bool) or not isinstance(n_objects, (int, np.integer)) or n_objects < 0:
            raise ValueError(f"n_objects must be a non-negative integer, got {n_objects!r}")
        if not depth > 0:
            raise ValueError(f"depth must be positive (m), got {depth}")
        if not 0 <= cloud_cover <= 1:
            raise ValueError(f"cloud_cover must be in [0, 1], got {cloud_cover}")
        if lawn not in LAWNS:
            raise ValueError(f"lawn must be one of {', '.join(map(repr, LAWNS))}, got {lawn!r}")
        wts = dict(DEFAULT_WEIGHTS if weights is None else weights)
        unknown = set(wts) - set(OBJECT_TYPES)
        if unknown:
            raise ValueError(f"unknown object types {sorted(unknown)}; available: {', '.join(OBJECT_TYPES)}")
        if any(v < 0 for v in wts.values()) or (n_objects and sum(wts.values()) <= 0):
            raise ValueError("object type weights must be non-negative with a positive sum")

        rng = np.random.default_rng(int(seed))
        r_free = 0.5 * float(np.hypot(w, h)) + margin
        r_out = r_free + depth
        world = cls(area=(w, h), free_radius=r_free, outer_radius=r_out, seed=int(seed))
        world.ground = GroundSpec(seed=int(rng.integers(2**31)))
        if lawn == "uniform":
            world.ground.green2 = world.ground.green
            world.ground.dry_fraction = 0.0
        world.sky = SkySpec(seed=int(rng.integers(2**31)), cloud_cover=float(cloud_cover))
        b = _Builder(world, rng)
        placed: list[WorldObject] = []

        kinds = sorted(wts)
        probs = np.array([wts[k] for k in kinds], float)
        for mid in markers:
            b.marker(int(mid), marker_size, marker_dictionary)
            obj = b.place(placed, near=True)
            placed.append(obj)
        if n_objects:
            probs = probs / probs.sum()
            # big objects first, so they find room
            order = {"house": 0, "shed": 1, "hedge": 2, "fence": 3}
            # quota sampling: each type gets floor(p n) objects, the rest are drawn by p,
            # so a garden has about the expected mix (plain draws give 8 houses now and then)
            quota = np.floor(probs * n_objects).astype(int)
            rest = rng.choice(len(kinds), size=int(n_objects) - int(quota.sum()), p=probs)
            counts = quota + np.bincount(rest, minlength=len(kinds))
            drawn = [k for k, c in zip(kinds, counts) for _ in range(int(c))]
            drawn = [drawn[i] for i in rng.permutation(len(drawn))]
            drawn.sort(key=lambda k: order.get(k, 9))
            for kind in drawn:
                getattr(b, kind)()
                placed.append(b.place(placed))
        for spec in obstacles:
            placed.extend(b.obstacle(spec))
        if inner or patches:
            # own stream: the rest of the world is the same with and without them
            rng2 = np.random.default_rng([int(seed), 7])
            b2 = _Builder(world, rng2, prefix="in")
            if patches:
                world.ground.patches = tuple(b2.patches(patches))
            if inner:
                placed.extend(b2.inner(inner, placed))
        world.objects = placed
        if dynamic is not None:
            world.add_dynamic(dynamic, seed=int(rng.integers(2**31)))
        world.__post_init__()
        return world

    def add_dynamic(self, dynamic: DynamicCylinder | dict[str, Any], seed: int = 0) -> DynamicCylinder:
        """Adds a moving textured cylinder (thesis 6.2.1). A dict is passed to
        :class:`DynamicCylinder`; its ``orbit`` defaults to the free radius
        (circling just outside the area) and ``period`` to 100 s. A missing
        texture gets a striped one."""
        if isinstance(dynamic, dict):
            d = dict(dynamic)
            d.setdefault("orbit", self.free_radius)
            d.setdefault("period", 100.0)
            try:
                dynamic = DynamicCylinder(**d)
            except TypeError as exc:
                raise ValueError(f"bad dynamic object fields: {exc}") from None
        if not isinstance(dynamic, DynamicCylinder):
            raise TypeError("dynamic must be a DynamicCylinder or a dict of its fields")
        if dynamic.texture not in self.textures:
            self.textures[dynamic.texture] = Texture(
                "stripes", (0.85, 0.2, 0.15), 0.8, int(seed), (2 * np.pi * dynamic.radius / 2, 1.0),
                {"n": 4, "color2": (0.95, 0.9, 0.3)},
            )
        self.dynamic.append(dynamic)
        return dynamic

    # ------------------------------------------------------------ queries

    @property
    def obstacles(self) -> list[WorldObject]:
        """Objects inside the free area that block the robot."""
        return [o for o in self.objects if o.obstacle]

    @property
    def markers(self) -> dict[int, tuple[float, float]]:
        """Marker id -> centre (x, y) of the marker face (m)."""
        out = {}
        for o in self.objects:
            if o.marker_id is not None:
                board = o.parts[-1]
                out[o.marker_id] = (board.x, board.y)
        return out

    def in_area(self, x: Any, y: Any, margin: float = 0.0) -> np.ndarray:
        """Whether points lie inside the free area shrunk by ``margin`` (m)."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        return (np.abs(x) <= self.area[0] / 2 - margin) & (np.abs(y) <= self.area[1] / 2 - margin)

    def collides(self, x: Any, y: Any, margin: float = 0.0) -> np.ndarray:
        """Whether points are within ``margin`` (m) of an obstacle footprint
        (of its parts lower than ``BLOCK_HEIGHT``)."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        hit = np.zeros(np.broadcast(x, y).shape, bool)
        for o in self.obstacles:
            for p in o.parts:
                if p.z0 < BLOCK_HEIGHT:
                    hit |= _rect_distance(x, y, p) <= margin
        return hit

    def free(self, x: Any, y: Any, margin: float = 0.0) -> np.ndarray:
        """Inside the area (shrunk by ``margin``) and clear of obstacles by ``margin``."""
        return self.in_area(x, y, margin) & ~self.collides(x, y, margin)

    def primitives(self, t: float = 0.0) -> list[Primitive]:
        """All primitives, with the dynamic objects where they are at time ``t`` (s)."""
        prims = [p for o in self.objects for p in o.parts]
        prims.extend(d.primitive_at(t) for d in self.dynamic)
        return prims

    # ------------------------------------------------------------ JSON

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "version": VERSION,
            "seed": self.seed,
            "area": list(self.area),
            "free_radius": self.free_radius,
            "outer_radius": self.outer_radius,
            "ground": _ground_dict(self.ground),
            "sky": asdict(self.sky),
            "textures": {k: t.to_dict() for k, t in self.textures.items()},
            "objects": [asdict(o) for o in self.objects],
            "dynamic": [asdict(d) for d in self.dynamic],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "World":
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise ValueError(f"not an sfanav world (format {d.get('format') if isinstance(d, dict) else None!r})")
        if int(d.get("version", 0)) > VERSION:
            raise ValueError(
                f"world file version {d['version']} is newer than this sfanav reads ({VERSION}); upgrade sfanav"
            )
        try:
            objects = [
                WorldObject(**{**o, "parts": [Primitive(**p) for p in o["parts"]]}) for o in d["objects"]
            ]
            return cls(
                area=tuple(d["area"]),
                free_radius=float(d["free_radius"]),
                outer_radius=float(d["outer_radius"]),
                objects=objects,
                textures={k: Texture.from_dict(t) for k, t in d["textures"].items()},
                ground=GroundSpec(**_tuples(d["ground"])),
                sky=SkySpec(**_tuples(d["sky"])),
                dynamic=[DynamicCylinder(**_tuples(x)) for x in d.get("dynamic", [])],
                seed=d.get("seed"),
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"world file is missing or has a bad field: {exc}") from None

    def save(self, path: str | os.PathLike) -> None:
        """Writes the world as JSON."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def load(cls, path: str | os.PathLike) -> "World":
        """Reads a world written by :meth:`save`."""
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"no world file at {path}")
        try:
            d = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"world file {path} is not valid JSON: {exc}") from None
        return cls.from_dict(d)


def _ground_dict(g: GroundSpec) -> dict[str, Any]:
    d = asdict(g)
    if not d["patches"]:
        del d["patches"]  # worlds without patches write what they always wrote
    else:
        d["patches"] = [dict(p) for p in g.patches]
    return d


def _tuples(d: dict[str, Any]) -> dict[str, Any]:
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}


class _Builder:
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
