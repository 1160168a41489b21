"""Omnidirectional -> panoramic unwarping and mirror estimation."""

import numpy as np
import pytest

from sfanav.data import Mirror, Unwarper, estimate_mirror

CENTER, R_IN, R_OUT, OMNI = (101.3, 88.7), 20.0, 80.0, (210, 180)  # OMNI = (W, H)


def scene(theta, rho, phase=0.0):
    """A smooth scene over azimuth (rad, counter-clockwise with y up) and radius (px)."""
    return (
        0.5
        + 0.25 * np.sin(3 * theta + 0.5 + phase)
        + 0.1 * np.cos(theta - 1.0)
        + 0.15 * np.cos(2 * np.pi * (rho - R_IN) / (R_OUT - R_IN))
    )


def render_omni(center=CENTER, size=OMNI, phase=0.0, blind=0.1):
    """The scene as a donut image, rendered pixel by pixel (independent of sfanav)."""
    W, H = size
    y, x = np.mgrid[0:H, 0:W].astype(float)
    dx, dy = x - center[0], center[1] - y
    rho, theta = np.hypot(dx, dy), np.arctan2(dy, dx)
    img = scene(theta, rho, phase)
    img[rho > R_OUT] = 0.0
    img[rho < R_IN] = blind
    return img


def expected_panorama(size, offset_deg=0.0, clockwise=False, phase=0.0):
    """The scene sampled where the documented convention puts each panorama pixel."""
    w, h = size
    sign = -1.0 if clockwise else 1.0
    theta = np.deg2rad(offset_deg) + sign * 2 * np.pi * np.arange(w) / w
    rho = R_OUT + (R_IN - R_OUT) * (np.arange(h) + 0.5) / h
    return scene(theta[None, :], rho[:, None], phase)


@pytest.mark.parametrize("size", [(350, 40), (120, 30)])
@pytest.mark.parametrize("offset,clockwise", [(0.0, False), (30.0, True), (-75.0, False)])
def test_unwarps_a_synthetic_omni_image_to_its_panorama(size, offset, clockwise):
    omni = np.stack([render_omni(), render_omni(phase=1.0)])
    u = Unwarper(CENTER, R_IN, R_OUT, size, azimuth_offset=offset, clockwise=clockwise)
    pan = u.transform(omni)
    assert pan.shape == (2, size[1], size[0]) and pan.dtype == omni.dtype
    want = np.stack([expected_panorama(size, offset, clockwise), expected_panorama(size, offset, clockwise, 1.0)])
    # rows next to the rim and the blind spot interpolate with the background
    assert np.abs(pan - want)[:, 1:-1].max() < 0.01
    assert np.abs(pan - want).mean() < 0.005
    # the wrong direction is clearly wrong
    other = Unwarper(CENTER, R_IN, R_OUT, size, azimuth_offset=offset, clockwise=not clockwise).transform(omni)
    assert np.abs(other - want).mean() > 0.05


def test_top_inner_flips_rows_and_inverse_transform_round_trips():
    omni = render_omni()[None]
    outer = Unwarper(CENTER, R_IN, R_OUT, (200, 30)).transform(omni)
    inner = Unwarper(CENTER, R_IN, R_OUT, (200, 30), top="inner").transform(omni)
    np.testing.assert_allclose(inner, outer[:, ::-1], atol=1e-6)
    u = Unwarper(CENTER, R_IN, R_OUT, (200, 30))
    pan = expected_panorama((200, 30))[None]
    back = u.transform(u.inverse_transform(pan, OMNI))
    assert np.abs(back - pan)[:, 1:-1].max() < 0.01
    donut = u.inverse_transform(pan, OMNI)[0]
    assert donut[0, 0] == 0 and donut[int(CENTER[1]), int(CENTER[0])] == 0  # outside the ring


