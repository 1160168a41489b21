"""The camera's gamma from the stream (sfanav.data.camera_gamma): the log
spread's invariances, the power that undoes a gamma, the causal tracker, the
reference a model stores, the streaming localizer's and the command line's
use of it, and bad input."""

import numpy as np
import pytest
from clitools import assert_one_line_error, run, tiny_dataset
from hypothesis import given, settings
from hypothesis import strategies as st

import sfanav
from sfanav.data.camera_gamma import (MAX_FACTOR, MIN_IMAGES, OFFSET, CameraGamma, apply_gamma, log_spread,
                                      predict_corrected, reference_spread)
from sfanav.data.corruptions import Corruption, corrupt
from sfanav.data.photometric import lowpass_log_contrast


def run_of(n=30, h=12, w=60, seed=0):
    """Panoramas with a sky gradient, a darker ground and texture (values 15..235)."""
    rng = np.random.default_rng(seed)
    rows = np.linspace(1.0, 0.45, h)[:, None, None]
    cols = 0.8 + 0.2 * np.sin(np.linspace(0, 6 * np.pi, w))[None, :, None]
    base = 200 * rows * cols * np.array([0.9, 1.0, 1.1])
    imgs = base[None] * rng.uniform(0.7, 1.15, (n, h, w, 3))
    return np.clip(imgs, 15, 235).round().astype(np.uint8)


def gamma(x, g):
    return Corruption("gamma", {"gamma": g})(x)


# ---------------------------------------------------------------- the spread
@pytest.mark.parametrize("g", [0.7, 1.4])
def test_a_gamma_scales_the_log_spread(g):
    x = run_of()
    ratio = np.median(log_spread(gamma(x, g))) / np.median(log_spread(x))
    assert ratio == pytest.approx(g, rel=0.05)


@pytest.mark.parametrize("c", [Corruption("exposure", {"gain": 0.6}),
                               Corruption("white-balance", {"gains": (1.15, 1.0, 0.8)}),
                               Corruption("vignetting", {"strength": 0.5})])
def test_a_gain_a_white_balance_and_a_vignetting_leave_the_log_spread(c):
    x = run_of()
    ratio = np.median(log_spread(c(x))) / np.median(log_spread(x))
    assert ratio == pytest.approx(1.0, abs=0.04), c.kind


@pytest.mark.parametrize("c", ["defocus-2", "motion-blur", "noise-10", "jpeg-50"])
def test_the_low_pass_keeps_blur_noise_and_jpeg_out_of_the_spread(c):
    x = run_of(n=30, h=20, w=120)
    y = corrupt(x, c, seed=1)
    ratio = lambda lp: np.median(log_spread(y, lowpass=lp)) / np.median(log_spread(x, lowpass=lp))  # noqa: E731
    assert abs(np.log(ratio(2.0))) < 0.1  # well inside the dead zone (0.2)
    assert abs(np.log(ratio(2.0))) < 0.6 * abs(np.log(ratio(0.0)))  # less than half of it without the low-pass
    assert ratio(2.0) == pytest.approx(np.median(log_spread(y)) / np.median(log_spread(x)))  # the default


@settings(max_examples=20, deadline=None)
@given(g=st.one_of(st.floats(0.6, 0.8), st.floats(1.25, 1.6)), seed=st.integers(0, 50))
def test_apply_gamma_undoes_a_gamma_before_the_normalisation_property(g, seed):
    # what the default's normalisation keeps of a gamma shrinks; what is left is the 8-bit rounding of the
    # gamma'd image and the offset before the logarithm (dark pixels), about half at 0.7 and 1.4 on this run.
    # Gammas outside the tracker's dead zone (0.82..1.22) only: nearer 1 the rounding is as large as the gamma's
    # trace (0.8-0.9 of it left at 0.9 and 1.1), and the tracker leaves those images as they are
    x = run_of(n=4, seed=seed)
    y = gamma(x, g)
    ref = lowpass_log_contrast(x)
    before = np.abs(lowpass_log_contrast(y) - ref).mean()
    after = np.abs(lowpass_log_contrast(apply_gamma(y, 1.0 / g)) - ref).mean()
    assert after <= 0.75 * before, (before, after)  # 0.53-0.67 over g in 0.6..0.8, 1.25..1.6 and 26 seeds


