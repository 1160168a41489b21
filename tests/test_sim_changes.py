"""Gardens that change between runs (sim.changes, RunSpec(changes=...), the
garden-changes preset): what changes and what stays, rendering, the
dataset's records, determinism and bad parameters."""

import json

import numpy as np
import pytest

from sfanav import Dataset, sim
from sfanav.sim import GardenChanges, Lighting, PanoramicCamera, Renderer, World
from sfanav.sim.changes import ADD_KINDS, NEAR, changed_gardens, changes_stream
from sfanav.sim.presets import GARDEN_CHANGES, RunSpec
from clitools import run

CAM = PanoramicCamera(360, 24)


@pytest.fixture(scope="module")
def garden():
    return World.generate(3, area=(8.0, 8.0), n_objects=20)


def _key(o):
    return json.dumps([o.kind, o.x, o.y, [p.__dict__ for p in o.parts]], sort_keys=True)


def test_apply_moves_removes_and_adds_and_keeps_the_rest(garden):
    before = json.dumps(garden.to_dict())
    spec = GardenChanges("b", move=2, remove=2, add=("car", "trailer", "furniture"))
    changed, records = spec.apply(garden, 0)
    assert json.dumps(garden.to_dict()) == before  # the given world is left as it is
    assert [r["change"] for r in records] == ["moved"] * 2 + ["removed"] * 2 + ["added"] * 3
    assert len(changed.objects) == len(garden.objects) - 2 + 3
    old = {_key(o) for o in garden.objects}
    new = {_key(o) for o in changed.objects}
    assert len(old & new) == len(garden.objects) - 4  # every other object exactly as it was
    # the lawn's extent, the sky and the ground stay (outer_radius sizes the lawn's colour map)
    assert changed.outer_radius == garden.outer_radius and changed.free_radius == garden.free_radius
    assert changed.sky == garden.sky and changed.ground == garden.ground
    near = []
    for r in records:
        if r["change"] == "moved":
            assert abs(r["turn_deg"]) >= 30 - 1e-9
            src = next(o for o in garden.objects if [o.x, o.y] == r["from"])
            dst = next(o for o in changed.objects if [o.x, o.y] == r["to"])
            assert dst.kind == src.kind == r["kind"]
            # the same shape: sizes and heights of the parts, distances between them
            assert [(p.shape, p.z0, p.z1, p.radius, p.length, p.width) for p in src.parts] == \
                   [(p.shape, p.z0, p.z1, p.radius, p.length, p.width) for p in dst.parts]
            d = lambda o: [np.hypot(p.x - o.x, p.y - o.y) for p in o.parts]  # noqa: E731
            np.testing.assert_allclose(d(src), d(dst), atol=1e-9)
        elif r["change"] == "added":
            o = next(o for o in changed.objects if [o.x, o.y] == r["at"])
            dist = np.hypot(o.x, o.y)
            # in the ring, near the area where there is room
            assert garden.free_radius + o.radius - 1e-9 <= dist <= garden.outer_radius - o.radius + 1e-9
            near.append(dist <= garden.free_radius + o.radius + NEAR + 1e-9)
    assert any(near)
    # clear of each other, as when the garden was generated
    objs = [o for o in changed.objects if not o.obstacle]
    for i, a in enumerate(objs):
        for b in objs[i + 1:]:
            if _key(a) not in old or _key(b) not in old:
                assert np.hypot(a.x - b.x, a.y - b.y) >= a.radius + b.radius + 0.3 - 1e-9
    # the removed objects' textures go with them, the new ones come under the garden's name
    used = {p.texture for o in changed.objects for p in o.parts} | {p.front for o in changed.objects for p in o.parts}
    assert set(changed.textures) <= used | set(garden.textures) and set(changed.textures) <= used | {None}
    assert any(k.startswith("b:") for k in changed.textures)
    # JSON round trip
    assert World.from_dict(json.loads(json.dumps(changed.to_dict()))).to_dict() == \
           World.from_dict(changed.to_dict()).to_dict()


def test_changes_are_deterministic_from_the_stream(garden):
    spec = GardenChanges("b", move=2, remove=1, add=("shed",))
    a, ra = spec.apply(garden, changes_stream(5, "b"))
    b, rb = spec.apply(garden, changes_stream(5, "b"))
    assert ra == rb and a.to_dict() == b.to_dict()
    _, rc = spec.apply(garden, changes_stream(6, "b"))
    _, rd = spec.apply(garden, changes_stream(5, "c"))
    assert rc != ra and rd != ra


def _span(pose, x, y, radius, margin_deg=4.0):
    """(bearing, half width) in radians of a footprint circle seen from pose (x, y, heading 0)."""
    dx, dy = x - pose[0], y - pose[1]
    dist = np.hypot(dx, dy)
    return np.arctan2(dy, dx), np.arcsin(min(1.0, radius / dist)) + np.radians(margin_deg)


def test_a_changed_object_renders_differently_and_the_rest_the_same(garden):
    changed, records = GardenChanges("b", move=1, remove=1, add=("car",)).apply(garden, 1)
    light = Lighting(shadows=False)
    pose = (0.0, 0.0, 0.0)
    a = Renderer(garden).render(CAM, pose, lighting=light)
    b = Renderer(changed).render(CAM, pose, lighting=light)
    near = np.zeros(CAM.width, bool)
    spans = []
    for r in records:
        for where, world in (("from", garden), ("at", None), ("to", changed)):
            if where in r:
                objs = garden.objects if r["change"] == "removed" else (world or changed).objects
                o = next(o for o in objs if [o.x, o.y] == r[where])
                c, h = _span(pose, o.x, o.y, o.radius)
                spans.append((c, h))
                near |= np.abs(np.angle(np.exp(1j * (CAM.bearings - c)))) <= h
    assert 0 < near.sum() < CAM.width / 2
    # away from every changed object the images are the same, pixel for pixel
    np.testing.assert_array_equal(a[:, ~near], b[:, ~near])
    # and where each one stood or stands they differ
    for c, h in spans:
        cols = np.abs(np.angle(np.exp(1j * (CAM.bearings - c)))) <= h - np.radians(4.0)
        assert (a[:, cols] != b[:, cols]).any(), np.degrees(c)