def test_channels_dtypes_gray_and_single_images():
    rgb = np.stack([render_omni(), render_omni(phase=0.7), render_omni(phase=2.0)], axis=-1)
    rgb8 = np.round(rgb * 255).astype(np.uint8)[None].repeat(2, axis=0)
    u = Unwarper(CENTER, R_IN, R_OUT, (120, 30))
    col = u.transform(rgb8)
    assert col.shape == (2, 30, 120, 3) and col.dtype == np.uint8
    gray = Unwarper(CENTER, R_IN, R_OUT, (120, 30), gray=True).transform(rgb8)
    assert gray.shape == (2, 30, 120) and gray.dtype == np.uint8
    want = np.clip(np.rint(col.astype(np.float32) @ np.float32([0.299, 0.587, 0.114])), 0, 255)
    np.testing.assert_array_equal(gray, want)
    bgr = Unwarper(CENTER, R_IN, R_OUT, (120, 30), gray=True, channel_order="bgr").transform(rgb8)
    assert np.abs(bgr.astype(int) - gray).max() > 5
    one = u(rgb8[0])
    np.testing.assert_array_equal(one, col[0])
    np.testing.assert_array_equal(u(rgb8[0, ..., 0]), u.transform(rgb8[:1, ..., :1])[0])
    assert u.transform(rgb.astype(np.float32)[None]).dtype == np.float32


def test_normalization():
    omni = np.stack([render_omni(), 3 * render_omni(phase=1.0) + 7])
    pan = Unwarper(CENTER, R_IN, R_OUT, (120, 30), normalize=True).transform(omni)
    assert pan.dtype == np.float32
    np.testing.assert_allclose(pan.reshape(2, -1).mean(1), 0, atol=1e-5)
    np.testing.assert_allclose(pan.reshape(2, -1).std(1), 1, atol=1e-5)
    flat = Unwarper(CENTER, R_IN, R_OUT, (120, 30), normalize=True).transform(np.full((1, 180, 210), 5.0))
    np.testing.assert_array_equal(flat, 0.0)  # a constant panorama is only centred


def test_center_jitter_is_seeded_bounded_and_shifts_the_center():
    omni = np.stack([render_omni(phase=p) for p in (0.0, 0.5, 1.0, 1.5)])
    a = Unwarper(CENTER, R_IN, R_OUT, (120, 30), jitter=5, random_state=3)
    b = Unwarper(CENTER, R_IN, R_OUT, (120, 30), jitter=5, random_state=3)
    twin = Unwarper(CENTER, R_IN, R_OUT, (120, 30), jitter=5, random_state=3)
    offsets = twin.draw_offsets(4)
    assert np.all(np.abs(offsets) <= 5) and np.abs(offsets).max() > 1
    pa, pb = a.transform(omni), b.transform(omni)
    np.testing.assert_array_equal(pa, pb)  # same seed, same offsets
    assert not np.array_equal(a.transform(omni), pa)  # the generator advances
    for i, (dx, dy) in enumerate(offsets):
        shifted = Unwarper((CENTER[0] + dx, CENTER[1] + dy), R_IN, R_OUT, (120, 30)).transform(omni[i : i + 1])
        np.testing.assert_allclose(pa[i], shifted[0], atol=1e-3)  # float32 map rounding
    explicit = Unwarper(CENTER, R_IN, R_OUT, (120, 30)).transform(omni, offsets=offsets)
    np.testing.assert_allclose(explicit, pa, atol=1e-6)
    plain = Unwarper(CENTER, R_IN, R_OUT, (120, 30))
    np.testing.assert_array_equal(plain.transform(omni), plain.transform(omni, offsets=np.zeros((4, 2))))