def test_apply_gamma_of_one_is_the_images_and_factors_per_image():
    x = run_of(n=3)
    np.testing.assert_array_equal(apply_gamma(x, 1.0), x.astype(np.float32))
    out = apply_gamma(x, [1.0, 0.5, 2.0])
    assert out.dtype == np.float32 and out.shape == x.shape and (out >= 0).all()
    np.testing.assert_array_equal(out[0], x[0])
    # a power about the channels' mean log: the channel means of the log stay, the spread scales
    L = lambda a: np.log(a.astype(np.float64) + OFFSET)  # noqa: E731
    np.testing.assert_allclose(L(out[2]).mean(axis=(0, 1)), L(x[2]).mean(axis=(0, 1)), rtol=1e-5)
    assert log_spread(out[2:], lowpass=0) == pytest.approx(2 * log_spread(x[2:], lowpass=0), rel=1e-4)


# ---------------------------------------------------------------- the tracker
def places(n):
    return np.c_[np.arange(n) * 0.25, np.zeros(n)]


def test_the_tracker_is_causal_and_finds_the_gamma():
    x = run_of(n=60)
    cg = CameraGamma(log_spread(x), places(60))
    y = gamma(x, 1.4)
    out = cg.correct(y[: MIN_IMAGES - 1], places(60)[: MIN_IMAGES - 1])  # not enough images yet: left as they are
    assert np.array_equal(out, y[: MIN_IMAGES - 1]) and cg.factor_ == 1.0
    out = cg.correct(y[MIN_IMAGES - 1:], places(60)[MIN_IMAGES - 1:])
    assert cg.n_images_ == 60 and cg.factor_ == pytest.approx(1 / 1.4, rel=0.05)
    # image by image, the same as the batch
    one = CameraGamma(cg.spreads, cg.positions)
    rows = np.concatenate([one.correct(y[i:i + 1], places(60)[i:i + 1]) for i in range(len(y))])
    np.testing.assert_allclose(rows[MIN_IMAGES - 1:], out, rtol=1e-5)


def test_the_reference_is_the_place_s_so_a_scene_of_other_contrast_is_no_gamma():
    # the training run: half its places low in contrast, half high; a test run that keeps to the high half
    x = run_of(n=60)
    flat = apply_gamma(x[:30], 0.6).round().clip(0, 255).astype(np.uint8)  # the first 30 places: less contrast
    train = np.concatenate([flat, x[30:]])
    cg = CameraGamma(log_spread(train), places(60))
    cg.correct(x[30:], places(60)[30:])
    assert cg.factor_ == 1.0 and abs(cg.log_ratio_) < 0.05
    # against the run's median spread instead (the place ignored), the same walk reads as a gamma
    pooled = CameraGamma(np.full(60, np.median(log_spread(train))), places(60))
    pooled.correct(x[30:], places(60)[30:])
    assert abs(pooled.log_ratio_) > 0.1


def test_a_stream_like_the_training_run_is_left_exactly_as_it_is():
    x = run_of(n=40, seed=1)
    cg = CameraGamma(log_spread(run_of(n=40, seed=2)), places(40))
    assert np.array_equal(cg.correct(x, places(40)), x) and cg.factor_ == 1.0
    assert abs(cg.log_ratio_) < 0.05
    # without the dead zone the few per cent between two runs of one camera apply
    raw = CameraGamma(cg.spreads, cg.positions, dead_zone=0.0)
    raw.correct(x, places(40))
    assert raw.factor_ == pytest.approx(np.exp(raw.log_ratio_)) and raw.factor_ != 1.0


def test_the_window_forgets():
    x = run_of(n=40)
    cg = CameraGamma(log_spread(x), places(40), window=20, min_images=5)
    cg.correct(gamma(x, 1.4), places(40))
    assert cg.factor_ == pytest.approx(1 / 1.4, rel=0.05)
    cg.correct(x[:20], places(40)[:20])  # the camera changed back: the last 20 images are the training run's
    assert cg.factor_ == 1.0


