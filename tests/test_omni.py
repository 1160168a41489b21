"""Omnidirectional images end to end: uneven ground tilts and bobs the
simulated camera (the horizon ring moves in the image), the centre jitter of
the unwarping on the preprocessing path and in ``sfanav train``."""

import numpy as np
import pytest

import sfanav
from sfanav import sim
from sfanav.app.cli import main
from sfanav.data import Preprocessing, Preprocessor, Unwarper
from sfanav.data.dataset import Dataset
from sfanav.data.sources import load_run
from sfanav.sim import Attitude, UnevenGround
from sfanav.sim.recording import preset_terrain

from clitools import TINY_TOML, assert_one_line_error, run


@pytest.fixture(scope="module")
def renderer():
    return sim.Renderer(sim.World.generate(4, area=(5.0, 7.0), n_objects=20, depth=8.0))


def _best_offset(unwarper, tilted, reference, rows=slice(2, -2)):
    """The unwarping centre offset (dx, dy), on a half-pixel grid, whose
    panorama of ``tilted`` is nearest the ``reference`` panorama."""
    ref = unwarper.transform(reference[None], offsets=np.zeros((1, 2)))[0][rows]
    best = None
    for dx in np.arange(-6.0, 6.5, 0.5):
        for dy in np.arange(-6.0, 6.5, 0.5):
            un = unwarper.transform(tilted[None], offsets=np.array([[dx, dy]]))[0][rows]
            err = float(np.abs(un - ref).mean())
            if best is None or err < best[0]:
                best = (err, dx, dy)
    return best


def test_a_tilt_moves_the_horizon_ring_as_a_centre_offset_does(renderer):
    cam = sim.OmniCamera(200, elevation_deg=(-30.0, 20.0))
    c = (cam.size - 1) / 2
    unwarper = Unwarper((c, c), cam.inner_radius, cam.outer_radius, (200, 20), gray=True)
    px_per_deg = cam.radius_of_elevation(np.radians(0.5)) - cam.radius_of_elevation(np.radians(-0.5))
    pose = (0.3, -0.2, 0.4)
    level = renderer.render(cam, pose).astype(np.float32)
    # nose up: the horizon ahead (up in the image) comes nearer the centre, behind farther: the ring moves down
    err, dx, dy = _best_offset(unwarper, renderer.render(cam, pose, attitude=Attitude(pitch_deg=4.0)).astype(
        np.float32), level)
    assert dx == 0 and dy == pytest.approx(4.0 * px_per_deg, abs=1.0)
    # left side up: the ring moves right
    err, dx, dy = _best_offset(unwarper, renderer.render(cam, pose, attitude=Attitude(roll_deg=4.0)).astype(
        np.float32), level)
    assert dy == 0 and dx == pytest.approx(4.0 * px_per_deg, abs=1.0)
    # a level camera's image stays centred
    err, dx, dy = _best_offset(unwarper, renderer.render(cam, pose, attitude=Attitude(height_m=0.03)).astype(
        np.float32), level)
    assert (dx, dy) == (0, 0)


def test_the_default_attitude_renders_the_old_image(renderer):
    for cam in (sim.OmniCamera(64), sim.PanoramicCamera(80, 10), sim.PanoramicCamera(60, 8, rgb=False)):
        a = renderer.render(cam, (0.5, 1.0, 2.0), 3.0)
        np.testing.assert_array_equal(a, renderer.render(cam, (0.5, 1.0, 2.0), 3.0, attitude=Attitude()))
        up = renderer.render(cam, (0.5, 1.0, 2.0), 3.0, attitude=Attitude(height_m=0.05))
        tilted = renderer.render(cam, (0.5, 1.0, 2.0), 3.0, attitude=Attitude(roll_deg=2.0, pitch_deg=-3.0))
        assert up.shape == tilted.shape == a.shape and up.dtype == np.uint8
        assert not np.array_equal(up, a) and not np.array_equal(tilted, a)