def test_unwarper_errors():
    omni = render_omni()[None]
    with pytest.raises(ValueError, match="outer_radius .* must be larger"):
        Unwarper(CENTER, 50, 40)
    with pytest.raises(ValueError, match="inner_radius must be a finite number >= 0"):
        Unwarper(CENTER, -1, 40)
    with pytest.raises(ValueError, match="size must be"):
        Unwarper(CENTER, 10, 40, size=(350,))
    with pytest.raises(ValueError, match="center must be"):
        Unwarper((1.0, 2.0, 3.0), 10, 40)
    with pytest.raises(ValueError, match="center contains NaN"):
        Unwarper((np.nan, 2.0), 10, 40)
    with pytest.raises(ValueError, match="top must be"):
        Unwarper(CENTER, 10, 40, top="middle")
    with pytest.raises(ValueError, match="interpolation"):
        Unwarper(CENTER, 10, 40, interpolation="area")
    u = Unwarper(CENTER, R_IN, R_OUT, (120, 30))
    bad = omni.copy()
    bad[0, 5, 5] = np.nan
    with pytest.raises(ValueError, match="image 0 contains NaN"):
        u.transform(bad)
    with pytest.raises(ValueError, match=r"offsets must have shape \(1, 2\)"):
        u.transform(omni, offsets=np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"\(N, H, W\) or \(N, H, W, C\)"):
        u.transform(omni[0, 0])
    with pytest.raises(ValueError, match="gray=True needs 1, 3 or 4 channels"):
        Unwarper(CENTER, R_IN, R_OUT, gray=True).transform(np.zeros((1, 20, 20, 2)))
    with pytest.raises(ValueError, match="panoramas must be 120x30"):
        u.inverse_transform(np.zeros((1, 30, 100)), OMNI)
    with pytest.raises(TypeError, match="real numbers"):
        u.transform(np.zeros((1, 5, 5), dtype=bool))


# ------------------------------------------------------------------ mirror


def textured_omni(n, center, r_in, r_out, size, seed=0, noise=0.0):
    """Donut images of random smooth panoramas (background 0, blind spot 0.1)."""
    import cv2

    rng = np.random.default_rng(seed)
    pans = np.stack([cv2.GaussianBlur(rng.random((30, 200)).astype(np.float32), (0, 0), 1.5) for _ in range(n)])
    pans = 0.2 + 0.8 * (pans - pans.min()) / (pans.max() - pans.min())
    omni = Unwarper(center, r_in, r_out, (200, 30)).inverse_transform(pans, size)
    W, H = size
    y, x = np.mgrid[0:H, 0:W]
    omni[:, np.hypot(x - center[0], y - center[1]) < r_in] = 0.1
    return omni + noise * rng.standard_normal(omni.shape).astype(np.float32)


@pytest.mark.parametrize(
    "center,r_in,r_out,size",
    [((101.3, 88.7), 20, 80, (210, 180)), ((150.0, 120.0), 35, 140, (300, 240)), ((99.5, 60.0), 15, 90, (200, 120))],
)
def test_estimate_mirror_recovers_center_and_radii(center, r_in, r_out, size):
    # the last case's disc is clipped by the top and bottom of the image
    for images in (textured_omni(5, center, r_in, r_out, size), textured_omni(1, center, r_in, r_out, size, noise=0.02)):
        m = estimate_mirror(images)
        assert isinstance(m, Mirror)
        assert np.hypot(m.center[0] - center[0], m.center[1] - center[1]) < 0.5, m
        assert abs(m.inner_radius - r_in) < 0.5, m
        assert abs(m.outer_radius - r_out) < 0.5, m


def test_estimate_mirror_on_uint8_rgb_and_from_images():
    omni = textured_omni(3, CENTER, R_IN, R_OUT, OMNI)
    rgb8 = np.round(np.stack([omni, omni * 0.9, omni * 0.8], axis=-1) * 255).astype(np.uint8)
    m = estimate_mirror(rgb8)
    assert abs(m.outer_radius - R_OUT) < 0.7 and abs(m.inner_radius - R_IN) < 0.7
    u = Unwarper.from_images(rgb8, size=(120, 30), gray=True)
    assert u.transform(rgb8).shape == (3, 30, 120) and u.size == (120, 30)
    assert m.unwarper((64, 16)).map_x.shape == (16, 64)


def test_estimate_mirror_errors():
    with pytest.raises(ValueError, match="uniform"):
        estimate_mirror(np.zeros((2, 50, 50)))
    with pytest.raises(ValueError, match=r"\(N, H, W\)"):
        estimate_mirror(np.zeros((50, 50)))
