"""Robustness to a robot camera's corruptions (issue 41): the photometric
normalisation's invariances, the corruption model, the readout fitted on
corrupted copies, the network's invariance partners, the recipe's levels and
the command line."""

import numpy as np
import pytest
from clitools import TINY_TOML, assert_one_line_error, run, tiny_dataset
from hypothesis import given, settings
from hypothesis import strategies as st

import sfanav
from sfanav.data.corruptions import CAMERA, Corruption, CorruptionModel, corrupt
from sfanav.data.photometric import LOG_SCALE, log_contrast, lowpass_log_contrast, normalize
from sfanav.experiments.localization import tiny_config
from sfanav.localization.recipe import DEFAULT_ROBUSTNESS, ROBUSTNESS, recipe_for
from sfanav.localization.training import augmented_features, fit_localizer, invariance_partners


def scene(n=4, h=10, w=48, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.integers(40, 180, (n, h, w, 3)).astype(np.float64)
    return np.clip(base, 0, 255).astype(np.uint8)


# ---------------------------------------------------------------- photometric normalisation
def test_log_contrast_removes_exposure_white_balance_and_gamma():
    x = scene()
    ref = log_contrast(x)
    assert ref.dtype == np.float32 and ref.shape == x.shape
    # every image: zero mean per channel, the fixed contrast
    assert np.allclose(ref.reshape(4, -1, 3).mean(axis=1), 0, atol=1e-3)
    assert np.allclose(ref.reshape(4, -1).std(axis=1), LOG_SCALE, rtol=1e-4)
    for c in (Corruption("exposure", {"gain": 0.6}), Corruption("white-balance", {"gains": (1.15, 1.0, 0.8)}),
              Corruption("gamma", {"gamma": 1.4})):
        d = np.abs(log_contrast(c(x)) - ref).mean()
        raw = np.abs(c(x).astype(float) - x).mean()
        # in units of the normalised image's std (40): a small fraction of it, where the raw change is large
        assert d < 0.06 * LOG_SCALE, (c.kind, d)
        assert raw > 8, c.kind


def test_log_contrast_without_rounding_is_exact_for_a_gain():
    rng = np.random.default_rng(1)
    x = rng.uniform(50, 200, (2, 6, 20, 3))
    gain = np.array([1.3, 0.9, 1.1])
    # exact with a zero offset: log(g I) = log g + log I, and the centring removes log g per channel
    a = log_contrast(x, offset=1e-9)
    b = log_contrast(x * gain, offset=1e-9)
    np.testing.assert_allclose(a, b, atol=1e-3)


def test_log_contrast_flat_and_gray_images():
    flat = np.full((2, 5, 9), 77, np.uint8)
    np.testing.assert_array_equal(log_contrast(flat), 0)
    gray = scene()[..., 0]
    g = log_contrast(gray)
    assert g.shape == gray.shape and abs(float(g[0].mean())) < 1e-3


def test_lowpass_log_contrast_without_lowpass_or_flat_field_is_log_contrast():
    x = scene()
    np.testing.assert_allclose(lowpass_log_contrast(x, sigma=0, flat=False), log_contrast(x), atol=1e-4)
    out = lowpass_log_contrast(x)
    assert out.dtype == np.float32 and out.shape == x.shape
    assert np.allclose(out.reshape(4, -1).std(axis=1), LOG_SCALE, rtol=1e-4)
    # the flat field: every channel's row means have no quadratic profile left over the rows
    t = np.linspace(-1, 1, x.shape[1])
    rows = out.mean(axis=2)  # (N, H, C)
    for k in range(3):
        assert np.abs(np.polynomial.polynomial.polyfit(t, rows[:, :, k].T, 2)).max() < 1e-2  # of a contrast of 40


def test_lowpass_log_contrast_commutes_with_a_rotation_of_the_panorama():
    # the low-pass wraps around the seam: rotating the panorama (rolling its columns) and normalising is
    # normalising and rotating, as the network's simulated rotation needs
    x = scene(w=40)
    for shift in (1, 7, 39):
        np.testing.assert_allclose(lowpass_log_contrast(np.roll(x, shift, axis=2)),
                                   np.roll(lowpass_log_contrast(x), shift, axis=2), atol=1e-2)  # float32 sums


@settings(max_examples=20, deadline=None)
@given(st.floats(0.1, 0.6))
def test_lowpass_log_contrast_removes_vignetting_that_log_contrast_keeps(strength):
    x = scene(n=3, h=16, w=60, seed=2)
    v = Corruption("vignetting", {"strength": strength})
    moved_flat = np.abs(lowpass_log_contrast(v(x)) - lowpass_log_contrast(x)).mean()
    moved_plain = np.abs(lowpass_log_contrast(v(x), flat=False) - lowpass_log_contrast(x, flat=False)).mean()
    assert moved_flat < 0.35 * moved_plain and moved_flat < 0.1 * LOG_SCALE


def test_lowpass_log_contrast_takes_away_fine_structure():
    # JPEG and sensor noise move the low-passed image far less than the plain one (relative to its contrast),
    # on images with structure at every scale (smooth shapes and a fine texture)
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(3)
    smooth = gaussian_filter(rng.normal(size=(3, 16, 60, 3)), (0, 3, 3, 0), mode="wrap")
    x = np.clip(120 + 60 * smooth / smooth.std() + rng.normal(0, 8, smooth.shape), 0, 255).astype(np.uint8)
    for c in ("jpeg-50", "noise-10"):
        lp = np.abs(lowpass_log_contrast(corrupt(x, c, seed=0)) - lowpass_log_contrast(x)).mean()
        plain = np.abs(log_contrast(corrupt(x, c, seed=0)) - log_contrast(x)).mean()
        assert lp < 0.5 * plain, (c, lp, plain)


def test_lowpass_log_contrast_per_axis_widths():
    """(rows, columns) widths: one number is both; each axis is the separable Gaussian's (scipy's, wrapping in
    columns) before the logarithm."""
    from scipy.ndimage import gaussian_filter

    x = scene()
    np.testing.assert_array_equal(lowpass_log_contrast(x, sigma=(1.5, 1.5)), lowpass_log_contrast(x, sigma=1.5))
    rows_only = lowpass_log_contrast(x, sigma=(2.0, 0.0), flat=False)
    blurred = gaussian_filter(x.astype(np.float32), (0, 2.0, 0, 0), mode=("nearest", "nearest", "wrap", "nearest"))
    np.testing.assert_allclose(rows_only, log_contrast(blurred), atol=1e-3)
    assert np.abs(lowpass_log_contrast(x, sigma=(1, 2)) - lowpass_log_contrast(x, sigma=(2, 1))).max() > 1


def test_lowpass_log_contrast_bad_input():
    with pytest.raises(ValueError, match="sigma must be finite"):
        lowpass_log_contrast(scene(), sigma=-1)
    with pytest.raises(ValueError, match="sigma must be finite"):
        lowpass_log_contrast(scene(), sigma=float("nan"))
    for bad in ((1.0, -1.0), (1.0, 2.0, 3.0), "2"):
        with pytest.raises(ValueError, match="sigma must be finite"):
            lowpass_log_contrast(scene(), sigma=bad)
    with pytest.raises(ValueError, match="offset and scale"):
        lowpass_log_contrast(scene(), scale=0)
    np.testing.assert_array_equal(normalize(scene(), "lowpass-log-contrast"), lowpass_log_contrast(scene()))


def test_normalize_dispatch_and_bad_input():
    x = scene()
    assert normalize(x, None) is x
    np.testing.assert_array_equal(normalize(x, "log-contrast"), log_contrast(x))
    with pytest.raises(ValueError, match="photometric normalisation must be one of"):
        normalize(x, "histogram")
    with pytest.raises(ValueError, match="offset and scale"):
        log_contrast(x, offset=0)


@settings(max_examples=20, deadline=None)
@given(gain=st.floats(0.3, 0.8), seed=st.integers(0, 1000))
def test_log_contrast_of_a_darker_image_property(gain, seed):
    x = scene(n=1, seed=seed)
    y = np.rint(x * gain).astype(np.uint8)  # no clipping below 1
    assert np.abs(log_contrast(y) - log_contrast(x)).mean() < 0.1 * LOG_SCALE


# ---------------------------------------------------------------- the corruption model
def test_corruption_model_is_deterministic_per_image():
    x = scene(n=6)
    a = CAMERA.apply(x, seed=3)
    np.testing.assert_array_equal(a[2:], CAMERA.apply(x[2:], seed=3, start=2))
    assert [c.describe() for c in CAMERA.draw(3, seed=3)] == [c.describe() for c in CAMERA.draw(3, seed=3)]
    assert [c.describe() for c in CAMERA.draw(8, seed=3)] != [c.describe() for c in CAMERA.draw(8, seed=4)]
    kinds = {c.kind for c in CAMERA.draw(400, seed=0)}
    assert kinds == {"jpeg", "gaussian-noise", "defocus", "motion-blur", "defects", "exposure", "vignetting"}
    qualities = [c.param("quality") for c in CAMERA.draw(400, seed=0) if c.kind == "jpeg"]
    assert all(isinstance(q, int) and 30 <= q <= 95 for q in qualities)


def test_corruption_model_bad_input():
    with pytest.raises(ValueError, match="at least one family"):
        CorruptionModel({})
    with pytest.raises(ValueError, match="needs a kind"):
        CorruptionModel({"a": {"quality": (1, 2)}})
    with pytest.raises(ValueError, match="quality"):
        CorruptionModel({"a": {"kind": "jpeg", "quality": (0, 200)}})
    with pytest.raises(TypeError, match="uint8"):
        CAMERA.apply(np.zeros((1, 4, 8, 3), np.float32))
    gray = CorruptionModel({"wb": {"kind": "white-balance", "gains": (0.8, 1.2)}}).apply(scene()[..., 0])
    np.testing.assert_array_equal(gray, scene()[..., 0])  # no white balance on gray images


# ---------------------------------------------------------------- training
@pytest.fixture(scope="module")
def run_images():
    rng = np.random.default_rng(0)
    # a smooth synthetic run: panoramas whose pattern moves with the position
    n = 40
    xy = np.c_[np.linspace(0, 3, n), np.sin(np.linspace(0, 3, n))]
    cols = np.arange(48)
    imgs = np.empty((n, 8, 48, 3), np.uint8)
    for i, (x, y) in enumerate(xy):
        for r in range(8):
            v = 120 + 60 * np.sin(2 * np.pi * cols / 48 * (1 + r % 3) + x) + 30 * np.cos(2 * np.pi * cols / 24 + y * r)
            imgs[i, r] = np.clip(v[:, None] + rng.normal(0, 2, (48, 3)), 0, 255).astype(np.uint8)
    return imgs, xy


def _net():
    return sfanav.Network(tiny_config(48, 8, 3, out=6))


def test_fit_localizer_robustness_light_and_full(run_images):
    imgs, xy = run_images
    light = fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False,
                          **recipe_for(robustness="light").fit_kwargs() | {"rows": None})
    assert light.photometric == "lowpass-log-contrast" and light.n_augmented_ == len(imgs)
    assert light.training_positions_.shape == (len(imgs), 2)  # the originals, not the copies
    assert "readout_augmentation" in light.info and "invariance" not in light.info
    full = fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False,
                         **recipe_for(robustness="full").fit_kwargs() | {"rows": None})
    assert full.network.n_partners_ == len(imgs) and full.network.n_loop_closures_ == 0
    assert full.info["invariance_weight"] == 1.0
    # the photometric normalisation: an exposure change moves the estimates little
    dark = corrupt(imgs, "exposure-0.6")
    for loc in (light, full):
        shift = np.abs(loc.predict(dark) - loc.predict(imgs)).mean()
        assert shift < 0.2, shift