def test_attitudes_and_uneven_ground_refuse_bad_values(renderer):
    with pytest.raises(ValueError, match="roll_deg must be within"):
        Attitude(roll_deg=25.0)
    with pytest.raises(ValueError, match="pitch_deg must be finite"):
        Attitude(pitch_deg=float("nan"))
    with pytest.raises(TypeError, match="height_m must be a number"):
        Attitude(height_m="0.1")
    with pytest.raises(TypeError, match="attitude must be an Attitude"):
        renderer.render(sim.OmniCamera(32), (0, 0, 0), attitude=(1.0, 2.0, 0.0))
    with pytest.raises(ValueError, match="below the ground"):
        renderer.render(sim.OmniCamera(32), (0, 0, 0), attitude=Attitude(height_m=-0.6))
    with pytest.raises(ValueError, match="roughness_m must be a finite number >= 0"):
        UnevenGround(roughness_m=-0.01)
    with pytest.raises(ValueError, match="wheelbase_m must be > 0"):
        UnevenGround(wheelbase_m=0.0)
    with pytest.raises(ValueError, match="unknown uneven-ground fields"):
        UnevenGround.from_dict({"roughness": 0.01})
    assert UnevenGround.from_dict(UnevenGround().to_dict()) == UnevenGround()
    with pytest.raises(ValueError, match="poses must have shape"):
        UnevenGround().field(0).attitude_array([[0.0, 0.0]])


def test_uneven_ground_is_random_by_seed_and_tilts_a_few_degrees():
    a, b = preset_terrain("thesis-5.2.3-outdoor", 0), preset_terrain("thesis-5.2.3-outdoor", 0)
    np.testing.assert_array_equal(a.heights, b.heights)
    assert not np.array_equal(a.heights, preset_terrain("thesis-5.2.3-outdoor", 1).heights)
    assert preset_terrain("demo", 0) is None  # flat
    rng = np.random.default_rng(0)
    poses = np.c_[rng.uniform(-2.5, 2.5, 2000), rng.uniform(-3.5, 3.5, 2000), rng.uniform(-np.pi, np.pi, 2000)]
    att = a.attitude_array(poses)
    assert 0.5 < att[:, 0].std() < 5 and 0.5 < att[:, 1].std() < 5  # roll, pitch (deg)
    assert 0.005 < att[:, 2].std() < 0.05  # height (m)
    # turning on the spot changes the tilt: the wheels stand on other bumps
    turned = a.attitude_array(poses + [0.0, 0.0, np.pi / 2])
    assert np.abs(turned[:, :2] - att[:, :2]).mean() > 0.3


def test_simulating_on_uneven_ground_is_deterministic_and_flat_presets_are_unchanged(tmp_path):
    cam = sim.OmniCamera(48, elevation_deg=(-30.0, 20.0))
    one = sim.simulate("thesis-5.2.3-outdoor", tmp_path / "a", seed=2, max_frames=6, camera=cam, progress=False)
    two = sim.simulate("thesis-5.2.3-outdoor", tmp_path / "b", seed=2, max_frames=6, camera=cam, progress=False)
    np.testing.assert_array_equal(one.load_images(), two.load_images())
    roll = one.column("roll_deg").astype(float)
    assert len(roll) == 12 and roll.std() > 0 and np.isfinite(one.column("camera_dz_m").astype(float)).all()
    assert one.metadata["terrain"] == UnevenGround().to_dict()
    # a frame is the level render of its pose, tilted by its attitude
    world = sim.World.load(tmp_path / "a" / "world.json")
    r = sim.Renderer(world)
    k = 3
    att = Attitude(float(roll[k]), float(one.column("pitch_deg")[k]), float(one.column("camera_dz_m")[k]))
    np.testing.assert_array_equal(one.image(k), r.render(cam, one.poses[k], float(one.timestamps[k]), attitude=att))
    # a flat preset: no attitude columns, every frame the level render of its pose
    flat = sim.simulate("demo", tmp_path / "c", seed=2, max_frames=4, camera=cam, progress=False)
    with pytest.raises((KeyError, ValueError)):
        flat.column("roll_deg")
    assert "terrain" not in flat.metadata
    # the uneven preset driven flat (a control): the same poses, level images
    control = sim.simulate("thesis-5.2.3-outdoor", tmp_path / "d", seed=2, max_frames=6, camera=cam, progress=False,
                           flat=True)
    assert "terrain" not in control.metadata
    np.testing.assert_array_equal(control.poses, one.poses)
    np.testing.assert_array_equal(control.image(k), sim.Renderer(world).render(cam, one.poses[k],
                                                                               float(one.timestamps[k])))
    with pytest.raises(TypeError, match="flat must be a bool"):
        sim.simulate("demo", tmp_path / "e", max_frames=2, camera=cam, progress=False, flat="yes")
    r = sim.Renderer(sim.World.load(tmp_path / "c" / "world.json"))
    for i in range(len(flat)):
        np.testing.assert_array_equal(flat.image(i), r.render(cam, flat.poses[i], float(flat.timestamps[i])))