def test_a_flat_or_broken_stream_gives_a_bounded_factor_and_finite_images():
    x = run_of(n=40)
    cg = CameraGamma(log_spread(x), places(40))
    black = np.zeros_like(x)
    out = cg.correct(black, places(40))  # a covered lens: flat images add nothing, the factor stays 1
    assert cg.factor_ == 1.0 and np.array_equal(out, black)
    washed = gamma(x, 0.2)  # far beyond any camera's gamma: clipped to MAX_FACTOR's range
    out = cg.correct(washed, places(40))
    assert cg.factor_ == pytest.approx(MAX_FACTOR) and np.isfinite(out).all()


def test_bad_input():
    x = run_of(n=2)
    ok = {"spreads": [0.5, 0.6], "positions": [[0, 0], [1, 0]]}
    for kw, err in (({"spreads": [0.0, 0.5]}, ValueError), ({"spreads": [np.nan, 0.5]}, ValueError),
                    ({"spreads": []}, ValueError), ({"positions": [[0, 0]]}, ValueError),
                    ({"window": 0}, ValueError), ({"window": 5, "min_images": 6}, ValueError),
                    ({"min_images": 2.5}, TypeError), ({"dead_zone": -0.1}, ValueError)):
        with pytest.raises(err):
            CameraGamma(**{**ok, **kw})
    cg = CameraGamma(**ok)
    with pytest.raises(ValueError):
        cg.correct(x, [[0, 0]])  # one position for two images
    with pytest.raises(ValueError, match="positions contains NaN"):
        cg.correct(x, [[0, 0], [np.nan, 0]])
    with pytest.raises(ValueError, match="finite"):
        log_spread(np.full((1, 4, 6, 3), np.nan))
    with pytest.raises(ValueError, match="gamma factors"):
        apply_gamma(x, 0.0)
    with pytest.raises(ValueError, match="gamma factors"):
        apply_gamma(x, [1.0, np.inf])
    with pytest.raises(ValueError, match="shape"):
        log_spread(np.zeros((4, 6)))
    assert CameraGamma.for_localizer(object()) is None


# ---------------------------------------------------------------- models, stream, command line
@pytest.fixture(scope="module")
def model():
    from sfanav.experiments.localization import tiny_config
    from sfanav.localization.recipe import recipe_for
    from sfanav.localization.training import fit_localizer

    x = run_of(n=40, h=8, w=48, seed=3)
    xy = np.c_[np.linspace(0, 3, 40), np.zeros(40)]
    loc = fit_localizer(sfanav.Network(tiny_config(48, 8, 3, out=6)), x, xy, rotation=sfanav.Rotation(4),
                        progress=False, **recipe_for(robustness="light").fit_kwargs() | {"rows": None})
    return loc, x


def test_a_photometric_model_stores_its_reference_and_keeps_it(model, tmp_path):
    loc, x = model
    ref = loc.info["camera_gamma"]
    assert ref == reference_spread(x, loc.training_positions_)
    loc.save(tmp_path / "m.sfa")
    back = CameraGamma.for_localizer(sfanav.load(tmp_path / "m.sfa"))
    np.testing.assert_allclose(back.spreads, log_spread(x), atol=1e-5)
    np.testing.assert_allclose(back.positions, loc.training_positions_, atol=1e-3)


def test_the_streaming_localizer_corrects_what_it_sees(model):
    from sfanav.odometry.streaming import StreamingLocalizer

    loc, x = model
    y = gamma(np.concatenate([x, x]), 1.4)
    noise = {"distance_noise": 0.05, "heading_noise": 0.05, "measurement_noise": 0.2}
    got = []
    streams = {}
    said = []
    for setting in (None, True, False):  # None: the default, wherever the model holds the reference
        got = streams[setting] = []
        live = StreamingLocalizer(loc, noise, camera_gamma=setting, on_estimate=lambda t, z, got=got: got.append(z),
                                  log=said.append if setting is None else None)
        for k in range(0, len(y), 16):  # in batches, as sfanav localize pushes a recording
            live.push_images(np.arange(k, min(k + 16, len(y))) * 10**8, y[k:k + 16])
        if setting is not False:
            assert live.camera_gamma.factor_ == pytest.approx(1 / 1.4, rel=0.06)
    tracker = CameraGamma.for_localizer(loc)  # the same batches through one tracker
    want = np.concatenate([predict_corrected(loc, tracker, y[k:k + 16]) for k in range(0, len(y), 16)])
    np.testing.assert_allclose(np.array(streams[None]), want, atol=1e-9)
    gamma_lines = [m for m in said if m.startswith("camera gamma:")]
    assert len(gamma_lines) == 1 and "a power of 0.7" in gamma_lines[0], said  # said once, when it started
    np.testing.assert_allclose(np.array(streams[True]), want, atol=1e-9)
    np.testing.assert_allclose(np.array(streams[False]), loc.predict(y), atol=1e-9)
    assert not np.allclose(want, loc.predict(y))  # the correction changed the estimates
    plain = loc.sibling()
    plain.info = {}
    for setting, said in ((True, True), (None, False)):  # asked for explicitly: one line; by default: quietly
        lines = []
        assert StreamingLocalizer(plain, noise, camera_gamma=setting, log=lines.append).camera_gamma is None
        assert any("no camera gamma reference" in m for m in lines) == said


