"""Relative-pose loop closures (sfanav.loopclosure.relative_pose): the
warping method on small simulated panoramas of known geometry, invariants,
the covariance of uninformative images and bad input."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sfanav import sim
from sfanav.loopclosure.relative_pose import RelativePoses, gradient_offsets, reference_warping, relative_poses

W = 120


def _wrapdeg(a):
    return np.degrees(np.angle(np.exp(1j * np.asarray(a, float))))


@pytest.fixture(scope="module")
def scene():
    """Six pairs of 120x16 gray panoramas 0.4-1.4 m apart at unrelated
    headings in a garden with objects inside, and their true poses."""
    w = sim.World.generate(3, area=(10, 10), n_objects=20, depth=8.0, inner={"tree": 1, "bush": 2, "pole": 2})
    r = sim.Renderer(w)
    cam = sim.PanoramicCamera(W, 16, rgb=False)
    rng = np.random.default_rng(0)
    poses = []
    for d in np.linspace(0.4, 1.4, 6):
        p0 = np.r_[rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)]
        a = rng.uniform(-np.pi, np.pi)
        poses += [p0, np.r_[p0[:2] + d * np.r_[np.cos(a), np.sin(a)], rng.uniform(-np.pi, np.pi)]]
    P = np.array(poses)
    X = np.array([r.render(cam, p) for p in P])
    return X, P, np.arange(0, len(P), 2), np.arange(1, len(P), 2)


def _truth(P, i, j):
    d = P[j, :2] - P[i, :2]
    return np.arctan2(d[:, 1], d[:, 0]) - P[i, 2], P[j, 2] - P[i, 2], np.hypot(d[:, 0], d[:, 1])


def test_heading_and_baseline_direction_match_the_truth(scene):
    X, P, i, j = scene
    rp = relative_poses(X, i, j)
    bearing, dtheta, _ = _truth(P, i, j)
    eh = np.abs(_wrapdeg(rp.dtheta - dtheta))
    eb = np.abs(_wrapdeg(rp.bearing - bearing))
    assert eh.max() < 4.0, eh
    assert np.median(eb) < 15.0 and eb.max() < 45.0, eb
    # the reported sigmas are of the size of the errors (not 100x off)
    z = eb / np.degrees(rp.sigma_bearing)
    assert 0.05 < np.median(z) < 3.0, z
    assert np.all(rp.contrast > 0.3)
    assert np.isnan(rp.dx).all() and np.isinf(rp.covariance[:, 0, 0]).all()  # no distance: position unknown
    assert np.all(np.isfinite(rp.covariance[:, 2, 2]))


def test_offset_and_covariance_with_a_distance_prior(scene):
    X, P, i, j = scene
    _, _, d = _truth(P, i, j)
    rp = relative_poses(X, i, j, distance=d, distance_sigma=0.1)
    np.testing.assert_allclose(np.hypot(rp.dx, rp.dy), d)
    np.testing.assert_allclose(np.arctan2(rp.dy, rp.dx), rp.bearing, atol=1e-12)
    C = rp.covariance
    np.testing.assert_allclose(C, np.swapaxes(C, 1, 2))
    assert np.all(np.linalg.eigvalsh(C) > 0)
    # along the baseline the distance's variance, across it (d sigma_bearing)^2
    u = np.c_[np.cos(rp.bearing), np.sin(rp.bearing)]
    n = np.c_[-u[:, 1], u[:, 0]]
    np.testing.assert_allclose(np.einsum("ki,kij,kj->k", u, C[:, :2, :2], u), 0.01)
    np.testing.assert_allclose(np.einsum("ki,kij,kj->k", n, C[:, :2, :2], n), (d * rp.sigma_bearing) ** 2)
    # the default sigma is a fraction of the distance
    rp2 = relative_poses(X, i[:1], j[:1], distance=2.0)
    assert rp2.sigma_distance[0] == pytest.approx(0.6)


def test_swapping_the_frames_inverts_the_relation(scene):
    X, _, i, j = scene
    a, b = relative_poses(X, i, j), relative_poses(X, j, i)
    np.testing.assert_allclose(_wrapdeg(a.dtheta + b.dtheta), 0, atol=4.0)
    # i seen from j, in j's frame, is the opposite of the baseline turned by -dtheta
    eb = np.abs(_wrapdeg(b.bearing - (a.bearing + np.pi - a.dtheta)))
    assert np.median(eb) < 15.0 and eb.max() < 45.0, eb


@pytest.mark.parametrize("k", [7, -20])
def test_rolling_a_panorama_shifts_the_heading(scene, k):
    X, _, i, j = scene
    base = relative_poses(X, i[:2], j[:2])
    Y = X.copy()
    Y[j[:2]] = np.roll(X[j[:2]], k, axis=2)  # j turned k columns to the left
    rj = relative_poses(Y, i[:2], j[:2])
    np.testing.assert_allclose(_wrapdeg(rj.dtheta - base.dtheta), k * 360 / W, atol=1e-6)
    np.testing.assert_allclose(_wrapdeg(rj.bearing - base.bearing), 0, atol=1e-6)
    Z = X.copy()
    Z[i[:2]] = np.roll(X[i[:2]], k, axis=2)  # i turned: dtheta and the bearing in i's frame decrease
    # exact when the grid of baseline directions steps by whole columns
    base = relative_poses(X, i[:2], j[:2], n_bearings=W)
    ri = relative_poses(Z, i[:2], j[:2], n_bearings=W)
    np.testing.assert_allclose(_wrapdeg(ri.dtheta - base.dtheta), -k * 360 / W, atol=1e-6)
    np.testing.assert_allclose(_wrapdeg(ri.bearing - base.bearing), -k * 360 / W, atol=1e-6)


def test_pure_rotation_analytic():
    rng = np.random.default_rng(2)
    pano = rng.random((1, 3, 72, 3))
    X = np.concatenate([pano, np.roll(pano, -9, axis=2)])  # 45 degrees to the right
    rp = relative_poses(X, [0], [1], distance=0.5)
    assert np.degrees(rp.dtheta[0]) == pytest.approx(-45.0, abs=0.01)


def test_featureless_images_report_that_they_cannot_tell():
    flat = np.full((2, 16, W), 128, np.uint8)
    rp = relative_poses(flat, [0], [1], distance=1.0)
    assert np.isinf(rp.sigma_bearing[0]) and np.isinf(rp.sigma_dtheta[0])
    assert np.isinf(rp.covariance[0, 0, 0]) and not rp.informative()[0]


def test_an_empty_world_is_less_certain_than_a_garden(scene):
    X, P, i, j = scene
    empty = sim.World.generate(3, area=(10, 10), n_objects=0, lawn="uniform", cloud_cover=0.0)
    r = sim.Renderer(empty)
    cam = sim.PanoramicCamera(W, 16, rgb=False)
    E = np.array([r.render(cam, p) for p in P[:4]])
    e = relative_poses(E, [0, 2], [1, 3], distance=1.0)
    g = relative_poses(X, i[:2], j[:2], distance=1.0)
    assert np.all(e.sigma_bearing > 2 * g.sigma_bearing)
    assert np.all(e.covariance[:, 1, 1] + e.covariance[:, 0, 0] > 2 * (g.covariance[:, 1, 1] + g.covariance[:, 0, 0]))
    assert np.all(e.contrast < g.contrast)


def test_gradient_offsets_give_the_distance():
    rng = np.random.default_rng(4)
    G = rng.normal(size=(6, 2))
    pos = rng.uniform(-2, 2, (5, 2))
    F = pos @ G.T + 1e-3 * rng.normal(size=(5, 6))
    off, cov = gradient_offsets(F, [0, 1], [2, 3], G)
    np.testing.assert_allclose(off, pos[[2, 3]] - pos[[0, 1]], atol=0.01)
    assert cov.shape == (2, 2, 2) and np.all(np.linalg.eigvalsh(cov) > 0)
    X = rng.random((5, 4, 48))
    rp = relative_poses(X, [0, 1], [2, 3], features=F, gradient=G)
    np.testing.assert_allclose(rp.distance, np.hypot(*(pos[[2, 3]] - pos[[0, 1]]).T), atol=0.02)
    assert np.all(rp.sigma_distance < 0.02)
    # combined with a loose prior, the features dominate
    rp2 = relative_poses(X, [0, 1], [2, 3], features=F, gradient=G, distance=5.0, distance_sigma=10.0)
    np.testing.assert_allclose(rp2.distance, rp.distance, atol=1e-3)


def test_bad_input():
    X = np.random.default_rng(0).random((3, 4, 32))
    with pytest.raises(ValueError, match="shape"):
        relative_poses(X[0], [0], [1])
    with pytest.raises(ValueError, match="index"):
        relative_poses(X, [0], [3])
    with pytest.raises(TypeError, match="integer"):
        relative_poses(X, [0.0], [1.0])
    with pytest.raises(ValueError, match="must match"):
        relative_poses(X, [0, 1], [2])
    with pytest.raises(ValueError, match="distance"):
        relative_poses(X, [0], [1], distance=-1.0)
    with pytest.raises(ValueError, match="distance_sigma needs"):
        relative_poses(X, [0], [1], distance_sigma=1.0)
    with pytest.raises(ValueError, match="ratios"):
        relative_poses(X, [0], [1], ratios=[0.1, 1.5])
    with pytest.raises(ValueError, match="give both"):
        relative_poses(X, [0], [1], features=np.zeros((3, 4)))
    with pytest.raises(ValueError, match="8 columns"):
        relative_poses(X[:, :, :6], [0], [1])
    with pytest.raises(ValueError, match="NaN"):
        relative_poses(np.full((2, 4, 32), np.nan), [0], [1])
    with pytest.raises(ValueError, match="singular"):
        gradient_offsets(np.zeros((3, 3)), [0], [1], np.ones((3, 2)))
    with pytest.raises(ValueError, match="shape"):
        gradient_offsets(np.zeros((3, 3)), [0], [1], np.ones((4, 2)))


def test_empty_pairs():
    rp = relative_poses(np.random.default_rng(0).random((2, 4, 32)), np.zeros(0, int), np.zeros(0, int))
    assert isinstance(rp, RelativePoses) and len(rp) == 0 and rp.covariance.shape == (0, 3, 3)


def test_heading_agrees_with_the_panorama_compass(scene):
    from sfanav.odometry.pose_graph import relative_headings

    X, _, i, j = scene
    rp = relative_poses(X, i, j)
    compass = relative_headings(X, j, i)  # heading of current (j) minus past (i)
    np.testing.assert_allclose(_wrapdeg(rp.dtheta - compass), 0, atol=4.0)


def test_the_core_scores_match_the_numpy_reference(scene):
    """The Rust core's warping scores (in parallel, in chunks) give the same
    relative poses as the per-pair numpy path, to rounding."""
    images = scene[0]
    n = len(images)
    i = np.arange(0, n - 3)
    j = i + 3
    got = relative_poses(images, i, j)
    want = reference_warping(images, i, j)
    np.testing.assert_allclose(got.dtheta, want[:, 0], atol=1e-9)
    np.testing.assert_allclose(got.bearing, want[:, 1], atol=1e-9)
    np.testing.assert_allclose(got.sigma_dtheta, want[:, 2], rtol=1e-7)
    np.testing.assert_allclose(got.sigma_bearing, want[:, 3], rtol=1e-7)


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 4), st.integers(8, 40), st.integers(1, 6), st.integers(0, 10_000))
def test_warp_scores_property(rows, width, n_shifts, seed):
    """sfanav._core.warp_scores equals the numpy reference for any images,
    warped columns and (possibly negative, fractional) shifts."""
    from sfanav import _core
    from sfanav.loopclosure.relative_pose import _scores_reference

    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(2, 2, rows, width))
    cols = rng.uniform(0, width, size=(3, 2, width))
    shifts = rng.uniform(-2 * width, 2 * width, size=(2, n_shifts))
    got = _core.warp_scores(a, b, cols.reshape(6, width), shifts).reshape(2, 3, 2, n_shifts)
    for p in range(2):
        np.testing.assert_allclose(got[p], _scores_reference(a[p], b[p], cols, shifts[p]), rtol=1e-10, atol=1e-10)


def test_warp_scores_bad_input():
    from sfanav import _core

    a = np.zeros((2, 3, 16))
    with pytest.raises(ValueError, match="must match"):
        _core.warp_scores(a, a[:1], np.zeros((1, 16)), np.zeros((2, 1)))
    with pytest.raises(ValueError, match="columns"):
        _core.warp_scores(a, a, np.zeros((1, 15)), np.zeros((2, 1)))
    with pytest.raises(ValueError, match="shifts"):
        _core.warp_scores(a, a, np.zeros((1, 16)), np.zeros((3, 1)))
    with pytest.raises(ValueError, match="NaN"):
        _core.warp_scores(a, a, np.full((1, 16), np.nan), np.zeros((2, 1)))


def _landmark_panorama(L, amp, pose, W=180, width=1.2):
    """Gray panorama (K, W) of point landmarks ``L`` (n, 2), each a Gaussian
    bump ``width`` columns wide with per-row amplitudes ``amp`` (n, K), seen
    from ``pose`` (x, y, heading); columns as :func:`relative_poses` reads them."""
    d = L - pose[:2]
    b = np.arctan2(d[:, 1], d[:, 0]) - pose[2]
    c = (W / 2 - 0.5 - b * W / (2 * np.pi)) % W
    dc = (np.arange(W)[None, :] - c[:, None] + W / 2) % W - W / 2
    return amp.T @ np.exp(-0.5 * (dc / width) ** 2)


def test_min_warping_is_not_pulled_by_landmarks_at_unequal_distances():
    """Landmarks 1.5-3 m away on one side and 20-40 m on the other: the one
    distance per hypothesis of the warping errs by degrees in the heading and
    by tens of degrees in the baseline direction; min-warping (a distance per
    column) stays within about a degree and a few degrees."""
    errs = {"warping": [], "min-warping": []}
    for seed in range(6):
        rng = np.random.default_rng(seed)
        b = rng.uniform(-np.pi, np.pi, 60)
        r = np.where(b > 0, rng.uniform(1.5, 3.0, 60), rng.uniform(20, 40, 60))
        L, amp = np.c_[r * np.cos(b), r * np.sin(b)], rng.uniform(0.2, 1.0, (60, 4))
        a = rng.uniform(-np.pi, np.pi)
        p0, p1 = np.r_[0.0, 0.0, 0.3], np.r_[0.5 * np.cos(a), 0.5 * np.sin(a), 0.3 + rng.uniform(-0.3, 0.3)]
        X = np.stack([_landmark_panorama(L, amp, p0), _landmark_panorama(L, amp, p1)])
        for method, e in errs.items():
            rp = relative_poses(X, [0], [1], method=method)
            e.append((abs(_wrapdeg(rp.dtheta[0] - (p1[2] - p0[2]))), abs(_wrapdeg(rp.bearing[0] - (a - p0[2])))))
    w, m = np.median(errs["warping"], axis=0), np.median(errs["min-warping"], axis=0)
    assert m[0] < 1.0 and m[0] < 0.5 * w[0], (w, m)
    assert m[1] < 10.0 and m[1] < 0.5 * w[1], (w, m)


def test_min_warping_on_the_garden_and_its_reference(scene):
    X, P, i, j = scene
    rp = relative_poses(X, i, j, method="min-warping")
    bearing, dtheta, _ = _truth(P, i, j)
    assert np.abs(_wrapdeg(rp.dtheta - dtheta)).max() < 4.0
    assert np.median(np.abs(_wrapdeg(rp.bearing - bearing))) < 15.0
    want = reference_warping(X, i, j, method="min-warping")
    np.testing.assert_allclose(rp.dtheta, want[:, 0], atol=1e-9)
    np.testing.assert_allclose(rp.bearing, want[:, 1], atol=1e-9)
    np.testing.assert_allclose(rp.sigma_bearing, want[:, 3], rtol=1e-7)
    with pytest.raises(ValueError, match="method"):
        relative_poses(X, i, j, method="minwarp")
    with pytest.raises(ValueError, match="method"):
        reference_warping(X, i, j, method="minwarp")


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 4), st.integers(8, 40), st.integers(1, 6), st.integers(1, 3), st.integers(0, 10_000))
def test_min_warp_scores_property(rows, width, n_shifts, n_ratios, seed):
    """sfanav._core.warp_scores with group = the ratios per direction equals
    the numpy reference's min-warping, and is never above the plain warping's
    best ratio of each direction."""
    from sfanav import _core
    from sfanav.loopclosure.relative_pose import _scores_reference

    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(2, 2, rows, width))
    cols = rng.uniform(0, width, size=(3, n_ratios, width))
    shifts = rng.uniform(-2 * width, 2 * width, size=(2, n_shifts))
    flat = cols.reshape(3 * n_ratios, width)
    got = _core.warp_scores(a, b, flat, shifts, n_ratios)
    plain = _core.warp_scores(a, b, flat, shifts).reshape(2, 3, n_ratios, n_shifts)
    assert got.shape == (2, 3, n_shifts)
    for p in range(2):
        want = _scores_reference(a[p], b[p], cols, shifts[p], min_warping=True)[:, 0]
        np.testing.assert_allclose(got[p], want, rtol=1e-10, atol=1e-10)
    assert np.all(got <= plain.min(axis=2) + 1e-10)


def test_min_warp_scores_bad_group():
    from sfanav import _core

    a = np.zeros((2, 3, 16))
    for group in (0, 3):
        with pytest.raises(ValueError, match="groups"):
            _core.warp_scores(a, a, np.zeros((4, 16)), np.zeros((2, 1)), group)
    for group in (0, 3):
        with pytest.raises(ValueError, match="groups"):
            _core.warp_and_min_warp_scores(a, a, np.zeros((4, 16)), np.zeros((2, 1)), group)
    with pytest.raises(ValueError, match="must match"):
        _core.warp_and_min_warp_scores(a, a[:1], np.zeros((4, 16)), np.zeros((2, 1)), 2)


@settings(max_examples=20, deadline=None)
@given(st.integers(1, 4), st.integers(8, 40), st.integers(1, 6), st.integers(1, 3), st.integers(0, 10_000))
def test_both_scores_from_one_pass_property(rows, width, n_shifts, n_ratios, seed):
    """sfanav._core.warp_and_min_warp_scores gives what warp_scores gives with
    groups of one and with the group, from one pass."""
    from sfanav import _core

    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(2, 3, rows, width))
    flat = rng.uniform(0, width, size=(2 * n_ratios, width))
    shifts = np.round(rng.uniform(-2 * width, 2 * width, size=(3, n_shifts)) * 4) / 4
    each, mins = _core.warp_and_min_warp_scores(a, b, flat, shifts, n_ratios)
    assert each.shape == (3, 2 * n_ratios, n_shifts) and mins.shape == (3, 2, n_shifts)
    np.testing.assert_allclose(each, _core.warp_scores(a, b, flat, shifts), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(mins, _core.warp_scores(a, b, flat, shifts, n_ratios))


def test_relative_poses_by_method_are_each_methods_relative_poses(scene):
    from sfanav.loopclosure.relative_pose import relative_poses_by_method

    X = scene[0]
    i, j = np.arange(0, 6), np.arange(3, 9)
    both = relative_poses_by_method(X, i, j, distance=1.0, n_bearings=32, ratios=(0.05, 0.2))
    assert list(both) == ["warping", "min-warping"]
    for m, rp in both.items():
        one = relative_poses(X, i, j, distance=1.0, n_bearings=32, ratios=(0.05, 0.2), method=m)
        for name in ("dtheta", "bearing", "sigma_dtheta", "sigma_bearing", "covariance", "distance"):
            np.testing.assert_allclose(getattr(rp, name), getattr(one, name), rtol=1e-9, atol=1e-12, err_msg=name)
    with pytest.raises(ValueError, match="method must be one of"):
        relative_poses_by_method(X, i, j, methods=("warping", "warping"))
    with pytest.raises(ValueError, match="method must be one of"):
        relative_poses_by_method(X, i, j, methods=("bearing",))
    with pytest.raises(ValueError, match="method must be one of"):
        relative_poses(X, i, j, method=("warping",))
