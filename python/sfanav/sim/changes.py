"""Gardens that change between runs: objects moved, removed or added.

A garden a robot maps is not the same from one run to the next: a shed is
moved, a tree is cut down, a car or a trailer is parked by the fence,
garden furniture comes out. :class:`GardenChanges` describes such a change
and :meth:`GardenChanges.apply` makes the changed garden from a world: a new
:class:`~sfanav.sim.world.World` (the original is left as it is) and one
record per object changed.

A preset gives a run a changed garden with ``RunSpec(..., changes=
GardenChanges(...))`` (:mod:`sfanav.sim.presets`); runs whose changes have
the same ``name`` see the same changed garden. ``simulate`` draws the
changes from the preset seed (a stream of their own: the rest of the
dataset is the same with and without them), writes the changed world as
``world-<name>.json`` beside ``world.json`` (the unchanged world) and
records what changed in ``metadata.json["gardens"][name]`` and which
garden a run saw in ``metadata.json["runs"][run]["garden"]``.

What changes: only the garden objects around the free area (not obstacles
inside it, marker boards or objects that come and go with the seasons),
and new objects stand in the ring around the area, within
:data:`NEAR` m of its free radius (where a robot in the area sees them;
farther out where that band is full). So
a trajectory planned in one garden is valid in the other, and the lawn, the
sky and every other object stay exactly as they were (the world's
``outer_radius``, which sizes the lawn's colour map, does not change). A
moved object keeps its shape and its orientation to the garden's centre: it
is turned about the centre by at least ``min_turn_deg`` and shifted by up
to :data:`SHIFT` m outwards or inwards. A changed garden has no dynamic
object (:class:`~sfanav.sim.world.DynamicCylinder`).

Units: metres; ``min_turn_deg`` in degrees, yaw in radians in the primitives.

Examples
--------
>>> from sfanav.sim import World
>>> w = World.generate(0, area=(8.0, 8.0), n_objects=12)
>>> changed, records = GardenChanges("after", move=2, remove=1, add=("car",)).apply(w, rng=0)
>>> sorted(r["change"] for r in records)
['added', 'moved', 'moved', 'removed']
>>> len(changed.objects) == len(w.objects), changed.outer_radius == w.outer_radius
(True, True)
"""

from __future__ import annotations

import copy
import re
import zlib
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from .._checks import check_int, check_positive_float
from .objects import ObjectBuilder
from .primitives import Primitive, WorldObject, posed
from .transient import TransientBuilder

if TYPE_CHECKING:
    from .world import World

CHANGEABLE_KINDS = ("tree", "conifer", "bush", "shed", "fence", "hedge", "rock")
"""The garden objects that may be moved or removed by default (houses stay)."""

ADD_KINDS = ("car", "trailer", "shed", "fence", "hedge", "bush", "tree", "conifer", "rock", "furniture", "parasol",
             "wheelbarrow", "toys", "tarp")
"""The objects a change can add: a parked car and a trailer, the garden
objects of :data:`sfanav.sim.world.OBJECT_TYPES` but houses, and some of
:data:`sfanav.sim.transient.TRANSIENT_KINDS` (there for good here)."""

NEAR = 3.0
"""New objects stand between the free radius and this many metres (plus their radius) beyond it."""

SHIFT = 1.5
"""A moved object's distance from the centre changes by at most this (m)."""

CLEARANCE = 0.3
"""Objects keep at least this gap (m) between their footprint circles, as when the garden was generated."""

#: new objects whose long side faces the area (parked along the border)
_ALONG_BORDER = ("car", "trailer", "fence", "hedge")

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")

_CAR_PAINT = ((0.75, 0.75, 0.77), (0.10, 0.10, 0.12), (0.62, 0.10, 0.10), (0.15, 0.25, 0.55), (0.92, 0.92, 0.90))