@pytest.mark.parametrize("kind", ["log-contrast", "lowpass-log-contrast"])
def test_photometric_localizer_round_trip(run_images, tmp_path, kind):
    imgs, xy = run_images
    loc = fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False, photometric=kind,
                        signature="fourier")
    loc.save(tmp_path / "m.sfa")
    back = sfanav.load(tmp_path / "m.sfa")
    assert back.photometric == kind
    np.testing.assert_allclose(back.predict(imgs[:5]), loc.predict(imgs[:5]))
    from sfanav.sfa.modelfile import read_model

    assert read_model(tmp_path / "m.sfa")[2]["version"] == 6
    # the network saw the normalised images: features are the network's outputs on them
    np.testing.assert_allclose(loc.features(imgs[:3]), loc.transform_rows(normalize(imgs[:3], kind)))
    # a sibling sees images as the localizer does
    sib = loc.sibling(readout={"kind": "knn", "n_outputs": 4, "k": 2}, signature=None)
    assert sib.photometric == kind and sib.network is loc.network and not sib.is_fitted_


def test_lowpass_for_keeps_the_angle_of_the_rows():
    from sfanav.data.photometric import LOWPASS_ROW_DEGREES, LOWPASS_SIGMA, lowpass_for

    assert lowpass_for((-30, 20), 40) == (LOWPASS_SIGMA, LOWPASS_SIGMA)  # the default camera: as before
    rows, cols = lowpass_for((-55, 20), 40)
    assert cols == LOWPASS_SIGMA and rows * 75 / 40 == pytest.approx(LOWPASS_SIGMA * LOWPASS_ROW_DEGREES)
    assert lowpass_for((-30, 20), 80)[0] == pytest.approx(2 * LOWPASS_SIGMA)  # twice the rows: twice the pixels
    # the recipe decides it with the rest of fit_localizer's arguments, given the panoramas' height
    assert recipe_for().fit_kwargs((-55, 20), 40)["lowpass"] == lowpass_for((-55, 20), 40)
    assert "lowpass" not in recipe_for().fit_kwargs((-55, 20))
    assert "lowpass" not in recipe_for(robustness="none").fit_kwargs((-55, 20), 40)
    for elevation, height in (((20, -30), 40), ((0, float("nan")), 40), ((-30, 20), 0)):
        with pytest.raises(ValueError, match="elevation_deg|height"):
            lowpass_for(elevation, height)


