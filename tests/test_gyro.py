"""A yaw gyro fused with the odometry's turns (sfanav.odometry.gyro): in
the pose graph (both back ends), the EKF's prediction and learn_positions;
the noise model's fusion weights; bad input."""

import numpy as np
import pytest

from sfanav.localization import align
from sfanav.odometry import OdometryEKF, fit_pose_graph, learn_positions
from sfanav.odometry.gyro import DEFAULT_GYRO_NOISE, fuse_gyro, fuse_turns
from sfanav.odometry.self_supervision import fit_localizer_from_odometry
from sfanav.sim import GyroNoise, OdometryNoise, simulate_gyro, simulate_odometry
from sfanav.sim.cameras import bearings

# wheels with a poor heading (random walk and per-step noise), good distances
WHEELS = OdometryNoise(0.005, 0.0, 0.03, 0.02, 0.0, 0.0, 0.0, 0.0)
PG_NOISE = {"distance_sigma": 0.005, "heading_sigma": 0.03, "turn_sigma": 0.02, "slip_rate": 0.0}


def lanes(n_lanes=6, per_lane=12, length=11.0, spacing=1.2):
    out = []
    for k in range(n_lanes):
        x = np.linspace(0, length, per_lane)
        x = x if k % 2 == 0 else x[::-1]
        out.append(np.c_[x, np.full(per_lane, k * spacing), np.full(per_lane, 0.0 if k % 2 == 0 else np.pi)])
    return np.concatenate(out)


def panoramas(headings, width=120, height=3, seed=0):
    rng = np.random.default_rng(seed)
    k = np.arange(1, 7)
    amp, phase = rng.normal(size=(height, 6)) / k, rng.uniform(0, 2 * np.pi, size=(height, 6))
    world = headings[:, None] + bearings(width)[None, :]
    img = (amp[None, :, None, :] * np.cos(k * world[:, None, :, None] + phase[None, :, None, :])).sum(axis=3)
    return (img * 40 + 128).astype(np.float32)


def mean_error(P, T):
    return float(np.mean(np.hypot(*(align(P, T).apply(P) - T).T)))


@pytest.fixture(scope="module")
def run():
    T = lanes()
    t = np.arange(len(T)) * 2.5
    odo = simulate_odometry(T, WHEELS, rng=3)
    gyro = simulate_gyro(T, t, GyroNoise(), rng=4)
    return T, odo, gyro


def test_fusion_weights_follow_the_variances():
    # equal variances: the mean; a perfect gyro (variance -> 0): the gyro's turn
    turn, var, w = fuse_turns(np.array([0.2]), np.array([1e-4]), np.array([0.0]), np.array([0.0]),
                              {"heading_sigma": 0.0, "turn_fraction": 0.0})
    assert w[0] == pytest.approx(1.0) and turn[0] == pytest.approx(0.0, abs=1e-8) and var[0] < 1e-12
    s2 = DEFAULT_GYRO_NOISE["heading_sigma"] ** 2 * 4.0
    turn, var, w = fuse_turns(np.array([0.1]), np.array([s2]), np.array([0.0]), np.array([4.0]),
                              {"turn_fraction": 0.0})
    assert w[0] == pytest.approx(0.5) and turn[0] == pytest.approx(0.05) and var[0] == pytest.approx(s2 / 2)
    # an odometry turn wrapped to -pi is taken on the gyro's branch (+pi)
    turn, _, _ = fuse_turns(np.array([-np.pi + 0.01]), np.array([1.0]), np.array([np.pi - 0.01]), np.array([1.0]))
    assert turn[0] == pytest.approx(np.pi - 0.01, abs=1e-3)


def test_fused_odometry_keeps_the_steps_and_takes_the_gyros_headings(run):
    T, odo, gyro = run
    f = fuse_gyro(odo, gyro, odometry_noise=PG_NOISE)
    np.testing.assert_allclose(np.hypot(*np.diff(f.odometry[:, :2], axis=0).T),
                               np.hypot(*np.diff(odo[:, :2], axis=0).T), rtol=1e-9)
    np.testing.assert_allclose(f.odometry[0], odo[0])
    assert np.all(f.gyro_weight > 0.9) and np.all(f.heading_sigma > 0)
    err = lambda th: np.abs(np.angle(np.exp(1j * (th - T[:, 2])))).mean()  # noqa: E731
    assert err(f.odometry[:, 2]) < 0.2 * err(odo[:, 2])
    assert mean_error(f.odometry[:, :2], T[:, :2]) < 0.5 * mean_error(odo[:, :2], T[:, :2])