@pytest.fixture(scope="module")
def omni(tmp_path_factory):
    """A tiny omnidirectional dataset on uneven ground (train and test runs of 30 frames)."""
    root = tmp_path_factory.mktemp("omni")
    sim.simulate("thesis-5.2.3-outdoor", root / "data", seed=1, max_frames=30,
                 camera=sim.OmniCamera(64, elevation_deg=(-30.0, 20.0)), progress=False)
    cfg = root / "tiny.toml"
    cfg.write_text(TINY_TOML)
    return {"root": root, "data": root / "data", "config": cfg}


def test_preprocessor_jitter_is_seeded_and_for_omni_images_only(omni):
    ds = Dataset(omni["data"]).select(run="train")
    imgs = ds.load_images()  # 30 images: load_run's first batch, from which the mirror is estimated
    prep = Preprocessing(60, 8, gray=True, normalize=False)
    plain = Preprocessor(prep, log=lambda m: None)(imgs)
    msgs = []
    a = Preprocessor(prep, jitter=2.0, seed=5, log=msgs.append)(imgs)
    b = Preprocessor(prep, jitter=2.0, seed=5, log=lambda m: None)(imgs)
    c = Preprocessor(prep, jitter=2.0, seed=6, log=lambda m: None)(imgs)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c) and not np.array_equal(a, plain)
    assert a.shape == plain.shape == (30, 8, 60)
    assert "centre jittered by up to +-2 px per image (seed 5)" in msgs[0]
    # the same through load_run; a preprocessor and a jitter at once is refused
    X, xy = load_run(ds, prep, jitter=2.0, seed=5, log=lambda m: None)
    np.testing.assert_array_equal(X, a)  # one batch: the same mirror and offsets
    with pytest.raises(ValueError, match="give the jitter and seed to the Preprocessor"):
        load_run(ds, prep, preprocessor=Preprocessor(prep), jitter=2.0)
    # panoramas pass without jitter, and the log says so
    pano = np.zeros((3, 8, 60, 3), np.uint8)
    msgs = []
    out = Preprocessor(prep, jitter=2.0, log=msgs.append)(pano)
    assert out.shape == (3, 8, 60) and "applies to omnidirectional images only" in msgs[0]


@pytest.mark.parametrize("jitter, seed, error, words", [
    (-1.0, None, ValueError, "jitter must be a finite number >= 0"),
    (float("inf"), None, ValueError, "jitter must be a finite number >= 0"),
    ("5", None, TypeError, "jitter must be a number"),
    (1.0, -3, ValueError, "seed must be a non-negative integer"),
])
def test_preprocessor_refuses_bad_jitter(jitter, seed, error, words):
    with pytest.raises(error, match=words):
        Preprocessor(Preprocessing(60, 8, gray=True), jitter=jitter, seed=seed)


def test_a_jitter_wider_than_the_mirror_ring_is_refused(omni):
    imgs = Dataset(omni["data"]).select(run="train").load_images()[:4]
    with pytest.raises(ValueError, match="not smaller than the mirror ring's width"):
        Preprocessor(Preprocessing(60, 8, gray=True), jitter=40.0)(imgs)


