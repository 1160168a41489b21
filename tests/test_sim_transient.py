"""Objects that come and go with the seasons (sim.transient, WorldObject.seasons):
rendering in and out of season, shadows, JSON, generation and validation."""

import json

import numpy as np
import pytest

from sfanav import sim
from sfanav.sim import SEASONS, Lighting, PanoramicCamera, Primitive, Renderer, Season, Texture, World, WorldObject
from sfanav.sim.transient import BORDER, TRANSIENT_KINDS

CAM = PanoramicCamera(90, 16)


def world(with_pool=True, seasons=("summer",)):
    """A red post due west; a blue paddling pool (transient) 3 m due east of the origin."""
    tex = {"post": Texture("noise", (0.8, 0.1, 0.1), 0.0, 0), "pool": Texture("noise", (0.1, 0.3, 0.9), 0.0, 1)}
    objs = [WorldObject("post", -5.0, 0.0, 0.3, [Primitive("cylinder", -5.0, 0.0, 0.0, 2.0, "post", radius=0.3)])]
    if with_pool:
        objs.append(WorldObject("paddling_pool", 3.0, 0.0, 1.0,
                                [Primitive("cylinder", 3.0, 0.0, 0.0, 0.4, "pool", radius=1.0)], True,
                                seasons=seasons))
    return World((4.0, 4.0), 3.0, 12.0, objs, tex)


def east(img, half=3):
    """Pixels of the columns within ``half`` of bearing 0 (east, heading 0) below the horizon."""
    c = int(np.floor(CAM.column_of_bearing(0.0) + 0.5))
    rows = CAM.grid.elev < 0
    return img[rows][:, np.arange(c - half, c + half + 1) % CAM.width].reshape(-1, 3).astype(float)


def test_an_object_is_drawn_in_its_seasons_only():
    r, bare = Renderer(world()), Renderer(world(with_pool=False))
    pose = (0.0, 0.0, 0.0)
    for name, season in SEASONS.items():
        light = Lighting(sun_elevation_deg=40.0, season=season)
        img = r.render(CAM, pose, lighting=light)
        blue = east(img)[:, 2] - east(img)[:, 0]
        if name == "summer":
            assert blue.max() > 100  # the pool, straight ahead
        else:
            assert blue.max() < 60
            # out of season the world renders exactly as one without the object, shadows included
            np.testing.assert_array_equal(img, bare.render(CAM, pose, lighting=light))
    # no season counts as summer
    np.testing.assert_array_equal(r.render(CAM, pose), r.render(CAM, pose, lighting=Lighting(season=SEASONS["summer"])))
    # a season of another name (custom) shows no transient object
    custom = Lighting(season=Season("custom"))
    np.testing.assert_array_equal(r.render(CAM, pose, lighting=custom), bare.render(CAM, pose, lighting=custom))


def test_a_transient_object_casts_its_shadow_in_season_only():
    r = Renderer(world(seasons=("autumn", "winter")))
    sun = dict(sun_azimuth_deg=180.0, sun_elevation_deg=20.0)  # the shadow falls east of the pool
    out = r._shadow_map(Lighting(season=SEASONS["summer"], **sun))
    there = r._shadow_map(Lighting(season=SEASONS["autumn"], **sun))
    assert there.sum() > out.sum() + 10


def test_seasons_json_round_trip_and_old_files_unchanged():
    w = world(seasons=["winter", "spring"])
    assert w.objects[1].seasons == ("spring", "winter")  # the order of the year
    d = w.to_dict()
    assert "seasons" not in d["objects"][0] and d["objects"][1]["seasons"] == ["spring", "winter"]
    back = World.from_dict(json.loads(json.dumps(d)))
    assert back.objects[1].seasons == ("spring", "winter") and back.objects[0].seasons is None
    assert json.dumps(back.to_dict()) == json.dumps(d)
    assert [o.kind for o in w.transient] == ["paddling_pool"]
    assert len(w.primitives(season="winter")) == 2 and len(w.primitives(season="summer")) == 1
    bad = json.loads(json.dumps(d))
    bad["objects"][1]["seasons"] = ["monsoon"]
    with pytest.raises(ValueError, match="unknown season names \\['monsoon'\\]"):
        World.from_dict(bad)


@pytest.mark.parametrize("seasons, match", [
    ([], "non-empty list of season names"),
    ("summer", "non-empty list of season names"),
    (["summer", "sumer"], "unknown season names \\['sumer'\\]"),
    (["summer", "summer"], "names a season twice"),
])
def test_bad_object_seasons(seasons, match):
    with pytest.raises(ValueError, match=match):
        WorldObject("pool", 0.0, 0.0, 1.0, [], seasons=seasons)


