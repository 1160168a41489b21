"""Localization metrics and Umeyama alignment."""

import numpy as np
import pytest

from sfanav.localization import align, euclidean_errors, localization_metrics, mae, mae_percent, med


def rot2(deg):
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def test_errors_on_known_values():
    true = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0], [4.0, 4.0]])
    pred = true + np.array([[3.0, 4.0], [0.0, 0.0], [-1.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(euclidean_errors(pred, true), [5, 0, 1, 1])
    assert med(pred, true) == pytest.approx(7 / 4)
    np.testing.assert_allclose(mae(pred, true), [1.0, 1.25])
    np.testing.assert_allclose(mae_percent(pred, true), [25.0, 31.25])  # ranges 4 and 4
    np.testing.assert_allclose(mae_percent(pred, true, coordinate_range=[10, 5]), [10.0, 25.0])
    m = localization_metrics(pred, true, percentiles=(50, 100))
    assert m["n"] == 4 and m["med"] == pytest.approx(1.75) and m["p50"] == pytest.approx(1.0)
    assert m["p100"] == m["max"] == pytest.approx(5.0)
    assert m["rmse"] == pytest.approx(np.sqrt(27 / 4))
    assert m["mae_x_pct"] == pytest.approx(25.0) and m["mae_y"] == pytest.approx(1.25)


def test_metric_input_errors():
    a = np.zeros((5, 2))
    with pytest.raises(ValueError, match="xy_pred has 5 rows but xy_true has 4"):
        med(a, np.zeros((4, 2)))
    bad = a.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"xy_pred contains NaN.*\(3, 1\)"):
        med(bad, a)
    with pytest.raises(ValueError, match=r"shape \(N, d\)"):
        med(np.zeros(5), np.zeros(5))
    with pytest.raises(ValueError, match="coordinate range must be positive"):
        mae_percent(a, a)  # all ground truth at one point
    with pytest.raises(TypeError, match="real numbers"):
        med(np.array([["a", "b"]]), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="percentiles"):
        localization_metrics(a + [[0, 1]] * np.arange(5)[:, None], a + [[1, 1]] * np.arange(5)[:, None], percentiles=(120,))


@pytest.mark.parametrize("deg", [0.0, 37.0, -150.0])
def test_rigid_alignment_recovers_rotation_and_translation(deg):
    rng = np.random.default_rng(1)
    truth = rng.uniform(0, 5, (200, 2))
    R, t = rot2(deg), np.array([2.5, -1.0])
    estimate = (truth - t) @ R  # truth = R @ estimate + t
    al = align(estimate, truth)
    assert al.kind == "rigid" and al.scale == 1.0
    np.testing.assert_allclose(al.rotation, R, atol=1e-10)
    np.testing.assert_allclose(al.translation, t, atol=1e-10)
    assert al.angle_deg == pytest.approx(deg)
    np.testing.assert_allclose(al.apply(estimate), truth, atol=1e-10)
    assert al.rmse < 1e-10
    np.testing.assert_allclose((al.matrix() @ np.c_[estimate, np.ones(200)].T).T[:, :2], truth, atol=1e-10)


def test_similarity_alignment_recovers_scale_and_3d():
    rng = np.random.default_rng(2)
    truth = rng.normal(size=(100, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R = q * np.sign(np.linalg.det(q))  # proper rotation
    s, t = 0.37, np.array([1.0, 2.0, 3.0])
    estimate = ((truth - t) @ R) / s
    al = align(estimate, truth, scale=True)
    assert al.kind == "similarity"
    assert al.scale == pytest.approx(s)
    np.testing.assert_allclose(al.rotation, R, atol=1e-9)
    np.testing.assert_allclose(al.apply(estimate), truth, atol=1e-9)
    # with noise the fit is still close
    noisy = estimate + 0.01 * rng.normal(size=estimate.shape)
    assert align(noisy, truth, scale=True).scale == pytest.approx(s, rel=0.02)


def test_scale_range_clips_to_the_constrained_optimum():
    rng = np.random.default_rng(3)
    truth = rng.uniform(0, 4, (150, 2))
    estimate = truth @ rot2(20).T / 2.0 + 0.05 * rng.normal(size=truth.shape)  # true scale about 2
    free = align(estimate, truth, scale=True)
    assert free.scale == pytest.approx(2.0, rel=0.05) and not free.scale_clipped
    lim = align(estimate, truth, scale=(0.5, 1.5))
    assert lim.scale == 1.5 and lim.scale_clipped
    inside = align(estimate, truth, scale=(1.0, 3.0))
    assert inside.scale == pytest.approx(free.scale) and not inside.scale_clipped

    def cost(s):  # best rotation/translation for a fixed scale, brute force over angles
        best = np.inf
        for a in np.linspace(-180, 180, 3601):
            p = s * estimate @ rot2(a).T
            p += truth.mean(0) - p.mean(0)
            best = min(best, ((truth - p) ** 2).sum(1).mean())
        return best

    assert lim.rmse**2 <= cost(1.5) + 1e-6
    assert lim.rmse**2 < cost(1.4)


def test_reflection_only_when_allowed():
    rng = np.random.default_rng(4)
    truth = rng.uniform(0, 3, (50, 2))
    mirrored = truth * [-1, 1]
    proper = align(mirrored, truth)
    assert np.linalg.det(proper.rotation) == pytest.approx(1.0) and proper.rmse > 0.1
    refl = align(mirrored, truth, allow_reflection=True)
    assert np.linalg.det(refl.rotation) == pytest.approx(-1.0) and refl.rmse < 1e-10


def test_alignment_errors():
    pts = np.random.default_rng(0).normal(size=(10, 2))
    with pytest.raises(ValueError, match="at least 2 point pairs"):
        align(pts[:1], pts[:1])
    with pytest.raises(ValueError, match="single point repeated"):
        align(np.ones((5, 2)), pts[:5])
    with pytest.raises(ValueError, match="scale range"):
        align(pts, pts, scale=(2.0, 1.0))
    with pytest.raises(ValueError, match="scale range"):
        align(pts, pts, scale=(0.0, 1.0))
    with pytest.raises(TypeError, match="scale must be"):
        align(pts, pts, scale="yes")
    with pytest.raises(ValueError, match="reference has 3"):
        align(pts, np.zeros((10, 3)))
    with pytest.raises(ValueError, match="angle_deg"):
        _ = align(np.c_[pts, pts[:, :1]], np.c_[pts, pts[:, :1]]).angle_deg
    with pytest.raises(ValueError, match="2 columns"):
        align(pts, pts).apply(np.zeros((3, 3)))
