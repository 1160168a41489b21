"""Season.texture_seed: the fine structure of leaves and lawn changes with the
season (validation, JSON, offsets), only vegetation is affected, the default
renders as before, and thesis-6.1-seasons uses it while other presets do not."""

from dataclasses import replace

import numpy as np
import pytest
from sfanav import sim
from sfanav.sim import (
    Lighting,
    PanoramicCamera,
    Primitive,
    Renderer,
    Season,
    Texture,
    World,
    WorldObject,
)
from sfanav.sim.world import GroundSpec

CAM = PanoramicCamera(120, 24, (-40, 30))


def garden():
    """Textured leaves: a deciduous tree due east (bark trunk), a conifer due
    west, a stone box due north; a patio on the lawn due south of the origin."""
    tex = {"bark": Texture("bark", (0.36, 0.27, 0.18), 0.8, 1),
           "leaves": Texture("leaves", (0.22, 0.40, 0.13), 0.8, 2, tile=(1.5, 1.5)),
           "needles": Texture("leaves", (0.10, 0.26, 0.12), 0.8, 4, tile=(1.5, 1.5)),
           "stone": Texture("gravel", (0.5, 0.5, 0.48), 0.8, 5, tile=(0.8, 0.8))}
    objs = [WorldObject("tree", 5.0, 0.0, 2.0, [Primitive("cylinder", 5.0, 0.0, 0.0, 2.5, "bark", radius=0.3),
                                                Primitive("ellipsoid", 5.0, 0.0, 1.5, 4.0, "leaves", radius=1.5)]),
            WorldObject("conifer", -5.0, 0.0, 1.5, [Primitive("ellipsoid", -5.0, 0.0, 0.2, 5.0, "needles",
                                                              radius=1.5)]),
            WorldObject("rock", 0.0, 5.0, 1.0, [Primitive("box", 0.0, 5.0, 0.0, 1.5, "stone", length=2.0,
                                                          width=1.0)])]
    ground = GroundSpec(patches=({"kind": "patio", "x": 0.0, "y": -2.5, "length": 3.0, "width": 3.0, "yaw": 0.0,
                                  "tile": 0.5},))
    return World((4.0, 4.0), 3.0, 12.0, objs, tex, ground=ground)


@pytest.fixture(scope="module")
def renderer():
    return Renderer(garden())


def block(img, bearing_deg, half, elev_lo, elev_hi):
    c = int(np.floor(CAM.column_of_bearing(np.radians(bearing_deg)) + 0.5))
    cc = np.arange(c - half, c + half + 1) % img.shape[1]
    rows = (CAM.grid.elev > np.radians(elev_lo)) & (CAM.grid.elev < np.radians(elev_hi))
    return img[rows][:, cc].astype(float)


# ------------------------------------------------------------------ Season


def test_texture_seed_validation():
    for bad in (-1, 1.5, True, "3", [1]):
        with pytest.raises(ValueError, match="texture_seed must be None or an integer >= 0"):
            Season(texture_seed=bad)
    assert Season(texture_seed=np.int64(7)).texture_seed == 7
    assert type(Season(texture_seed=np.int64(7)).texture_seed) is int
    assert Season().texture_seed is None and Season.autumn().texture_seed is None


def test_texture_seed_json_round_trip():
    s = replace(Season.autumn(), texture_seed=3)
    d = s.to_dict()
    assert d["texture_seed"] == 3 and Season.from_dict(d) == s
    assert "texture_seed" not in Season.autumn().to_dict()  # datasets without it store what they stored
    light = Lighting(sun_elevation_deg=20.0, season=s)
    assert Lighting.from_dict(light.to_dict()) == light


def test_texture_offset():
    assert Season().texture_offset("foliage") == (0.0, 0.0) == Season().texture_offset("lawn")
    a, b = Season(texture_seed=1), Season(texture_seed=2)
    assert a.texture_offset("lawn") == Season(texture_seed=1).texture_offset("lawn")  # deterministic
    assert a.texture_offset("lawn") != b.texture_offset("lawn")
    assert a.texture_offset("lawn") != a.texture_offset("foliage")
    for s in (a, b):
        for part in sim.conditions.TEXTURE_PARTS:
            assert all(0 <= v < sim.conditions.TEXTURE_SHIFT_RANGE for v in s.texture_offset(part))
    with pytest.raises(ValueError, match="unknown texture part 'bark'"):
        a.texture_offset("bark")


# ------------------------------------------------------------------ rendering


def render(renderer, season):
    light = Lighting(shadows=False, sun_elevation_deg=60.0, season=season)
    return renderer.render(CAM, (0.0, 0.0, 0.0), lighting=light)


def test_only_vegetation_changes_with_the_texture_seed(renderer):
    # the same colours and light, only the texture seed differs
    one = render(renderer, Season("x", foliage=(1.1, 0.9, 0.8), texture_seed=1))
    two = render(renderer, Season("x", foliage=(1.1, 0.9, 0.8), texture_seed=2))
    crown = (0, 6, 20, 30)  # the deciduous crown, east
    lawn = (45, 6, -40, -25)  # lawn south-east
    assert (block(one, *crown) != block(two, *crown)).any(axis=-1).mean() > 0.3
    assert (block(one, *lawn) != block(two, *lawn)).any(axis=-1).mean() > 0.3
    # the colour statistics stay alike
    for part in (crown, lawn):
        m1, m2 = block(one, *part).mean(axis=(0, 1)), block(two, *part).mean(axis=(0, 1))
        np.testing.assert_allclose(m1, m2, atol=12)
    # the trunk (east, low), the conifer (west), the stone (north), the patio (south) and the sky keep theirs
    for part in ((0, 1, 3, 12), (180, 5, -5, 25), (90, 5, -5, 5), (-90, 8, -25, -17), (135, 10, 25, 30)):
        np.testing.assert_array_equal(block(one, *part), block(two, *part))


def test_no_texture_seed_renders_as_before(renderer):
    s = Season("x", ground=(1.1, 0.9, 1.0), foliage=(1.3, 0.9, 0.8), leaf_cover=0.6)
    base = render(renderer, s)
    np.testing.assert_array_equal(render(renderer, replace(s, texture_seed=None)), base)
    # the plain path: the offsets are zero and the shifted lookups are skipped
    assert s.texture_offset("foliage") == (0.0, 0.0)
    assert not np.array_equal(render(renderer, replace(s, texture_seed=0)), base)


def test_only_the_61_preset_uses_texture_seeds():
    from sfanav.sim.presets import SEASONS_61_TEXTURE_SEEDS, get
    assert sorted(SEASONS_61_TEXTURE_SEEDS.values()) == [1, 2, 3, 4]
    rng = np.random.default_rng(0)
    runs = {r.name: r for r in get("thesis-6.1-seasons").runs(rng)}
    route = runs["route"].conditions
    assert {c: route[c].season.texture_seed for c in route} == SEASONS_61_TEXTURE_SEEDS
    # every other preset keeps plain seasons (its datasets and numbers stay as they were)
    for name, preset in sim.presets.PRESETS.items():
        if name == "thesis-6.1-seasons":
            continue
        for r in preset.runs(np.random.default_rng(0)):
            for light in r.conditions.values():
                for li in ([light] if isinstance(light, Lighting) else [light(s) for s in (0.0, 0.3, 0.6, 1.0)]):
                    assert li.season is None or li.season.texture_seed is None, name
    # the year time-lapse of thesis-6.1-seasons blends plain seasons
    assert runs["year"].conditions["year"](0.6).season.texture_seed is None