@dataclass(frozen=True)
class GardenChanges:
    """What changes in a garden between runs.

    Parameters
    ----------
    name : str
        The changed garden's name (letters, digits, ``_``, ``.``, ``-``):
        its world file is ``world-<name>.json`` and runs naming the same
        garden see the same changes.
    move, remove : int, default 0
        Garden objects (of ``kinds``) moved to a new place around the area,
        and removed; distinct objects, drawn at random.
    add : sequence of str, default ()
        Kinds of new objects (:data:`ADD_KINDS`), one each, placed at random
        in the ring around the area.
    kinds : sequence of str, default :data:`CHANGEABLE_KINDS`
        The kinds of existing objects that may be moved or removed.
    min_turn_deg : float, default 30
        A moved object is turned about the garden's centre by this much at
        least (at most 180 degrees).

    Raises
    ------
    ValueError
        A bad name, negative counts, an unknown kind, ``min_turn_deg``
        outside (0, 180], nothing to change.
    TypeError
        Counts that are not integers.

    Examples
    --------
    >>> GardenChanges("after", move=1, add=("trailer",)).to_dict()["add"]
    ['trailer']
    """

    name: str
    move: int = 0
    remove: int = 0
    add: tuple[str, ...] = ()
    kinds: tuple[str, ...] = CHANGEABLE_KINDS
    min_turn_deg: float = 30.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name):
            raise ValueError(f"garden changes name must be letters, digits, '_', '.' or '-' (a file name part), "
                             f"got {self.name!r}")
        check_int(self.move, "garden changes move", minimum=0)
        check_int(self.remove, "garden changes remove", minimum=0)
        for field_, allowed in (("add", ADD_KINDS), ("kinds", CHANGEABLE_KINDS + ("house",))):
            value = getattr(self, field_)
            if isinstance(value, str) or not isinstance(value, (list, tuple)):
                raise ValueError(f"garden changes {field_} must be a list of kinds, got {value!r}")
            bad = [k for k in value if k not in allowed]
            if bad:
                raise ValueError(f"garden changes {field_}: unknown kinds {bad}; available: {', '.join(allowed)}")
            object.__setattr__(self, field_, tuple(value))
        turn = check_positive_float(self.min_turn_deg, "garden changes min_turn_deg")
        if turn > 180:
            raise ValueError(f"garden changes min_turn_deg must be in (0, 180], got {turn}")
        object.__setattr__(self, "min_turn_deg", turn)
        if not (self.move or self.remove or self.add):
            raise ValueError(f"garden changes {self.name!r} change nothing: give move, remove or add")

    def to_dict(self) -> dict[str, Any]:
        """The spec as JSON-ready data (``GardenChanges(**d)`` makes it again)."""
        d = asdict(self)
        d["add"], d["kinds"] = list(self.add), list(self.kinds)
        return d

    def apply(self, world: World, rng: np.random.Generator | int | None = None) -> tuple[World, list[dict[str, Any]]]:
        """The changed garden: ``(world, records)``.

        ``world`` is a deep copy of the given world with the changes (the
        given one is not modified); ``records`` one dict per object changed,
        in the order moved, removed, added: ``{"change": "moved", "kind",
        "from": [x, y], "to": [x, y], "turn_deg"}``, ``{"change": "removed",
        "kind", "at": [x, y]}``, ``{"change": "added", "kind", "at": [x,
        y]}`` (metres, the object's anchor). ``rng`` draws which objects
        change, where they go and what the new ones look like.

        Raises
        ------
        ValueError
            Fewer changeable objects than ``move + remove``, no room for a
            moved or new object in the ring, a world already changed under
            this name.
        """
        rng = np.random.default_rng(rng)
        prefix = f"{self.name}:"
        if any(k.startswith(prefix) for k in world.textures):
            raise ValueError(f"this world was already changed as garden {self.name!r}: name the next change anew")
        pool = [i for i, o in enumerate(world.objects) if o.kind in self.kinds and not o.obstacle
                and o.marker_id is None and not o.transient]
        if self.move + self.remove > len(pool):
            raise ValueError(f"garden changes {self.name!r}: {self.move} objects to move and {self.remove} to remove, "
                             f"but the world has {len(pool)} of kinds {', '.join(self.kinds)}")
        picked = [pool[int(i)] for i in rng.permutation(len(pool))[: self.move + self.remove]]
        moving, removing = picked[: self.move], set(picked[self.move:])
        out = copy.deepcopy(world)
        old = out.objects
        kept = [o for i, o in enumerate(old) if i not in removing and i not in moving]
        records: list[dict[str, Any]] = []
        moved_to: dict[int, WorldObject] = {}
        for i in moving:
            o = old[i]
            moved_to[i], turn = self._moved(o, kept + list(moved_to.values()), out, rng)
            n = moved_to[i]
            records.append({"change": "moved", "kind": o.kind, "from": [o.x, o.y], "to": [n.x, n.y],
                            "turn_deg": float(np.degrees(turn))})
        for i in sorted(removing):
            records.append({"change": "removed", "kind": old[i].kind, "at": [old[i].x, old[i].y]})
        # the order of the objects as before; new ones at the end
        objects = [moved_to.get(i, o) for i, o in enumerate(old) if i not in removing]
        builder = _ChangeBuilder(out, rng, prefix)
        for kind in self.add:
            new = builder.placed(kind, objects)
            objects.append(new)
            records.append({"change": "added", "kind": kind, "at": [new.x, new.y]})
        out.objects = objects
        _prune_textures(out, [old[i] for i in removing])
        out.dynamic = []
        out.__post_init__()
        return out, records

    def _moved(self, o: WorldObject, others: list[WorldObject], world: World,
               rng: np.random.Generator) -> tuple[WorldObject, float]:
        """``o`` turned about the centre by at least ``min_turn_deg`` and
        shifted radially, clear of ``others``: (the moved object, its turn in radians)."""
        r0, a0 = float(np.hypot(o.x, o.y)), float(np.arctan2(o.y, o.x))
        lo, hi = world.free_radius + o.radius, world.outer_radius - o.radius
        lo_turn = np.radians(self.min_turn_deg)
        for _ in range(2000):
            turn = float(rng.uniform(lo_turn, np.pi)) * (1.0 if rng.random() < 0.5 else -1.0)
            r = float(np.clip(r0 + rng.uniform(-SHIFT, SHIFT), lo, max(lo, hi))) if hi > lo else r0
            x, y = r * np.cos(a0 + turn), r * np.sin(a0 + turn)
            if _clear(x, y, o.radius, others):
                break
        else:
            raise ValueError(f"garden changes {self.name!r}: no room to move the {o.kind} at ({o.x:.1f}, {o.y:.1f}) m")
        parts = posed(o.parts, x, y, turn, about=(o.x, o.y))
        return WorldObject(o.kind, float(x), float(y), o.radius, parts, o.obstacle, o.marker_id, o.seasons), turn