def test_lowpass_widths_are_stored_and_refused_without_their_normalisation(run_images, tmp_path):
    from sfanav.sfa.modelfile import read_model

    imgs, xy = run_images
    loc = fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False,
                        photometric="lowpass-log-contrast", lowpass=(1.0, 2.0))
    assert loc.photometric_lowpass() == (1.0, 2.0) and loc.info["lowpass"] == [1.0, 2.0]
    np.testing.assert_array_equal(loc.normalized(imgs[:2]), lowpass_log_contrast(imgs[:2], sigma=(1.0, 2.0)))
    loc.save(tmp_path / "m.sfa")
    assert read_model(tmp_path / "m.sfa")[2]["version"] == 8  # older readers would normalise with 2 px
    back = sfanav.load(tmp_path / "m.sfa")
    assert back.photometric_lowpass() == (1.0, 2.0) and back.sibling().photometric_lowpass() == (1.0, 2.0)
    np.testing.assert_allclose(back.predict(imgs[:5]), loc.predict(imgs[:5]))
    # the default's widths are written as before (no format 8)
    two = fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False,
                        photometric="lowpass-log-contrast", lowpass=(2.0, 2.0))
    assert two.photometric_lowpass() is None and "lowpass" not in two.info
    two.save(tmp_path / "two.sfa")
    assert read_model(tmp_path / "two.sfa")[2]["version"] == 6
    for kw, match in (({"photometric": "log-contrast", "lowpass": 1.0}, "lowpass needs"),
                      ({"photometric": "lowpass-log-contrast", "lowpass": (1.0, -1.0)}, "sigma must be finite")):
        with pytest.raises(ValueError, match=match):
            fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False, **kw)


