"""Seasons in the simulator: Season validation and JSON, how a season
recolours and thins the garden, the seasons preset, and the pose jitter of
the long-term loop presets."""

import numpy as np
import pytest

from sfanav import sim
from sfanav.sim import SEASONS, Lighting, PanoramicCamera, Primitive, Renderer, Season, Texture, World, WorldObject

CAM = PanoramicCamera(60, 8)


def garden():
    """A deciduous tree due east, a bush due north, a conifer due west of the
    origin (flat-coloured leaves), on the default lawn."""
    tex = {"bark": Texture("bark", (0.36, 0.27, 0.18), 0.0, 1),
           "leaves": Texture("leaves", (0.22, 0.40, 0.13), 0.0, 2),
           "bushleaves": Texture("leaves", (0.20, 0.36, 0.12), 0.0, 3),
           "needles": Texture("leaves", (0.10, 0.26, 0.12), 0.0, 4)}
    objs = [WorldObject("tree", 5.0, 0.0, 2.0, [Primitive("cylinder", 5.0, 0.0, 0.0, 2.5, "bark", radius=0.2),
                                                Primitive("ellipsoid", 5.0, 0.0, 0.3, 4.0, "leaves", radius=2.0)]),
            WorldObject("bush", 0.0, 4.0, 1.2, [Primitive("ellipsoid", 0.0, 4.0, -0.5, 1.5, "bushleaves",
                                                          radius=1.2)]),
            WorldObject("conifer", -5.0, 0.0, 1.5, [Primitive("ellipsoid", -5.0, 0.0, 0.2, 5.0, "needles",
                                                              radius=1.5)])]
    return World((4.0, 4.0), 3.0, 12.0, objs, tex)


@pytest.fixture(scope="module")
def renderer():
    return Renderer(garden())


def columns(bearing_deg, half=3, width=60):
    """Column indices of a 60-wide panorama within ``half`` columns of a bearing."""
    c = int(np.floor(PanoramicCamera(width, 8).column_of_bearing(np.radians(bearing_deg)) + 0.5))
    return np.arange(c - half, c + half + 1) % width


def greenness(px):
    px = px.reshape(-1, 3).astype(float)
    return float((px[:, 1] / np.maximum(px.sum(axis=1), 1)).mean())


# ------------------------------------------------------------------ Season


def test_season_validation():
    with pytest.raises(ValueError, match="season ground colour multiplier must be three non-negative numbers"):
        Season(ground=(1.0, -0.1, 1.0))
    with pytest.raises(ValueError, match="season foliage colour multiplier"):
        Season(foliage=(1.0, 1.0))
    with pytest.raises(ValueError, match="season sky colour multiplier"):
        Season(sky=(1.0, float("nan"), 1.0))
    with pytest.raises(ValueError, match=r"leaf_cover must be in \[0, 1\], got 1.5"):
        Season(leaf_cover=1.5)
    with pytest.raises(ValueError, match="leaf_cover"):
        Season(leaf_cover="lots")
    with pytest.raises(ValueError, match="sun_elevation_deg must be \\(low, high\\)"):
        Season(sun_elevation_deg=(40.0, 20.0))
    with pytest.raises(ValueError, match="sun_elevation_deg"):
        Season(sun_elevation_deg=(0.0, 20.0))
    with pytest.raises(ValueError, match="name must be a non-empty string"):
        Season("")
    with pytest.raises(TypeError, match="season must be a Season or None, got dict"):
        Lighting(season={"name": "winter"})
    s = Season(ground=[1, 1, 1], sun_elevation_deg=[10, 20])
    assert s.ground == (1.0, 1.0, 1.0) and s.sun_elevation_deg == (10.0, 20.0)


def test_named_seasons():
    assert list(SEASONS) == ["spring", "summer", "autumn", "winter"]
    assert SEASONS["winter"] == Season.winter() and Season.summer() == Season("summer", sun_elevation_deg=(30, 60))
    win, summ, aut = Season.winter(), Season.summer(), Season.autumn()
    assert win.leaf_cover < aut.leaf_cover < summ.leaf_cover == 1.0
    assert win.sun_elevation_deg[1] < summ.sun_elevation_deg[0] + 1e-9 < summ.sun_elevation_deg[1]
    assert aut.foliage[0] > 1.5 * aut.foliage[1]  # leaves turn orange-brown


