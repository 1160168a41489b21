"""EKF fusion of odometry and SFA estimates (thesis 5.3.2)."""

import numpy as np
import pytest

import sfanav
from sfanav import OdometryEKF
from sfanav.odometry import ctrv_jacobians, ctrv_motion, grid_search, plot_fusion
from sfanav.experiments.synthetic_odometry import make_odometry_run


@pytest.fixture(scope="module")
def run():
    r = make_odometry_run(n_legs=6, random_state=2)
    rng = np.random.default_rng(7)
    r["sfa"] = r["xy"] + 0.15 * rng.normal(size=r["xy"].shape)
    return r


def med(a, b):
    return float(np.linalg.norm(a[:, :2] - b[:, :2], axis=1).mean())


def test_ctrv_jacobians_match_finite_differences():
    rng = np.random.default_rng(0)
    for dth in (0.0, 1e-6, 0.3, -2.0):
        x, u = rng.normal(size=3), np.array([0.7, dth])
        F, V = ctrv_jacobians(x, u)
        h = 1e-6
        Fn = np.column_stack([(ctrv_motion(x + h * e, u) - ctrv_motion(x - h * e, u)) / (2 * h) for e in np.eye(3)])
        Vn = np.column_stack([(ctrv_motion(x, u + h * e) - ctrv_motion(x, u - h * e)) / (2 * h) for e in np.eye(2)])
        np.testing.assert_allclose(F, Fn, atol=1e-8)
        np.testing.assert_allclose(V, Vn, atol=1e-7)
        # with the displacement's direction off the arc (beta held; the noise is in d and dtheta)
        u3 = np.array([0.7, dth, 0.4])
        F, V = ctrv_jacobians(x, u3)
        Fn = np.column_stack([(ctrv_motion(x + h * e, u3) - ctrv_motion(x - h * e, u3)) / (2 * h) for e in np.eye(3)])
        Vn = np.column_stack([(ctrv_motion(x, u3 + h * e) - ctrv_motion(x, u3 - h * e)) / (2 * h)
                              for e in np.eye(3)[:, :2].T])
        np.testing.assert_allclose(F, Fn, atol=1e-8)
        np.testing.assert_allclose(V, Vn, atol=1e-7)


def test_prediction_keeps_the_odometrys_direction_on_sparse_turns():
    # a mower's serpentine with 2 m between frames and quarter turns on the spot at the lane ends: the
    # filter without measurements follows the odometry exactly (the arc model was metres off at each lane end)
    lanes = [(x, 2.0 * r, 0.0 if r % 2 == 0 else np.pi) for r in range(4)
             for x in (np.arange(8) * 2.0 if r % 2 == 0 else np.arange(8)[::-1] * 2.0)]
    P = np.array(lanes)
    P[8::8, 2] = np.pi / 2
    ekf = OdometryEKF()
    fused = ekf.run(P, np.full((len(P), 2), np.nan), P[0])
    np.testing.assert_allclose(fused[:, :2], P[:, :2], atol=1e-9)
    np.testing.assert_allclose(OdometryEKF.dead_reckoning(P, P[0])[:, :2], P[:, :2], atol=1e-9)


def test_ekf_beats_both_inputs(run):
    odo = OdometryEKF.dead_reckoning(run["odometry"], run["poses"][0])
    ekf = OdometryEKF(distance_noise=0.003, heading_noise=0.01, measurement_noise=0.15)
    fused = ekf.run(run["odometry"], run["sfa"], run["poses"][0])
    assert fused.shape == (len(run["xy"]), 3) and ekf.covariances_.shape == (len(fused), 3, 3)
    e_odo, e_sfa, e_ekf = med(odo, run["poses"]), med(run["sfa"], run["poses"]), med(fused, run["poses"])
    assert e_ekf < 0.8 * e_sfa and e_ekf < e_odo, (e_ekf, e_sfa, e_odo)
    assert np.all(np.abs(fused[:, 2]) <= np.pi) and ekf.n_gated_ == 0 and np.isfinite(ekf.log_likelihood_)


def test_without_measurements_it_is_dead_reckoning(run):
    Z = np.full_like(run["sfa"], np.nan)
    ekf = OdometryEKF()
    fused = ekf.run(run["odometry"], Z, run["poses"][0])
    odo = OdometryEKF.dead_reckoning(run["odometry"], run["poses"][0])
    np.testing.assert_allclose(fused[:, :2], odo[:, :2], atol=1e-9)
    assert ekf.n_missing_ == len(Z)
    # uncertainty grows without measurements
    assert np.trace(ekf.covariances_[-1]) > np.trace(ekf.covariances_[1])