def test_the_recipe_scales_the_rows_low_pass_to_the_elevation_span(run_images):
    from sfanav.pipeline import train_localizer

    imgs, xy = run_images
    kw = dict(xy=xy, network=_net(), rotation=sfanav.Rotation(4), filter_noise=False, feedback="none",
              recipe=recipe_for(rows="all", signature=None))
    wide = train_localizer(imgs, camera_elevation=(-55.0, 20.0), **kw)
    rows = wide.photometric_lowpass()[0]
    assert rows == pytest.approx(2.0 * 1.25 / (75.0 / imgs.shape[1]))
    kw["network"] = _net()
    same = train_localizer(imgs, camera_elevation=(-30.0, -30.0 + 1.25 * imgs.shape[1]), **kw)  # 1.25 deg a row
    assert same.photometric_lowpass() is None


def test_fit_features_augmented_checks(run_images):
    imgs, xy = run_images
    loc = fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False)
    F = loc.features(imgs)
    sib = loc.sibling()
    with pytest.raises(ValueError, match="shape of the features"):
        sib.fit_features(F, xy, augmented=(F[:5], None))
    with pytest.raises(TypeError, match="tuple"):
        sib.fit_features(F, xy, augmented=F)
    with pytest.raises(ValueError, match="for both"):
        sib.fit_features(F, xy, augmented=(F, np.zeros((len(F), 3))))
    sib.fit_features(F, xy, augmented=(F + 0.01, None))
    assert sib.training_positions_.shape == (len(F), 2)