def test_season_and_lighting_json_round_trip():
    for season in list(SEASONS.values()) + [Season("custom", (1.1, 0.9, 1.0), leaf_cover=0.3)]:
        assert Season.from_dict(season.to_dict()) == season
        light = Lighting(intensity=0.7, tint=(0.6, 1.0, 1.0), sun_elevation_deg=12.0, season=season)
        d = light.to_dict()
        assert d["season"]["name"] == season.name
        assert Lighting.from_dict(d) == light
    plain = Lighting(sun_azimuth_deg=10.0)
    assert "season" not in plain.to_dict() and Lighting.from_dict(plain.to_dict()) == plain
    with pytest.raises(ValueError, match="unknown season fields \\['snow'\\]"):
        Season.from_dict({**Season.winter().to_dict(), "snow": 1})
    with pytest.raises(ValueError, match="unknown lighting fields"):
        Lighting.from_dict({"brightness": 1})
    with pytest.raises(ValueError, match="from a dict"):
        Season.from_dict(["winter"])


def test_leafy_is_a_fixed_stipple_of_the_leaf_cover():
    rng = np.random.default_rng(0)
    x, y, z = rng.uniform(-20, 20, (3, 20000))
    win = Season.winter()
    a = win.leafy(x, y, z)
    np.testing.assert_array_equal(a, win.leafy(x, y, z))
    assert abs(a.mean() - win.leaf_cover) < 0.02
    assert Season.summer().leafy(x, y, z).all()
    assert not Season(leaf_cover=0.0).leafy(x, y, z).any()


# ------------------------------------------------------------------ rendering


def test_no_season_renders_as_before(renderer):
    pose = (0.3, -0.2, 0.4)
    default = renderer.render(CAM, pose)
    np.testing.assert_array_equal(renderer.render(CAM, pose, lighting=Lighting(season=None)), default)
    # the world's own colours are summer's, and a neutral season changes nothing either
    np.testing.assert_array_equal(renderer.render(CAM, pose, lighting=Lighting(season=Season.summer())), default)
    np.testing.assert_array_equal(renderer.render(CAM, pose, lighting=Lighting(season=Season())), default)


def test_winter_lawn_is_less_green_and_its_sky_paler(renderer):
    cam = PanoramicCamera(60, 12)
    summer = renderer.render(cam, (0, 0, 0), lighting=Lighting(season=Season.summer())).astype(float)
    winter = renderer.render(cam, (0, 0, 0), lighting=Lighting(season=Season.winter())).astype(float)
    ground = cam.grid.elev < np.radians(-10)
    assert greenness(winter[ground][:, columns(-135)]) < greenness(summer[ground][:, columns(-135)]) - 0.02
    sky = cam.grid.elev > np.radians(15)
    blue = lambda img: float((img[sky][..., 2] - img[sky][..., 0]).mean())  # noqa: E731
    assert blue(winter) < blue(summer)


def test_autumn_foliage_turns_orange_and_winter_crowns_go_bare(renderer):
    light = dict(shadows=False, sun_elevation_deg=60.0)
    cam = PanoramicCamera(60, 12, (-5, 25))
    crown_rows = cam.grid.elev > np.radians(15)  # the tree's crown east, above its trunk
    imgs = {n: renderer.render(cam, (0, 0, 0), lighting=Lighting(season=s, **light)).astype(float)
            for n, s in (("summer", Season.summer()), ("autumn", Season.autumn()), ("winter", Season.winter()))}
    crown = {n: img[crown_rows][:, columns(0, 2)].reshape(-1, 3) for n, img in imgs.items()}
    assert (crown["autumn"][:, 0] / crown["autumn"][:, 1]).mean() > 1.5 * (
        crown["summer"][:, 0] / crown["summer"][:, 1]).mean()
    # the bare crown shows the sky behind it: brighter and bluer than the summer's leaves
    assert crown["winter"][:, 2].mean() > crown["summer"][:, 2].mean() + 30
    # the conifer (west) is evergreen: the same in winter, but for the sky between its needles' pixels
    con = columns(180, 1)
    mid = (np.abs(cam.grid.elev - np.radians(5)) < np.radians(3))
    np.testing.assert_allclose(imgs["winter"][mid][:, con], imgs["summer"][mid][:, con], atol=2)


def test_winter_shadows_of_crowns_are_weaker(renderer):
    summer = renderer._shadow_map(Lighting(sun_elevation_deg=30, season=Season.summer()))
    winter = renderer._shadow_map(Lighting(sun_elevation_deg=30, season=Season.winter()))
    assert winter.max() > 0.9  # trunks still cast full shadows
    assert winter.sum() < 0.75 * summer.sum()

# ------------------------------------------------------------------ the seasons preset, pose jitter


@pytest.fixture(scope="module")
def seasons_ds(tmp_path_factory):
    return sim.simulate("thesis-6.2.2-seasons", tmp_path_factory.mktemp("seasons") / "ds", seed=1, max_frames=3,
                        camera=CAM, progress=False)