def test_gating_rejects_outliers(run):
    rng = np.random.default_rng(3)
    Z = run["sfa"].copy()
    bad = rng.choice(len(Z), 25, replace=False)
    Z[bad] += rng.choice([-1, 1], (25, 2)) * rng.uniform(2, 4, (25, 2))
    params = dict(distance_noise=0.003, heading_noise=0.01, measurement_noise=0.15)
    plain = OdometryEKF(**params).run(run["odometry"], Z, run["poses"][0])
    ekf = OdometryEKF(**params, gate_probability=0.999)
    gated = ekf.run(run["odometry"], Z, run["poses"][0])
    assert med(gated, run["poses"]) < 0.8 * med(plain, run["poses"])
    assert 20 <= ekf.n_gated_ <= 40 and ekf.gated_[bad].mean() > 0.8


def test_grid_search(run, tmp_path):
    grid = dict(distance_noise=(0.003, 0.03), heading_noise=(0.01,), measurement_noise=(0.05, 0.15, 0.5))
    gs = grid_search(run["odometry"], run["sfa"], run["poses"][0], run["xy"], progress=False, **grid)
    assert len(gs.results) == 6 and gs.criterion == "med"
    assert gs.best_score == min(r["med"] for r in gs.results) == pytest.approx(med(gs.best_poses, run["poses"]))
    nll = grid_search(run["odometry"], run["sfa"], run["poses"][0], progress=False, **grid)
    assert nll.criterion == "nll" and nll.best_params["measurement_noise"] == 0.15  # the true noise
    png = plot_fusion(run["xy"], run["sfa"], run["odometry"], gs.best_poses, tmp_path / "fusion.png")
    assert png.exists() and png.stat().st_size > 1000
    with pytest.raises(ValueError, match="needs ground truth"):
        grid_search(run["odometry"], run["sfa"], run["poses"][0], criterion="med", progress=False)


def test_bad_inputs(run):
    ekf = OdometryEKF()
    with pytest.raises(ValueError, match="rows but measurements has"):
        ekf.run(run["odometry"], run["sfa"][:-1], run["poses"][0])
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        ekf.run(run["odometry"], run["poses"], run["poses"][0])
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        ekf.run(run["xy"], run["sfa"], run["poses"][0])
    with pytest.raises(ValueError, match="start_pose"):
        ekf.run(run["odometry"], run["sfa"], (0.0, 0.0))
    with pytest.raises(ValueError, match="measurement_noise must be > 0"):
        OdometryEKF(measurement_noise=0).run(run["odometry"], run["sfa"], run["poses"][0])
    with pytest.raises(ValueError, match="gate_probability"):
        OdometryEKF(gate_probability=1.5).run(run["odometry"], run["sfa"], run["poses"][0])
    with pytest.raises(ValueError, match="infinity"):
        Z = run["sfa"].copy()
        Z[3, 0] = np.inf
        ekf.run(run["odometry"], Z, run["poses"][0])
    with pytest.raises(ValueError, match="unknown parameter"):
        ekf.set_params(q=1)
    assert "OdometryEKF" in repr(sfanav.OdometryEKF())


def test_turn_noise_widens_the_heading_variance_in_turns_only():
    from sfanav.odometry import OdometryEKF

    n = 40
    th = np.r_[np.zeros(n // 2), np.linspace(0, np.pi, n // 2)]  # straight, then a half turn
    xy = np.cumsum(np.c_[np.cos(th), np.sin(th)] * 0.1, axis=0)
    odo = np.c_[xy, th]
    Z = np.full((n, 2), np.nan)  # no measurements: the prediction alone
    plain = OdometryEKF(0.01, 0.01, 0.2)
    plain.run(odo, Z, odo[0])
    turned = OdometryEKF(0.01, 0.01, 0.2, turn_noise=0.1)
    turned.run(odo, Z, odo[0])
    v0, v1 = plain.covariances_[:, 2, 2], turned.covariances_[:, 2, 2]
    np.testing.assert_allclose(v1[: n // 2], v0[: n // 2])  # no turn, no extra noise
    extra = v1[-1] - v0[-1]
    np.testing.assert_allclose(extra, 0.1**2 * np.pi, rtol=1e-6)  # turn_noise^2 * |total turn|
    with pytest.raises(ValueError, match="turn_noise"):
        OdometryEKF(turn_noise=-1.0).run(odo, Z, odo[0])