def test_robustness_needs_8_bit_images(run_images):
    imgs, xy = run_images
    with pytest.raises(ValueError, match="8-bit"):
        fit_localizer(_net(), imgs.astype(np.float32), xy, rotation=sfanav.Rotation(4), progress=False,
                      readout_augmentation=CAMERA)
    with pytest.raises(TypeError, match="CorruptionModel"):
        fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False, invariance="jpeg")


def test_invariance_partners_combine_loop_closures(run_images):
    imgs, _ = run_images
    ident = CorruptionModel({"none": {"kind": "gamma", "gamma": 1.0}})  # a corruption that changes nothing
    cur, w, partners = invariance_partners(imgs, ident, lambda a: a, weight=0.5,
                                           loop_closures=(np.array([1]), np.array([30]), np.array([4])))
    np.testing.assert_array_equal(cur, np.arange(len(imgs)))
    assert w[30] == 0.5 and w[0] == 0.5
    np.testing.assert_array_equal(partners[30], np.roll(imgs[1], 4, axis=1))  # the aligned earlier visit
    np.testing.assert_array_equal(partners[0], imgs[0])  # itself, "corrupted"
    with pytest.raises(ValueError, match="invariance_weight"):
        invariance_partners(imgs, ident, lambda a: a, weight=2.0)


def test_partners_equal_loop_closures_with_the_same_images(run_images):
    imgs, _ = run_images
    closures = (np.array([2, 5]), np.array([30, 35]), np.array([7, 0]))
    a = _net().fit(imgs, sfanav.Rotation(4), progress=False, loop_closures=closures)
    from sfanav.loopclosure.partners import closure_partners

    cur, w, P = closure_partners(imgs, closures)
    b = _net().fit(imgs, sfanav.Rotation(4), progress=False, partners=(np.array(cur), np.array(w), P))
    np.testing.assert_array_equal(a.transform(imgs), b.transform(imgs))
    assert b.n_partners_ == 2 and b.n_loop_closures_ == 0


@pytest.mark.parametrize("partners, match", [
    ((np.array([0, 0]), np.ones(2), None), "more than one partner"),
    ((np.array([0, 99]), np.ones(2), None), "index the 40 training images"),
    ((np.array([0, 1]), np.array([1.0, 2.0]), None), "weights"),
    ((np.array([0.5, 1]), np.ones(2), None), "integers"),
    ((np.array([0, 1]), np.ones(2), "small"), "size and dtype"),
])
def test_bad_partners(run_images, partners, match):
    imgs, _ = run_images
    cur, w, P = partners
    P = imgs[:2] if P is None else imgs[:2, :, :10]
    with pytest.raises(ValueError, match=match):
        _net().fit(imgs, sfanav.Rotation(4), progress=False, partners=(cur, w, P))
    with pytest.raises(ValueError, match="cannot be combined"):
        _net().fit(imgs, sfanav.Rotation(4), progress=False, partners=(np.array([0]), np.ones(1), imgs[:1]),
                   loop_closures=(np.array([1]), np.array([30]), np.array([0])))


