"""Corruptions of a robot's images (sfanav.data.corruptions): every kind
against its definition, determinism, batches, fixed sensor patterns and
bad input."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sfanav.data.corruptions import CORRUPTIONS, KINDS, Corruption, corrupt, defect_pattern, get


def scene(n=3, h=12, w=40, rgb=True, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.integers(20, 236, (n, h, w, 3) if rgb else (n, h, w))
    return base.astype(np.uint8)


@pytest.mark.parametrize("name", list(CORRUPTIONS))
def test_every_corruption_keeps_shape_and_dtype(name):
    x = scene()
    y = corrupt(x, name, seed=1)
    assert y.shape == x.shape and y.dtype == np.uint8
    assert not np.shares_memory(x, y)


@pytest.mark.parametrize("name", [n for n in CORRUPTIONS if n != "white-balance"])
def test_gray_images(name):
    x = scene(rgb=False)
    assert corrupt(x, name).shape == x.shape


def test_white_balance_needs_rgb():
    with pytest.raises(ValueError, match="RGB"):
        corrupt(scene(rgb=False), "white-balance")


@pytest.mark.parametrize("name", ["noise-5", "shot-noise", "jpeg-50", "dead-pixels"])
def test_batches_equal_the_whole_run(name):
    x = scene(n=5)
    whole = corrupt(x, name, seed=4)
    parts = np.concatenate([corrupt(x[:2], name, seed=4), corrupt(x[2:], name, seed=4, start=2)])
    np.testing.assert_array_equal(whole, parts)
    assert not np.array_equal(whole, corrupt(x, name, seed=5)) or name.startswith("jpeg")


def test_jpeg_is_opencv_round_trip_in_rgb_order():
    x = scene(n=1)
    ok, buf = cv2.imencode(".jpg", x[0][..., ::-1].copy(), [cv2.IMWRITE_JPEG_QUALITY, 75])
    ref = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
    np.testing.assert_array_equal(corrupt(x, "jpeg-75")[0], ref)
    # lower quality, larger error
    e = [np.abs(corrupt(x, f"jpeg-{q}").astype(float) - x).mean() for q in (95, 75, 50)]
    assert e[0] < e[1] < e[2]


def test_gaussian_noise_has_its_sigma():
    x = np.full((4, 50, 60, 3), 128, np.uint8)
    d = corrupt(x, "noise-5", seed=0).astype(float) - 128
    assert abs(d.mean()) < 0.1 and 4.8 < d.std() < 5.2


def test_shot_noise_grows_with_the_signal():
    dark, bright = np.full((2, 40, 50), 32, np.uint8), np.full((2, 40, 50), 224, np.uint8)
    sd = corrupt(dark, "shot-noise").astype(float).std()
    sb = corrupt(bright, "shot-noise").astype(float).std()
    # Poisson: sigma = sqrt(v / 255 * 1000) / (1000 / 255) grey levels
    assert sd == pytest.approx(np.sqrt(32 * 255 / 1000), rel=0.1)
    assert sb == pytest.approx(np.sqrt(224 * 255 / 1000), rel=0.1)


def test_exposure_gamma_and_white_balance_are_their_formulas():
    x = scene()
    xf = x.astype(float)
    np.testing.assert_array_equal(corrupt(x, "exposure-1.5"), np.clip(np.rint(xf * 1.5), 0, 255))
    np.testing.assert_array_equal(corrupt(x, "exposure-0.6"), np.clip(np.rint(xf * np.float32(0.6)), 0, 255))
    np.testing.assert_array_equal(corrupt(x, "gamma-0.7"), np.rint(255 * (xf / 255) ** 0.7))
    wb = corrupt(x, "white-balance").astype(float)
    np.testing.assert_allclose(wb, np.clip(np.rint(xf * np.float32([1.15, 1.0, 0.8])), 0, 255), atol=1)


def test_vignetting_darkens_the_outer_ring_most():
    x = np.full((1, 20, 30, 3), 200, np.uint8)
    y = corrupt(x, "vignetting").astype(float)
    rows = y[0, :, :, 0].mean(axis=1)
    assert np.all(np.diff(rows) > 0)  # first row = outermost ring: darkest
    assert rows[0] == pytest.approx(100, abs=1)  # half the light at the edge
    assert np.all(y[0, 3] == y[0, 3, 0])  # the same in every column


def test_blurs_wrap_around_the_panorama_seam():
    x = np.zeros((1, 9, 40), np.uint8)
    x[0, :, 0] = 255
    for name in ("defocus-1", "motion-blur"):
        y = corrupt(x, name)[0].astype(float)
        assert y[4, -1] > 0 and y[4, -1] == pytest.approx(y[4, 1], abs=1)
    # motion blur is horizontal only
    x = np.zeros((1, 9, 40), np.uint8)
    x[0, 4, :] = 255
    y = corrupt(x, "motion-blur")[0]
    assert np.all(y[3] == 0) and np.all(y[4] == 255)


def test_defects_are_the_same_in_every_frame():
    x = scene(n=4, h=30, w=60)
    y = corrupt(x, "dead-pixels", seed=3)
    cols, hot = defect_pattern((30, 60), dead_columns=2, hot_fraction=0.002, seed=3)
    assert len(cols) == 2
    assert np.all(y[:, :, cols] == 0)
    assert np.all(y[:, hot & ~np.isin(np.arange(60), cols)[None, :]] == 255)
    rest = np.ones((30, 60), bool)
    rest[:, cols] = False
    rest &= ~hot
    np.testing.assert_array_equal(y[:, rest], x[:, rest])


def test_no_corruption_at_zero_strength():
    x = scene()
    for c in (Corruption("defocus", {"sigma": 0}), Corruption("motion-blur", {"length": 1}),
              Corruption("gaussian-noise", {"sigma": 0}), Corruption("gamma", {"gamma": 1.0}),
              Corruption("vignetting", {"strength": 0.0})):
        np.testing.assert_array_equal(c(x), x)


@settings(max_examples=25, deadline=None)
@given(kind=st.sampled_from(sorted(KINDS)), seed=st.integers(0, 2**31), h=st.integers(1, 12), w=st.integers(1, 30))
def test_any_suite_corruption_on_any_size(kind, seed, h, w):
    c = next(c for c in CORRUPTIONS.values() if c.kind == kind)
    x = np.random.default_rng(seed).integers(0, 256, (2, h, w, 3), dtype=np.uint8)
    y = c(x, seed=seed)
    assert y.shape == x.shape and y.dtype == np.uint8


@pytest.mark.parametrize("kind, params, match", [
    ("jpeg", {"quality": 0}, "quality"),
    ("jpeg", {"quality": 90.0}, "quality"),
    ("jpeg", {}, "needs quality"),
    ("gaussian-noise", {"sigma": -1}, "sigma"),
    ("gaussian-noise", {"sigma": float("nan")}, "sigma"),
    ("exposure", {"gain": 0}, "gain"),
    ("shot-noise", {"full_well": 0}, "full_well"),
    ("white-balance", {"gains": (1, 2)}, "gains"),
    ("defects", {"hot_fraction": 2.0}, "hot_fraction"),
    ("defocus", {"sigma": 1, "radius": 3}, "takes sigma"),
    ("sepia", {}, "unknown corruption kind"),
])
def test_bad_parameters(kind, params, match):
    with pytest.raises(ValueError, match=match):
        Corruption(kind, params)


def test_bad_input():
    with pytest.raises(ValueError, match="unknown corruption 'jpeg-91'"):
        get("jpeg-91")
    with pytest.raises(TypeError, match="uint8"):
        corrupt(np.zeros((1, 4, 4, 3), np.float32), "noise-2")
    with pytest.raises(ValueError, match="shape"):
        corrupt(np.zeros((4, 4), np.uint8), "noise-2")
    with pytest.raises(ValueError, match="seed"):
        corrupt(scene(), "noise-2", seed=-1)