def test_fuse_images_takes_the_gamma_out_by_default(model):
    from sfanav.odometry.fusion import fuse_images

    loc, x = model
    odo = np.c_[np.linspace(0, 3, 40), np.zeros(40), np.zeros(40)]
    noise = {"distance_noise": 0.05, "heading_noise": 0.05, "measurement_noise": 0.2}
    est, _ = fuse_images(loc, x, odo, noise)  # a camera like the training run's: exactly as without
    np.testing.assert_array_equal(est, fuse_images(loc, x, odo, noise, camera_gamma=False)[0])
    y = gamma(x, 1.4)
    est, track = fuse_images(loc, y, odo, noise)
    np.testing.assert_allclose(est, predict_corrected(loc, CameraGamma.for_localizer(loc), y), atol=1e-12)
    assert not np.allclose(est, fuse_images(loc, y, odo, noise, camera_gamma=False)[0])
    assert track.shape == (40, 3) and np.isfinite(track).all()


def test_predict_corrected_with_novelty(model):
    loc, x = model
    xy, nov = predict_corrected(loc, None, x[:6], novelty=True)
    want_xy, want_nov = loc.predict_with_novelty(x[:6])
    np.testing.assert_array_equal(xy, want_xy)
    np.testing.assert_array_equal(nov, want_nov)
    y = gamma(np.concatenate([x, x]), 1.4)
    xy, nov = predict_corrected(loc, CameraGamma.for_localizer(loc), y, novelty=True)
    np.testing.assert_allclose(xy, predict_corrected(loc, CameraGamma.for_localizer(loc), y), atol=1e-12)
    assert nov.shape == (len(y),) and np.isfinite(nov).all()


def test_the_batch_in_which_the_window_fills_takes_its_first_factor():
    x = run_of(n=30, seed=4)
    y = gamma(x, 1.4)
    xy = np.c_[np.arange(30) * 0.25, np.zeros(30)]
    whole = CameraGamma(log_spread(x), xy, min_images=10).factors(y, xy)
    assert np.all(whole[:10] == whole[9]) and whole[9] == pytest.approx(1 / 1.4, rel=0.08)  # one batch: no start at 1
    cg = CameraGamma(log_spread(x), xy, min_images=10)
    parts = [cg.factors(y[k:k + 4], xy[k:k + 4]) for k in range(0, 30, 4)]
    assert np.all(parts[0] == 1.0) and np.all(parts[1] == 1.0)  # 8 images: not yet
    assert parts[2][0] == parts[2][1] != 1.0  # the 10th image's batch (8..11): its first factor from image 8 on
    np.testing.assert_allclose(np.concatenate(parts)[8:], whole[8:], atol=1e-12)  # then the same window