@pytest.mark.parametrize("solver", ["hand-written", "gtsam"])
def test_the_pose_graph_with_a_gyro_beats_the_noisy_wheels(run, solver):
    if solver == "gtsam":
        pytest.importorskip("gtsam")
    T, odo, gyro = run
    images, features = panoramas(T[:, 2]), T[:, :2] / 3.0
    kw = dict(odometry_noise=PG_NOISE, refine=0, solver=solver)
    without = fit_pose_graph(images, features, odo, **kw)
    with_gyro = fit_pose_graph(images, features, odo, gyro=gyro, **kw)
    e0, e1 = mean_error(without.poses[:, :2], T[:, :2]), mean_error(with_gyro.poses[:, :2], T[:, :2])
    assert e1 < 0.7 * e0, (e0, e1)
    h = lambda P: np.abs(np.angle(np.exp(1j * (P[:, 2] - T[:, 2])))).mean()  # noqa: E731
    assert h(with_gyro.poses) < h(without.poses)


def test_the_ekf_prediction_uses_the_gyro(run):
    T, odo, gyro = run
    Z = np.full((len(T), 2), np.nan)
    Z[::12] = T[::12, :2]  # sparse absolute fixes: the prediction carries the rest
    ekf = OdometryEKF(0.01, 0.05, 0.1, turn_noise=0.02)
    plain = ekf.run(odo, Z, T[0])
    fused = OdometryEKF(0.01, 0.05, 0.1, turn_noise=0.02).run(odo, Z, T[0], gyro=gyro)
    e = lambda P: float(np.mean(np.hypot(*(P[:, :2] - T[:, :2]).T)))  # noqa: E731
    assert e(fused) < 0.7 * e(plain), (e(plain), e(fused))


def test_learn_positions_passes_the_gyro(run):
    T, odo, gyro = run
    images, features = panoramas(T[:, 2]), T[:, :2] / 3.0
    kw = dict(images=images, odometry_noise=PG_NOISE, pose_graph={"refine": 0}, n_outputs=2)
    a = learn_positions(features, odo, **kw)
    b = learn_positions(features, odo, gyro=gyro, **kw)
    assert mean_error(b.positions, T[:, :2]) < mean_error(a.positions, T[:, :2])


def test_bad_gyro_raises_clear_errors(run):
    T, odo, gyro = run
    images, features = panoramas(T[:, 2]), T[:, :2] / 3.0
    with pytest.raises(ValueError, match="gyro has 71 headings but the odometry has 72"):
        fuse_gyro(odo, gyro[:-1])
    bad = gyro.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="frame 5"):
        fuse_gyro(odo, bad)
    with pytest.raises(ValueError, match="shape"):
        fuse_gyro(odo, np.c_[gyro, gyro])
    with pytest.raises(TypeError):
        fuse_gyro(odo, ["a"] * len(odo))
    with pytest.raises(ValueError, match="unknown gyro_noise key"):
        fuse_gyro(odo, gyro, gyro_noise={"bias": 0.1})
    with pytest.raises(ValueError, match="gyro_noise"):
        fuse_gyro(odo, gyro, gyro_noise={"heading_sigma": -1.0})
    with pytest.raises(ValueError, match="gyro has 10 headings"):
        fit_pose_graph(images, features, odo, gyro=gyro[:10])
    with pytest.raises(ValueError, match="frame 5"):
        OdometryEKF().run(odo, T[:, :2], T[0], gyro=bad)
    with pytest.raises(ValueError, match="gyro has 10 headings"):
        learn_positions(features, odo, images=images, gyro=gyro[:10], n_outputs=2)
    with pytest.raises(ValueError, match="frame 5"):  # before any network is trained (there is none here)
        fit_localizer_from_odometry(None, images, odo, gyro=bad)