def test_generate_transient_objects():
    specs = [{"kind": "snowman", "seasons": ["winter"], "x": 1.0, "y": -1.0, "yaw": 0.0},
             {"kind": "parasol", "seasons": ["summer"]},
             {"kind": "snow_patch", "seasons": ["winter", "spring"]}]
    w = World.generate(3, area=(12.0, 12.0), n_objects=8, transient=specs)
    again = World.generate(3, area=(12.0, 12.0), n_objects=8, transient=specs)
    assert json.dumps(w.to_dict()) == json.dumps(again.to_dict())
    plain = World.generate(3, area=(12.0, 12.0), n_objects=8)
    # their own random stream: the rest of the world is the same
    assert [asdict_(o) for o in w.objects if not o.transient] == [asdict_(o) for o in plain.objects]
    snowman, parasol, patch = w.transient
    assert (snowman.kind, snowman.x, snowman.y, snowman.seasons) == ("snowman", 1.0, -1.0, ("winter",))
    for o in (parasol, patch):  # drawn inside the area, BORDER m plus the radius from its border
        assert max(abs(o.x), abs(o.y)) <= 6.0 - BORDER - o.radius
    # obstacles in every season, but for the flat snow patch
    assert snowman.obstacle and parasol.obstacle and not patch.obstacle
    assert w.collides(1.0, -1.0) and not plain.collides(1.0, -1.0)


def asdict_(o):
    return json.dumps(o.__dict__, default=lambda p: p.__dict__)


def test_every_transient_kind_builds_and_renders():
    specs = [{"kind": k, "seasons": ["summer"], "x": 4.0 * np.cos(a), "y": 4.0 * np.sin(a)}
             for k, a in zip(TRANSIENT_KINDS, np.linspace(0, 2 * np.pi, len(TRANSIENT_KINDS), endpoint=False))]
    w = World.generate(0, area=(12.0, 12.0), n_objects=0, transient=specs)
    assert [o.kind for o in w.objects] == list(TRANSIENT_KINDS)
    r = Renderer(w)
    summer = r.render(CAM, (0.0, 0.0, 0.0), lighting=Lighting(season=SEASONS["summer"]))
    winter = r.render(CAM, (0.0, 0.0, 0.0), lighting=Lighting(season=SEASONS["winter"]))
    below = CAM.grid.elev < 0
    changed = (summer[below].astype(int) - winter[below]).__abs__().sum(axis=-1) > 60
    assert changed.any(axis=0).mean() > 0.3  # the objects stand all around


@pytest.mark.parametrize("spec, match", [
    ({"kind": "bike", "seasons": ["summer"]}, "unknown kind 'bike'"),
    ({"kind": "parasol"}, "non-empty list of season names"),
    ({"kind": "parasol", "seasons": ["june"]}, "unknown season names"),
    ({"kind": "parasol", "seasons": ["summer"], "x": 1.0}, "give both x and y"),
    ({"kind": "parasol", "seasons": ["summer"], "x": float("nan"), "y": 0.0}, "x must be a finite number"),
    ({"kind": "parasol", "seasons": ["summer"], "yaw": "north"}, "yaw must be a finite number"),
    ({"kind": "parasol", "seasons": ["summer"], "colour": "red"}, "unknown keys \\['colour'\\]"),
    ("parasol", "must be a dict"),
])
def test_bad_transient_specs(spec, match):
    with pytest.raises(ValueError, match=match):
        World.generate(0, area=(12.0, 12.0), n_objects=0, transient=[spec])


def test_transient_must_be_a_list_and_fit():
    with pytest.raises(ValueError, match="transient must be a list of dicts"):
        World.generate(0, area=(12.0, 12.0), n_objects=0, transient={"kind": "toys", "seasons": ["summer"]})
    with pytest.raises(ValueError, match="no room for furniture"):
        World.generate(0, area=(5.0, 5.0), n_objects=0, transient=[{"kind": "furniture", "seasons": ["summer"]}])


def test_seasons_preset_has_objects_that_come_and_go():
    w = sim.recording.preset_world("thesis-6.1-seasons", 0)
    by_season = {s: sorted(o.kind for o in w.transient if o.present(s)) for s in SEASONS}
    assert by_season["summer"] == ["furniture", "paddling_pool", "parasol", "toys"]
    assert by_season["winter"] == ["snow_patch", "snow_patch", "snowman", "tarp"]
    assert "wheelbarrow" in by_season["spring"] and "leaf_pile" in by_season["autumn"]
    # clear of the border-wire loop (1 m inside the border, wobbling by about 0.3 m)
    for o in w.transient:
        assert max(abs(o.x), abs(o.y)) + o.radius < 7.5 - 1.5