def test_predict_corrected_corrects_the_cameras_own_pixels(model):
    import cv2

    loc, x = model
    big = np.stack([cv2.resize(im, (96, 16), interpolation=cv2.INTER_CUBIC) for im in x])  # the camera's 96x16
    conform = sfanav.data.Preprocessor(sfanav.data.Preprocessing(48, 8, False), log=lambda *a: None)
    g = np.concatenate([gamma(big, 1.4)] * 2)
    X = conform(g)
    after = predict_corrected(loc, CameraGamma.for_localizer(loc), X)  # corrected after the resize
    before = predict_corrected(loc, CameraGamma.for_localizer(loc), X, source=g, conform=conform)
    tracker = CameraGamma.for_localizer(loc)
    f = tracker.factors(X, loc.predict(X))
    want = loc.predict(conform(apply_gamma(g, f)))
    np.testing.assert_allclose(before, want, atol=1e-9)
    assert not np.allclose(before, after)
    with pytest.raises(ValueError, match="go together"):
        predict_corrected(loc, None, X, source=g)
    with pytest.raises(ValueError, match="one source image per image"):
        predict_corrected(loc, None, X, source=g[:3], conform=conform)


def test_keeps_while_the_correction_brings_the_images_nearer_the_training_views():
    cg = CameraGamma(np.ones(5), np.zeros((5, 2)), window=4, min_images=1)
    assert np.isnan(cg.novelty_gain_) and cg.keeps([], [])
    assert cg.keeps([3.0, 3.0, 2.0], [2.0, 2.5, 2.0])  # unchanged images (equal novelty) do not count
    assert cg.novelty_gain_ == 0.75 and cg.n_reverted_ == 0
    assert not cg.keeps([1.0, 1.0, 1.0], [2.0, 3.0, 4.0])  # the window of 4: 0.5, -1, -2, -3 (1.0 dropped)
    assert cg.novelty_gain_ == -1.5 and cg.n_reverted_ == 3
    with pytest.raises(ValueError, match="one value per image"):
        cg.keeps([1.0], [1.0, 2.0])


def test_predict_corrected_without_a_tracker_is_predict(model):
    loc, x = model
    np.testing.assert_array_equal(predict_corrected(loc, None, x[:5]), loc.predict(x[:5]))


def test_localize_camera_gamma_on_the_command_line(tmp_path, capsys):
    root = tmp_path
    ds, cfg = tiny_dataset(root)
    for name, extra in (("none.sfa", ()), ("light.sfa", ("--robustness", "light"))):
        code, _, err = run(capsys, "train", "--dataset", root / "data", "--config", cfg, *extra,
                           "--out", root / name, "--no-progress")
        assert code == 0, err
    code, _, err = run(capsys, "localize", root / "none.sfa", root / "data", "--run", "test", "--camera-gamma",
                       "--out", root / "none.csv", "--no-progress")
    assert_one_line_error(code, err, "--camera-gamma")
    assert not (root / "none.csv").exists()
    code, out, err = run(capsys, "localize", root / "light.sfa", root / "data", "--run", "test", "--camera-gamma",
                         "--out", root / "light.csv", "--no-progress")
    assert code == 0, err
    assert "camera gamma:" in err + out and (root / "light.csv").exists()
    # the default: on wherever the model holds the reference, quietly off where it does not
    code, out, err = run(capsys, "localize", root / "light.sfa", root / "data", "--run", "test",
                         "--out", root / "default.csv", "--no-progress")
    assert code == 0, err
    assert "camera gamma:" in err + out
    # the tiny model cannot place this walk (MED metres): its spread reads as a gamma of about 1.3, but correcting
    # moves the images away from the training views, so they are localized as they came
    assert "localized as they came" in err
    assert (root / "default.csv").read_text() == (root / "light.csv").read_text()
    code, out, err = run(capsys, "localize", root / "light.sfa", root / "data", "--run", "test", "--odometry",
                         "--out", root / "fused.csv", "--no-progress")  # the streaming localizer says it as it goes
    assert code == 0, err
    assert "farther from the training views: images as they come" in err
    code, out, err = run(capsys, "localize", root / "light.sfa", root / "data", "--run", "test", "--no-camera-gamma",
                         "--out", root / "off.csv", "--no-progress")
    assert code == 0, err
    assert "camera gamma:" not in err + out
    assert (root / "off.csv").read_text() == (root / "light.csv").read_text()  # the guard left them as they came
    code, out, err = run(capsys, "localize", root / "none.sfa", root / "data", "--run", "test",
                         "--out", root / "none.csv", "--no-progress")
    assert code == 0, err
    assert "camera gamma" not in err + out and (root / "none.csv").exists()