def changes_stream(seed: int, name: str) -> np.random.Generator:
    """The random stream of the changed garden ``name`` of a preset seed:
    independent of the preset's other streams and of other gardens'
    (:func:`sfanav.sim.recording.simulate` uses it)."""
    key = zlib.crc32(name.encode("utf-8"))
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(7, key)))


def changed_gardens(world: World, runs: Sequence[Any], seed: int) -> dict[str, tuple[World, list, GardenChanges]]:
    """The changed gardens that ``runs`` (:class:`~sfanav.sim.presets.RunSpec`,
    their ``changes``) see: name -> (world, records, spec)
    (:meth:`GardenChanges.apply` on ``world``, drawn from
    :func:`changes_stream` of ``seed`` and the name).
    ValueError for two runs naming one garden with different changes."""
    out: dict[str, tuple[World, list, GardenChanges]] = {}
    for r in runs:
        spec = r.changes
        if spec is None:
            continue
        if spec.name in out:
            if out[spec.name][2] != spec:
                raise ValueError(f"run {r.name!r} names the changed garden {spec.name!r} with other changes than an "
                                 "earlier run: give the changes another name")
            continue
        changed, records = spec.apply(world, changes_stream(seed, spec.name))
        out[spec.name] = (changed, records, spec)
    return out


def _clear(x: float, y: float, radius: float, others: list[WorldObject]) -> bool:
    """Whether a footprint circle at (x, y) keeps :data:`CLEARANCE` from the
    garden objects in ``others`` (obstacles inside the area are far away)."""
    return all(np.hypot(x - o.x, y - o.y) >= radius + o.radius + CLEARANCE for o in others if not o.obstacle)


def _prune_textures(world: World, removed: list[WorldObject]) -> None:
    """Drops the textures only removed objects used."""
    used = {t for o in world.objects for p in o.parts for t in (p.texture, p.front) if t is not None}
    for o in removed:
        for p in o.parts:
            for t in (p.texture, p.front):
                if t is not None and t not in used:
                    world.textures.pop(t, None)