def test_closures_among_the_invariance_partners_are_counted(run_images):
    """With invariance partners the feedback closures train as partners (the network counts none as loop
    closures); the model's info still says how many closures it trained with."""
    imgs, xy = run_images
    closures = (np.array([1, 2]), np.array([30, 33]), np.array([4, 0]))
    loc = fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False, loop_closures=closures,
                        **recipe_for(robustness="standard").fit_kwargs() | {"rows": None})
    assert loc.network.n_loop_closures_ == 0 and loc.info["loop_closures"] == 2


def test_augmented_features_are_the_fit_draw(run_images):
    imgs, xy = run_images
    loc = fit_localizer(_net(), imgs, xy, rotation=sfanav.Rotation(4), progress=False, readout_augmentation=CAMERA,
                        seed=2)
    F, G = augmented_features(loc, imgs, CAMERA, seed=2)
    assert F.shape == (len(imgs), loc.n_features_in_) and G is None
    # the same draw as the fit's copies: refitting on them reproduces the readout
    again = loc.sibling().fit_features(loc.features(imgs), xy, augmented=(F, G))
    np.testing.assert_allclose(again.predict(imgs[:4]), loc.predict(imgs[:4]), atol=1e-9)


# ---------------------------------------------------------------- recipe and command line
def test_recipe_robustness_levels():
    assert ROBUSTNESS == ("none", "light", "standard", "full") and DEFAULT_ROBUSTNESS == "standard"
    r = recipe_for()
    assert r.name == "sfanav default" and r.robustness == "standard" and r.info()["robustness"] == "standard"
    kw = r.fit_kwargs()
    assert kw["photometric"] == "lowpass-log-contrast" and kw["readout_augmentation"] is CAMERA
    assert kw["invariance"] is CAMERA and kw["invariance_weight"] == 0.25
    light = recipe_for(robustness="light").fit_kwargs()
    assert light["invariance"] is None and light["readout_augmentation"] is CAMERA
    assert recipe_for(robustness="full").fit_kwargs()["invariance_weight"] == 1.0
    assert recipe_for(robustness="none").name == "custom"
    t = recipe_for("thesis-5.1")
    assert t.name == "thesis" and t.robustness == "none" and t.fit_kwargs()["photometric"] is None
    assert recipe_for(config=True).robustness == "none"
    with pytest.raises(ValueError, match="robustness must be one of"):
        recipe_for(robustness="max")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("robust-cli")
    ds, cfg = tiny_dataset(root)
    return {"root": root, "config": cfg}


@pytest.mark.parametrize("level", ["light", "standard"])
def test_train_robustness_from_the_command_line(tiny, tmp_path, capsys, level):
    code, out, err = run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"],
                         "--rows", "all", "--robustness", level, "--out", tmp_path / "m.sfa", "--no-progress")
    assert code == 0, err
    loc = sfanav.load(tmp_path / "m.sfa")
    assert loc.photometric == "lowpass-log-contrast" and loc.info["robustness"] == level
    assert ("invariance" in loc.info) == (level == "standard")
    code, out, err = run(capsys, "localize", tmp_path / "m.sfa", tiny["root"] / "data", "--run", "test",
                         "--out", tmp_path / "t.csv", "--no-progress")
    assert code == 0, err


def test_train_robustness_usage_errors(tiny, tmp_path, capsys):
    base = ["train", "--dataset", tiny["root"] / "data", "--config", tiny["config"], "--out", tmp_path / "m.sfa",
            "--no-progress"]
    code, _, err = run(capsys, *base, "--normalize", "--robustness", "light")
    assert_one_line_error(code, err, "--normalize", "--robustness light")
    code, _, err = run(capsys, *base, "--robustness", "max")
    assert code == 2 and "invalid choice" in err
    assert TINY_TOML  # the config the fixture wrote