def test_seasons_preset_records_a_year(seasons_ds):
    ds = seasons_ds
    conds = sorted(set(ds.conditions), key=lambda c: int(c[1:].split("-")[0]))
    assert len(ds) == 30 and ds.image(0).shape == (8, 60, 3)
    assert [c.split("-")[1] for c in conds] == ["spring"] * 3 + ["summer"] * 2 + ["autumn"] * 3 + ["winter"] * 2
    loop = ds.metadata["runs"]["loop"]
    assert loop["jitter"] == {"lateral_m": 0.05, "heading_deg": 2.0}
    for c in conds:
        light = Lighting.from_dict(loop["conditions"][c])
        assert light.season == SEASONS[c.split("-")[1]]
        lo, hi = light.season.sun_elevation_deg
        assert lo <= light.sun_elevation_deg <= hi
    # the same garden as thesis-6.2.2-conditions
    assert ds.metadata["description"].startswith("the 15x15 m garden and 279-frame border-wire loop")
    assert sim.recording.preset_world("thesis-6.2.2-seasons", 1).to_dict() == \
        sim.recording.preset_world("thesis-6.2.2-conditions", 1).to_dict()
    # winter's lawn is less green than summer's
    g = {s: greenness(np.stack([ds.image(i) for i in np.nonzero(np.char.endswith(ds.conditions.astype(str), s))[0]])
                      [:, 5:]) for s in ("summer", "winter")}
    assert g["winter"] < g["summer"]


def test_each_recording_drives_its_own_jittered_loop(seasons_ds):
    ds = seasons_ds
    conds = sorted(set(ds.conditions))
    P = {c: ds.select(condition=c).poses for c in conds}
    # reproducible from the seed: the loop of the trajectory stream, jittered from the jitter stream in order
    _, _, s_traj, _ = sim.recording.random_streams(1)
    world = sim.recording.preset_world("thesis-6.2.2-seasons", 1)
    loop = sim.trajectories.border_loop(world.area, 279, rng=s_traj)
    s_jit = sim.recording.jitter_stream(1)
    for c in ds.metadata["runs"]["loop"]["conditions"]:
        drive = sim.trajectories.jitter(loop, 0.05, 2.0, rng=s_jit)
        np.testing.assert_allclose(P[c], drive.poses[:3], atol=1e-9)
        off = np.hypot(*(P[c][:, :2] - loop.poses[:3, :2]).T)
        assert off.max() <= 0.05 + 1e-9
        # odometry follows the jittered drive (dead reckoning starts at its first pose)
        np.testing.assert_allclose(ds.select(condition=c).odometry[0], P[c][0], atol=1e-9)
    d = [np.hypot(*(P[a][:, :2] - P[b][:, :2]).T).max() for i, a in enumerate(conds) for b in conds[i + 1:]]
    assert 0.01 < max(d) <= 0.1 + 1e-9


def test_jitter_is_smooth_bounded_and_seeded():
    loop = sim.trajectories.border_loop((15.0, 15.0), 279, rng=0)
    drives = [sim.trajectories.jitter(loop, 0.05, 2.0, rng=s) for s in range(4)]
    for dr in drives:
        off = np.hypot(*(dr.poses[:, :2] - loop.poses[:, :2]).T)
        dth = np.degrees(np.abs(sim.wrap_angle(dr.poses[:, 2] - loop.poses[:, 2])))
        assert off.max() == pytest.approx(0.05) and dth.max() == pytest.approx(2.0)
        assert np.abs(np.diff(off)).max() < 0.015  # smooth along the loop: no jumps between frames
        np.testing.assert_array_equal(dr.times, loop.times)
    gaps = [np.hypot(*(a.poses[:, :2] - b.poses[:, :2]).T) for i, a in enumerate(drives) for b in drives[i + 1:]]
    assert all(0.02 < g.max() <= 0.1 + 1e-9 for g in gaps) and max(g.mean() for g in gaps) < 0.06
    np.testing.assert_array_equal(sim.trajectories.jitter(loop, rng=3).poses, drives[3].poses)
    np.testing.assert_array_equal(sim.trajectories.jitter(loop, 0.0, 0.0, rng=3).poses, loop.poses)
    with pytest.raises(ValueError, match="jitter lateral must be a finite number >= 0, got -0.1"):
        sim.trajectories.jitter(loop, -0.1)
    with pytest.raises(ValueError, match="jitter length"):
        sim.trajectories.jitter(loop, length=0)


def test_jitter_is_off_by_default():
    with pytest.raises(ValueError, match="jitter must be \\(lateral m, heading deg\\)"):
        sim.presets.RunSpec("x", lambda w, r: None, jitter=(0.05,))
    assert sim.presets.RunSpec("x", lambda w, r: None).jitter is None
    jittered = {n for n, p in sim.PRESETS.items() if any(r.jitter for r in p.runs(np.random.default_rng(0)))}
    assert jittered == {"thesis-6.2.2-conditions", "thesis-6.2.2-seasons"}