def test_every_added_kind_builds_and_renders():
    changed, records = GardenChanges("all", add=ADD_KINDS).apply(World.generate(0, area=(8.0, 8.0), n_objects=6), 2)
    assert [r["kind"] for r in records] == list(ADD_KINDS)
    img = Renderer(changed).render(PanoramicCamera(60, 8), (0.0, 0.0, 0.0))
    assert img.shape == (8, 60, 3)


@pytest.mark.parametrize("kwargs, error, match", [
    ({"name": "a/b", "move": 1}, ValueError, "name must be letters"),
    ({"name": "", "move": 1}, ValueError, "name must be letters"),
    ({"name": "b"}, ValueError, "change nothing"),
    ({"name": "b", "move": -1}, ValueError, "move must be at least 0"),
    ({"name": "b", "move": 1.5}, TypeError, "move must be an integer"),
    ({"name": "b", "add": ("spaceship",)}, ValueError, "unknown kinds \\['spaceship'\\]"),
    ({"name": "b", "add": "car"}, ValueError, "add must be a list of kinds"),
    ({"name": "b", "move": 1, "kinds": ("marker",)}, ValueError, "kinds: unknown kinds"),
    ({"name": "b", "move": 1, "min_turn_deg": 0}, ValueError, "min_turn_deg must be > 0"),
    ({"name": "b", "move": 1, "min_turn_deg": 200}, ValueError, "min_turn_deg must be in \\(0, 180\\]"),
])
def test_bad_changes(kwargs, error, match):
    with pytest.raises(error, match=match):
        GardenChanges(**kwargs)


def test_changes_that_do_not_fit(garden):
    with pytest.raises(ValueError, match="100 objects to move and 0 to remove, but the world has"):
        GardenChanges("b", move=100).apply(garden)
    changed, _ = GardenChanges("b", add=("car",)).apply(garden)
    with pytest.raises(ValueError, match="already changed as garden 'b'"):
        GardenChanges("b", add=("car",)).apply(changed)
    tight = World.generate(0, area=(4.0, 4.0), n_objects=0, depth=0.5)
    with pytest.raises(ValueError, match="no room for a new car"):
        GardenChanges("b", add=("car",)).apply(tight)
    with pytest.raises(TypeError, match="changes must be a GardenChanges"):
        RunSpec("x", lambda w, r: None, changes="after")
    runs = [RunSpec("x", lambda w, r: None, changes=GardenChanges("b", move=1)),
            RunSpec("y", lambda w, r: None, changes=GardenChanges("b", move=2))]
    with pytest.raises(ValueError, match="names the changed garden 'b' with other changes"):
        changed_gardens(garden, runs, 0)


def test_garden_changes_preset_records_what_changed(tmp_path, capsys):
    out = tmp_path / "gc"
    code, text, err = run(capsys, "simulate", "--preset", "garden-changes", "--out", str(out), "--max-frames", "2",
                          "--size", "60x8", "--no-progress")
    assert code == 0, err
    assert "wrote 6 images" in text
    ds = Dataset(out)
    md = ds.metadata
    assert set(ds.runs) == {"A", "B", "test"}
    assert "garden" not in md["runs"]["A"] and md["runs"]["B"]["garden"] == md["runs"]["test"]["garden"] == "after"
    g = md["gardens"]["after"]
    assert g["world"] == "world-after.json" and g["changes"] == GARDEN_CHANGES.to_dict()
    counts = {c: sum(r["change"] == c for r in g["objects"]) for c in ("moved", "removed", "added")}
    assert counts == {"moved": 4, "removed": 3, "added": 5}
    before, after = World.load(out / "world.json"), World.load(out / g["world"])
    # run A's world is thesis-6.2.1-static's, at the same seed
    same = sim.recording.preset_world("thesis-6.2.1-static", 0)
    assert json.loads(json.dumps(same.to_dict())) == json.loads(json.dumps(before.to_dict()))
    assert sorted(o.kind for o in after.objects if o.kind not in {p.kind for p in before.objects}) == \
           ["car", "furniture", "parasol", "trailer"]
    # the same pose in run A's and in run B's garden: the changed objects differ, the rest does not
    ra, rb = Renderer(before), Renderer(after)
    pose = tuple(ds.select(run="B").poses[0])
    a, b = ra.render(CAM, pose), rb.render(CAM, pose)
    differ = (a != b).any(axis=(0, 2))
    assert 0 < differ.mean() < 0.6
    # the dataset's images are those renders (run A in the unchanged garden, the test walk in the changed one)
    cam = PanoramicCamera(60, 8)
    for name, r in (("A", ra), ("test", rb)):
        sel = ds.select(run=name)
        np.testing.assert_array_equal(sel.image(0), r.render(cam, tuple(sel.poses[0])))
    # deterministic from the seed: the gardens the runs see
    runs = sim.presets.get("garden-changes").runs(np.random.default_rng(0))
    again = changed_gardens(sim.recording.preset_world("garden-changes", 0), runs, 0)["after"]
    assert again[1] == g["objects"]
    other = changed_gardens(sim.recording.preset_world("garden-changes", 1), runs, 1)["after"]
    assert other[1] != g["objects"]
