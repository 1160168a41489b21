"""Garden worlds: seeded generation and JSON files (thesis section 4.1).

A world is a flat textured ground plane under a sky with clouds and a
distant tree line, with garden objects (trees, conifers, bushes, houses,
sheds, fences, hedges, rocks, ArUco marker boards) placed at random polar
coordinates whose radii lie beyond the free area where the robot moves: the
construction of the thesis's Blender gardens. Optional obstacles (the
v-shaped wall of section 7.1.2, boxes) stand inside the area, optional
transient objects (garden furniture, a snowman, ...: :mod:`sfanav.sim.transient`)
are there in some seasons only, and an optional dynamic object (a textured
cylinder circling the area, section 6.2.1) moves with time.

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

from .objects import ObjectBuilder
from .primitives import BLOCK_HEIGHT, Primitive, WorldObject
from .textures import Texture
from .transient import TransientBuilder

FORMAT = "sfanav-world"


VERSION = 1


OBJECT_TYPES = ("tree", "conifer", "bush", "house", "shed", "fence", "hedge", "rock")








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
class MarkerOcclusion:
    """A marker hidden from a region of the area (thesis 5.4.1, occlusions).

    While the camera stands inside the rectangle ``x_range`` x ``y_range``
    (metres, bounds included; None: unbounded on that side), the marker's
    face is covered: the renderer draws the board's plain side texture in
    its place, so the marker cannot be detected from there. From everywhere
    else it looks as usual.

    Attributes
    ----------
    marker_id : int
        The hidden marker (an id of the world's ``markers``).
    x_range, y_range : (lo, hi)
        The region, metres; ``lo`` or ``hi`` None for no bound.

    Examples
    --------
    >>> occ = MarkerOcclusion(136, (None, 0.0), (None, 0.0))   # x <= 0 and y <= 0
    >>> bool(occ.contains(-1.0, -2.0)), bool(occ.contains(1.0, -2.0))
    (True, False)
    """

    marker_id: int
    x_range: tuple[float | None, float | None] = (None, None)
    y_range: tuple[float | None, float | None] = (None, None)

    def __post_init__(self) -> None:
        if isinstance(self.marker_id, bool) or not isinstance(self.marker_id, (int, np.integer)):
            raise TypeError(f"occlusion marker_id must be an integer, got {self.marker_id!r}")
        self.marker_id = int(self.marker_id)
        self.x_range = _bounds(self.x_range, "x_range")
        self.y_range = _bounds(self.y_range, "y_range")

    def contains(self, x: Any, y: Any) -> np.ndarray:
        """Whether camera positions ``(x, y)`` (metres, broadcast) lie in the region."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        inside = np.ones(np.broadcast(x, y).shape, bool)
        for v, (lo, hi) in ((x, self.x_range), (y, self.y_range)):
            if lo is not None:
                inside &= v >= lo
            if hi is not None:
                inside &= v <= hi
        return inside

    def to_dict(self) -> dict[str, Any]:
        return {"marker_id": self.marker_id, "x_range": list(self.x_range), "y_range": list(self.y_range)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "MarkerOcclusion":
        """An occlusion from :meth:`to_dict` output; ValueError for unknown or missing keys."""
        if isinstance(d, MarkerOcclusion):
            return d
        if not isinstance(d, dict):
            raise TypeError(f"an occlusion is a MarkerOcclusion or a dict, got {type(d).__name__}")
        unknown = set(d) - {"marker_id", "x_range", "y_range"}
        if unknown or "marker_id" not in d:
            raise ValueError(f"an occlusion is {{'marker_id', 'x_range', 'y_range'}}, got keys {sorted(map(str, d))}")
        return cls(d["marker_id"], tuple(d.get("x_range", (None, None))), tuple(d.get("y_range", (None, None))))


def _bounds(r: Any, name: str) -> tuple[float | None, float | None]:
    try:
        lo, hi = r
    except (TypeError, ValueError):
        raise ValueError(f"occlusion {name} must be (lo, hi) in metres (None: unbounded), got {r!r}") from None
    out = []
    for v in (lo, hi):
        if v is None:
            out.append(None)
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v):
            raise ValueError(f"occlusion {name} bounds must be finite numbers or None, got {r!r}")
        out.append(float(v))
    if out[0] is not None and out[1] is not None and out[0] > out[1]:
        raise ValueError(f"occlusion {name} must have lo <= hi, got {r!r}")
    return out[0], out[1]


@dataclass
class GroundSpec:
    """The lawn: a photographic detail texture (``detail``, tiling every
    ``detail_tile`` metres) times a large-scale colour map (two greens mixed
    by fractal noise, with drier patches) sampled every ``resolution`` m.

    ``patches``: dicts painted over the lawn's colour map (the realistic gardens'
    realistic gardens), each with a ``kind`` from ``sim.primitives.PATCH_KINDS``:
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
    patches: tuple = ()  # ground patches painted over the lawn (see sim.primitives.PATCH_KINDS)


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
    occlusions : list of MarkerOcclusion
        Markers hidden from regions of the area (thesis 5.4.1).
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
    occlusions: list[MarkerOcclusion] = field(default_factory=list)

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
        self.occlusions = [MarkerOcclusion.from_dict(o) for o in self.occlusions]
        ids = {o.marker_id for o in self.objects if o.marker_id is not None}
        for occ in self.occlusions:
            if occ.marker_id not in ids:
                raise ValueError(f"occlusion of marker {occ.marker_id}, but the world has "
                                 + (f"markers {sorted(ids)} only" if ids else "no markers"))

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
        occlusions: Sequence[MarkerOcclusion | dict[str, Any]] = (),
        cloud_cover: float = 0.45,
        inner: dict[str, int] | None = None,
        patches: dict[str, int] | None = None,
        lawn: str = "patchy",
        transient: Sequence[dict[str, Any]] = (),
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
        occlusions : sequence of MarkerOcclusion or dict
            Markers hidden from regions of the area (thesis 5.4.1), e.g.
            ``{"marker_id": 136, "x_range": [None, 0], "y_range": [None, 0]}``;
            each must name one of ``markers``. They draw no random numbers:
            the world is otherwise the same with and without them.
        cloud_cover : float
            Fraction of the sky under clouds, in [0, 1].
        inner : dict, optional
            Objects standing *inside* the free area (the realistic
            gardens), counts per type from ``sim.primitives.INNER_TYPES``: ``tree`` (small
            garden trees; the robot drives under the crown, around the
            trunk), ``bush``, ``pole`` (thin painted posts: washing-line and
            lamp posts), ``shed`` (against the area border). They are
            obstacles (``world.free`` keeps clear of their parts lower than
            ``BLOCK_HEIGHT``). Drawn from their own random stream, so a
            world's outer objects do not depend on them.
        patches : dict, optional
            Ground patches inside the area, counts per kind from
            ``sim.primitives.PATCH_KINDS`` (``patio``, ``path``, ``bed``); see
            :class:`GroundSpec`. Also their own random stream.
        lawn : {"patchy", "uniform"}
            ``"patchy"`` (default): the lawn's colour varies over metres (two
            greens mixed by fractal noise, with drier patches), as real lawns
            do. ``"uniform"``: one green everywhere, only the tiled grass
            detail and the objects' shadows vary (the thesis's Blender
            garden: "a textured ground plane"). A hierarchical SFA network
            trained on a patchy lawn codes the lawn's colour around the robot
            in its slowest outputs (docs/navigation.md).
        transient : sequence of dict
            Objects that are there in some seasons only (thesis 6.1), e.g.
            ``{"kind": "parasol", "seasons": ["summer"], "x": 3.0, "y": 3.0}``;
            kinds ``sim.transient.TRANSIENT_KINDS``, keys and placement as
            :mod:`sfanav.sim.transient` says (by default a random spot inside
            the area). Drawn from their own random stream, so the rest of
            the world is the same with and without them.

        Raises
        ------
        ValueError
            Bad sizes, counts, weights, kinds or specs (the message names
            the argument).
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
        b = ObjectBuilder(world, rng)
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
            b2 = ObjectBuilder(world, rng2, prefix="in")
            if patches:
                world.ground.patches = tuple(b2.patches(patches))
            if inner:
                placed.extend(b2.inner(inner, placed))
        # own stream as well: the rest of the world is the same with and without them
        placed.extend(TransientBuilder(world, np.random.default_rng([int(seed), 11])).build(
            () if transient is None else transient, placed))
        world.objects = placed
        world.occlusions = list(occlusions)
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
        """Objects inside the free area that block the robot (transient ones
        in every season)."""
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

    def hidden_markers(self, x: float, y: float) -> frozenset[int]:
        """Ids of the markers an occlusion hides from a camera at ``(x, y)`` (m)."""
        return frozenset(o.marker_id for o in self.occlusions if bool(o.contains(x, y)))

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

    @property
    def transient(self) -> list[WorldObject]:
        """Objects that are there in some seasons only (``WorldObject.seasons``)."""
        return [o for o in self.objects if o.transient]

    def primitives(self, t: float = 0.0, season: str | None = None) -> list[Primitive]:
        """The primitives of the objects there in the season named ``season``
        (None: counted as summer, see ``WorldObject.present``), with the
        dynamic objects where they are at time ``t`` (s)."""
        prims = [p for o in self.objects if o.present(season) for p in o.parts]
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
            "objects": [_object_dict(o) for o in self.objects],
            "dynamic": [asdict(d) for d in self.dynamic],
            # worlds without occlusions write what they always wrote
            **({"occlusions": [o.to_dict() for o in self.occlusions]} if self.occlusions else {}),
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
                occlusions=[MarkerOcclusion.from_dict(o) for o in d.get("occlusions", [])],
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


def _object_dict(o: WorldObject) -> dict[str, Any]:
    d = asdict(o)
    if d["seasons"] is None:
        del d["seasons"]  # worlds without transient objects write what they always wrote
    else:
        d["seasons"] = list(d["seasons"])
    return d


def _ground_dict(g: GroundSpec) -> dict[str, Any]:
    d = asdict(g)
    if not d["patches"]:
        del d["patches"]  # worlds without patches write what they always wrote
    else:
        d["patches"] = [dict(p) for p in g.patches]
    return d


def _tuples(d: dict[str, Any]) -> dict[str, Any]:
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}