class _ChangeBuilder(TransientBuilder):
    """Builds the new objects of a change (:data:`ADD_KINDS`); their
    textures are named ``<garden name>:<kind><n>``."""

    def __init__(self, world: World, rng: np.random.Generator, prefix: str):
        ObjectBuilder.__init__(self, world, rng, prefix=prefix)

    def car(self) -> tuple[float, list[Primitive]]:
        """A parked car: body, a dark glass house, four wheels (length along x)."""
        length, width = self.u(4.0, 4.8), self.u(1.7, 1.85)
        body = self.tex("noise", self.jitter(_CAR_PAINT[int(self.rng.integers(len(_CAR_PAINT)))], 0.03), 0.15,
                        (1.0, 1.0))
        glass = self.tex("noise", (0.12, 0.14, 0.17), 0.2, (0.5, 0.5))
        tyre = self.tex("noise", (0.06, 0.06, 0.06), 0.2, (0.3, 0.3))
        parts = [Primitive("box", 0, 0, 0.3, 0.95, body, length=length, width=width),
                 Primitive("box", -0.08 * length, 0, 0.95, 1.45, glass, length=0.55 * length, width=width - 0.12)]
        parts += [Primitive("box", sx * 0.32 * length, sy * (width / 2 - 0.12), 0.0, 0.62, tyre, length=0.62,
                            width=0.22) for sx in (-1, 1) for sy in (-1, 1)]
        return 0.5 * float(np.hypot(length, width)), parts

    def trailer(self) -> tuple[float, list[Primitive]]:
        """A box trailer with a drawbar, sometimes under a tarpaulin."""
        length, width = self.u(2.0, 3.0), self.u(1.3, 1.6)
        side = self.tex("planks", self.jitter((0.58, 0.58, 0.56), 0.03), 0.5, (1.0, 0.5), boards=3, gap=0.05)
        dark = self.tex("noise", (0.08, 0.08, 0.08), 0.2, (0.3, 0.3))
        parts = [Primitive("box", 0, 0, 0.45, 0.95, side, length=length, width=width),
                 Primitive("box", 0.5 * length + 0.6, 0, 0.4, 0.5, dark, length=1.2, width=0.08)]
        parts += [Primitive("box", 0, sy * (width / 2 + 0.12), 0.0, 0.55, dark, length=0.55, width=0.18)
                  for sy in (-1, 1)]
        if self.rng.random() < 0.5:
            cover = self.tex("noise", self.jitter((0.15, 0.30, 0.60), 0.08), 0.5, (0.8, 0.8), beta=1.6)
            parts.append(Primitive("box", 0, 0, 0.95, self.u(1.3, 1.7), cover, length=length - 0.1, width=width - 0.1))
        return max(0.5 * float(np.hypot(length, width + 0.6)), 0.5 * length + 1.2), parts

    def placed(self, kind: str, others: list[WorldObject]) -> WorldObject:
        """A new ``kind`` object at a free spot in the ring, clear of ``others``."""
        if kind in ("car", "trailer") or not hasattr(ObjectBuilder, kind):  # built at the origin facing +x
            radius, parts = getattr(self, kind)()
        else:  # a garden object of World.generate
            getattr(self, kind)()
            assert self.pending is not None
            _, radius, parts, _, _ = self.pending
            self.pending = None
        lo, top = self.w.free_radius + radius, self.w.outer_radius - radius
        found = False
        for attempt in range(4000 if top > lo else 0):
            hi = min(lo + NEAR, top) if attempt < 2000 else top  # crowded near the area: anywhere in the ring
            r = float(np.sqrt(self.rng.uniform(lo**2, hi**2)))
            a = float(self.rng.uniform(0, 2 * np.pi))
            x, y = r * np.cos(a), r * np.sin(a)
            if _clear(x, y, radius, others):
                found = True
                break
        if not found:
            raise ValueError(f"no room for a new {kind} in the ring around the {self.w.area[0]:g} x "
                             f"{self.w.area[1]:g} m area")
        yaw = a - np.pi / 2 + self.u(-0.2, 0.2) if kind in _ALONG_BORDER else self.u(0, 2 * np.pi)
        return WorldObject(kind, float(x), float(y), float(radius), posed(parts, x, y, yaw), False)