def test_train_with_jitter_on_omni_images(omni, tmp_path, capsys):
    code, out, err = run(capsys, "train", "--dataset", omni["data"], "--config", omni["config"], "--out",
                         tmp_path / "j.sfa", "--jitter", "1.5", "--jitter-seed", "3", "--no-progress")
    assert code == 0, err
    assert "centre jittered by up to +-1.5 px per image (seed 3)" in err
    assert "the network learns from the jittered panoramas, the readout from the unjittered ones" in err
    loc = sfanav.load(tmp_path / "j.sfa")
    assert loc.info["centre_jitter_px"] == 1.5 and loc.info["centre_jitter_seed"] == 3 and len(loc.info["mirror"]) == 4
    # localization unwarps with the model's mirror, without jitter
    code, out, err = run(capsys, "localize", tmp_path / "j.sfa", omni["data"], "--run", "test", "--out",
                         tmp_path / "j.csv", "--no-progress")
    assert code == 0, err
    assert "given mirror" in err and "jittered" not in err
    # same seed, same model; another seed, another model
    code, _, err = run(capsys, "train", "--dataset", omni["data"], "--config", omni["config"], "--out",
                       tmp_path / "k.sfa", "--jitter", "1.5", "--jitter-seed", "3", "--no-progress")
    assert code == 0, err
    test = Dataset(omni["data"]).select(run="test")
    X, _ = load_run(test, Preprocessing(60, 8, gray=False), mirror=loc.info["mirror"], log=lambda m: None)
    np.testing.assert_array_equal(loc.predict(X), sfanav.load(tmp_path / "k.sfa").predict(X))


@pytest.mark.parametrize("args, words", [
    (["--jitter", "-2"], ["--jitter", "expected a finite number >= 0"]),
    (["--jitter", "nan"], ["--jitter", "expected a finite number >= 0"]),
    (["--jitter", "five"], ["--jitter", "expected a number >= 0"]),
    (["--jitter-seed", "2"], ["--jitter-seed needs --jitter"]),
    (["--jitter", "2", "--jitter-seed", "-1"], ["--jitter-seed", "expected an integer >= 0"]),
])
def test_train_refuses_bad_jitter_in_one_line(omni, tmp_path, capsys, args, words):
    code, _, err = run(capsys, "train", "--dataset", omni["data"], "--config", omni["config"], "--out",
                       tmp_path / "bad.sfa", "--no-progress", *args)
    assert_one_line_error(code, err, *words)
    assert not (tmp_path / "bad.sfa").exists()


def test_train_refuses_a_jitter_wider_than_the_ring_in_one_line(omni, tmp_path, capsys):
    # known once the mirror is found in the first images: after the line that says what is trained
    code, _, err = run(capsys, "train", "--dataset", omni["data"], "--config", omni["config"], "--out",
                       tmp_path / "bad.sfa", "--no-progress", "--jitter", "500")
    assert code == 2 and "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("sfanav train: error: centre jitter 500 px is not smaller than the mirror ring's width")
    assert not (tmp_path / "bad.sfa").exists()


def test_jitter_shows_in_train_help(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    out = capsys.readouterr().out
    assert "--jitter PX" in out and "--jitter-seed N" in out


def test_fit_localizer_trains_the_network_on_network_images(omni):
    from sfanav.localization import fit_localizer
    from sfanav.sfa.network import Network, Rotation

    cfg = {"input": {"width": 60, "height": 8, "channels": 1}, "network": {"precision": "double"},
           "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 6}, {"rf": "full", "out": 6}]}
    ds = Dataset(omni["data"]).select(run="train")
    prep = Preprocessing(60, 8, gray=True, normalize=True)
    X, xy = load_run(ds, prep, log=lambda m: None)
    mirror = Preprocessor(prep, log=lambda m: None)
    mirror(ds.load_images())
    Xj, _ = load_run(ds, prep, mirror=mirror.mirror_used, jitter=1.5, seed=0, log=lambda m: None)
    kw = dict(rotation=Rotation(step=5), readout="quadratic", n_outputs=4, progress=False)
    plain = fit_localizer(Network(cfg), X, xy, **kw)
    same = fit_localizer(Network(cfg), X, xy, network_images=X, **kw)
    np.testing.assert_allclose(plain.predict(X), same.predict(X))
    jit = fit_localizer(Network(cfg), X, xy, network_images=Xj, **kw)
    net_only = fit_localizer(Network(cfg), Xj, xy, **kw)  # the same network, readout on the jittered images
    np.testing.assert_allclose(jit.features(X), net_only.features(X), atol=1e-6)
    assert not np.allclose(jit.predict(X), net_only.predict(X))
    with pytest.raises(ValueError, match="network_images must have the shape of images"):
        fit_localizer(Network(cfg), X, xy, network_images=Xj[:-1], **kw)
