"""The GTSAM pose-graph back end (sfanav.odometry.pose_graph_gtsam) and
fit_pose_graph(solver="gtsam")."""

import sys

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from sfanav.localization import align  # noqa: E402
from sfanav.odometry import fit_pose_graph  # noqa: E402
from sfanav.odometry.dead_reckoning import wrap_angle  # noqa: E402
from sfanav.odometry.pose_graph_gtsam import (  # noqa: E402
    IncrementalPoseGraph,
    RelativePoses,
    has_gtsam,
    odometry_sigmas,
    solve_pose_graph,
)
from sfanav.sim import OdometryNoise, simulate_odometry  # noqa: E402
from sfanav.sim.cameras import bearings  # noqa: E402

NOISE = {"distance_sigma": 0.01, "heading_sigma": 0.004, "turn_sigma": 0.01, "slip_rate": 0.0}


def square(side=10, step=1.0):
    """True poses around a square, counter-clockwise, back to the start."""
    out, x, y, th = [], 0.0, 0.0, 0.0
    for _ in range(4):
        for _ in range(int(side / step)):
            out.append([x, y, th])
            x, y = x + step * np.cos(th), y + step * np.sin(th)
        th += np.pi / 2
    out.append([x, y, th])
    return np.array(out)


def lanes(n_lanes=6, per_lane=10, length=9.0, spacing=1.5):
    """A serpentine of lanes along x (heading 0 / pi), stepping in y."""
    out = []
    for k in range(n_lanes):
        x = np.linspace(0, length, per_lane)
        x = x if k % 2 == 0 else x[::-1]
        out.append(np.c_[x, np.full(per_lane, k * spacing), np.full(per_lane, 0.0 if k % 2 == 0 else np.pi)])
    return np.concatenate(out)


def drifted(truth, drift):
    """Odometry with a heading drift of ``drift`` rad/m and nothing else."""
    noise = OdometryNoise(0.0, 0.0, 0.0, 0.0, drift, 0.0, 0.0, 0.0)
    return simulate_odometry(truth, noise, rng=0)


def neighbours(truth, radius, min_gap=5):
    """Pairs (i < j) of frames within ``radius`` m and ``min_gap`` frames apart,
    with their true relative pose in frame i."""
    D = np.hypot(*(truth[:, None, :2] - truth[None, :, :2]).transpose(2, 0, 1))
    i, j = np.nonzero((D < radius) & (np.arange(len(truth))[None, :] - np.arange(len(truth))[:, None] >= min_gap))
    c, s = np.cos(truth[i, 2]), np.sin(truth[i, 2])
    d = truth[j, :2] - truth[i, :2]
    return i, j, c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap_angle(truth[j, 2] - truth[i, 2])


def mean_error(P, T):
    return float(np.mean(np.hypot(*(align(P, T).apply(P) - T).T)))


def test_a_square_loop_with_a_closure_closes():
    T = square()
    odo = simulate_odometry(T, OdometryNoise(heading_drift=0.0, slip_rate=0.0, scale_error=0.0), rng=3)
    gap = np.hypot(*(odo[-1, :2] - odo[0, :2]))
    assert gap > 0.05  # the odometry does not close
    C = RelativePoses([0], [len(T) - 1], [0.0], [0.0], [0.0], sigmas=[[0.01, 0.01, 0.001]])
    r = solve_pose_graph(odo, C, odometry_noise=NOISE, drift="none")
    assert np.hypot(*(r.poses[-1, :2] - r.poses[0, :2])) < 0.02 * gap + 0.01
    np.testing.assert_allclose(r.poses[-1, 2] - r.poses[0, 2], 2 * np.pi, atol=0.01)  # unwrapped once around
    np.testing.assert_allclose(r.poses[0], odo[0], atol=1e-6)  # the first frame stays at its odometry pose
    assert r.weights[0] > 0.5


@pytest.mark.parametrize("drift_mode", ["joint", "iterate"])
def test_a_straight_line_with_drift_recovers_the_rate(drift_mode):
    T = np.c_[np.arange(50.0), np.zeros(50), np.zeros(50)]
    odo = drifted(T, 0.01)
    j = np.array([10, 20, 30, 40, 49])
    C = RelativePoses.from_headings(np.zeros(5, int), j, np.zeros(5), np.radians(0.5))
    r = solve_pose_graph(odo, C, odometry_noise=NOISE, drift=drift_mode)
    np.testing.assert_allclose(r.drift_rate, 0.01, rtol=1e-3)
    np.testing.assert_allclose(r.poses[:, 2], 0.0, atol=1e-4)
    np.testing.assert_allclose(r.poses[:, :2], T[:, :2], atol=1e-3)
    none = solve_pose_graph(odo, C, odometry_noise=NOISE, drift="none")
    assert none.drift_rate == 0.0 and np.abs(none.poses[:, 1]).max() > 0.1  # without the rate the line bends


def test_joint_and_iterated_drift_agree_across_u_turns():
    # the custom factor's Jacobians must hold at a relative heading of pi (the lane ends)
    T = lanes()
    odo = drifted(T, 0.02)
    i, j, dx, dy, dth = neighbours(T, 1.6)
    C = RelativePoses(i, j, dx, dy, dth, sigmas=np.tile([0.1, 0.1, 0.02], (len(i), 1)))
    a = solve_pose_graph(odo, C, odometry_noise=NOISE, drift="joint")
    b = solve_pose_graph(odo, C, odometry_noise=NOISE, drift="iterate")
    assert a.iterations < 30
    np.testing.assert_allclose(a.drift_rate, b.drift_rate, atol=2e-4)
    np.testing.assert_allclose(a.poses, b.poses, atol=0.02)
    assert mean_error(a.poses[:, :2], T[:, :2]) < 0.05 < mean_error(odo[:, :2], T[:, :2])


def test_the_robust_kernel_rejects_a_wrong_closure():
    T = square()
    odo = simulate_odometry(T, OdometryNoise(heading_drift=0.0, slip_rate=0.0, scale_error=0.0), rng=3)
    n = len(T)
    # right: the loop closes; wrong: frame 20 claimed 3 m beside frame 5, turned by 90 degrees
    C = RelativePoses([0, 5], [n - 1, 20], [0.0, 0.0], [0.0, 3.0], [0.0, np.pi / 2],
                      sigmas=[[0.05, 0.05, 0.01], [0.05, 0.05, 0.01]])
    good = solve_pose_graph(odo, C.subset([0]), odometry_noise=NOISE, drift="none")
    r = solve_pose_graph(odo, C, odometry_noise=NOISE, drift="none")
    assert r.weights[0] > 0.5 > 0.01 > r.weights[1]
    np.testing.assert_allclose(r.poses[:, :2], good.poses[:, :2], atol=0.05)
    plain = solve_pose_graph(odo, C, odometry_noise=NOISE, drift="none", robust="none")
    assert np.abs(plain.poses[:, :2] - good.poses[:, :2]).max() > 1.0  # least squares bends the map
    huber = solve_pose_graph(odo, C, odometry_noise=NOISE, drift="none", robust="huber")
    assert huber.weights[1] < 0.5


def test_isam2_after_all_updates_agrees_with_batch_levenberg_marquardt():
    T = lanes()
    odo = simulate_odometry(T, OdometryNoise(heading_drift=0.01, slip_rate=0.0), rng=1)
    i, j, dx, dy, dth = neighbours(T, 1.6)
    sig = np.tile([0.2, 0.2, 0.03], (len(i), 1))
    sig[::2, :2] = np.inf  # half of them heading-only
    C = RelativePoses(i, j, dx, dy, dth, sigmas=sig)
    batch = solve_pose_graph(odo, C, odometry_noise=NOISE, drift="joint")
    inc = IncrementalPoseGraph(odometry_noise=NOISE)
    added = np.zeros(len(C), bool)
    for k in range(6):
        inc.add_frames(odo[10 * k:10 * (k + 1)])
        ready = ~added & (np.maximum(C.i, C.j) < 10 * (k + 1))
        if ready.any():
            inc.add_closures(C.subset(ready))
            added |= ready
        inc.update()
    inc.update(extra_iterations=3)
    assert inc.n_frames_ == len(T) and added.all()
    np.testing.assert_allclose(inc.poses_, batch.poses, atol=2e-3)
    np.testing.assert_allclose(inc.drift_rate_, batch.drift_rate, atol=1e-4)


def test_heading_only_closures_fix_headings_without_pulling_lanes_together():
    T = lanes()
    i, j, _, _, dth = neighbours(T, 1.6)
    assert np.all(np.abs(T[i, 1] - T[j, 1]) > 1.0)  # the pairs join neighbouring lanes 1.5 m apart
    exact = solve_pose_graph(T, RelativePoses.from_headings(i, j, dth, 0.02), odometry_noise=NOISE)
    np.testing.assert_allclose(exact.poses, np.c_[T[:, :2], np.unwrap(T[:, 2])], atol=1e-3)  # nothing moves
    # the same closures with a (wrong) zero offset and a position sigma pull the lanes onto each other
    z = np.zeros(len(i))
    pulled = solve_pose_graph(T, RelativePoses(i, j, z, z, dth, sigmas=np.tile([0.1, 0.1, 0.02], (len(i), 1))),
                              odometry_noise=NOISE, robust="none")
    assert np.ptp(pulled.poses[:, 1]) < 0.8 * np.ptp(T[:, 1])
    # with drifted odometry they bring the headings back
    odo = drifted(T, 0.02)
    r = solve_pose_graph(odo, RelativePoses.from_headings(i, j, dth, 0.02), odometry_noise=NOISE)
    err = lambda th: np.abs(wrap_angle(th - T[:, 2])).max()  # noqa: E731
    assert err(r.poses[:, 2]) < 0.01 < 0.5 * err(odo[:, 2])


def test_odometry_sigmas_grow_with_distance_and_turn():
    P = np.array([[0, 0, 0], [1, 0, 0], [5, 0, 0], [5, 0, np.pi / 2]], float)
    s = odometry_sigmas(P, NOISE)
    np.testing.assert_allclose(s[0], [0.01, np.sqrt(1e-4 + (0.5 * 0.004) ** 2), 0.004], rtol=1e-4)
    np.testing.assert_allclose(s[1, 0], 0.01 * 2, rtol=1e-4)  # 4 m
    np.testing.assert_allclose(s[2, 2], 0.01 * np.sqrt(np.pi / 2), rtol=1e-4)  # a turn on the spot


def test_no_closures_is_dead_reckoning():
    T = lanes(2)
    odo = drifted(T, 0.02)
    for mode in ("joint", "iterate", "none"):
        r = solve_pose_graph(odo, None, odometry_noise=NOISE, drift=mode)
        np.testing.assert_allclose(r.poses[:, :2], odo[:, :2], atol=1e-6)
        assert abs(r.drift_rate) < 1e-9 and len(r.weights) == 0


def rotating_panoramas(headings, width=120, height=3, seed=0):
    rng = np.random.default_rng(seed)
    k = np.arange(1, 7)
    amp, phase = rng.normal(size=(height, 6)) / k, rng.uniform(0, 2 * np.pi, size=(height, 6))
    world = headings[:, None] + bearings(width)[None, :]
    img = (amp[None, :, None, :] * np.cos(k * world[:, None, :, None] + phase[None, :, None, :])).sum(axis=3)
    return (img * 40 + 128).astype(np.float32)


def test_fit_pose_graph_with_the_gtsam_solver_matches_the_hand_written_one():
    T = lanes(6, 12, 11.0, 1.2)
    odo = drifted(T, 0.01)
    images, features = rotating_panoramas(T[:, 2]), T[:, :2] / 3.0
    hw = fit_pose_graph(images, features, odo, refine=0)
    gt = fit_pose_graph(images, features, odo, refine=0, solver="gtsam")
    assert len(gt.pairs) == len(hw.pairs) > 20 and gt.n_inliers == len(gt.pairs)
    np.testing.assert_allclose(gt.drift_rate, 0.01, rtol=0.1)
    assert mean_error(gt.poses[:, :2], T[:, :2]) < 0.05 < mean_error(odo[:, :2], T[:, :2])
    assert abs(mean_error(gt.poses[:, :2], T[:, :2]) - mean_error(hw.poses[:, :2], T[:, :2])) < 0.03
    # further closures with a relative position go in beside the compass's
    i, j, dx, dy, dth = neighbours(T, 1.3)
    extra = RelativePoses(i, j, dx, dy, dth, covariance=np.tile(np.diag([0.01, 0.01, 1e-3]), (len(i), 1, 1)))
    both = fit_pose_graph(images, features, odo, refine=0, solver="gtsam", relative_poses=extra)
    assert mean_error(both.poses[:, :2], T[:, :2]) < 0.05
    assert len(both.weights) == len(both.pairs)


def test_bad_input_raises_clear_errors():
    ok = dict(i=[0], j=[3], dx=[0.0], dy=[0.0], dtheta=[0.0], sigmas=[[0.1, 0.1, 0.01]])
    RelativePoses(**ok)
    with pytest.raises(ValueError, match="one length"):
        RelativePoses(**{**ok, "dx": [0.0, 1.0]})
    with pytest.raises(ValueError, match="itself"):
        RelativePoses(**{**ok, "j": [0]})
    with pytest.raises(ValueError, match=">= 0"):
        RelativePoses(**{**ok, "i": [-1]})
    with pytest.raises(TypeError, match="frame indices"):
        RelativePoses(**{**ok, "i": [0.5]})
    with pytest.raises(ValueError, match="positive"):
        RelativePoses(**{**ok, "sigmas": [[0.0, 0.1, 0.01]]})
    with pytest.raises(ValueError, match="heading sigma"):
        RelativePoses(**{**ok, "sigmas": [[0.1, 0.1, np.inf]]})
    with pytest.raises(ValueError, match=r"shape \(1, 3\)"):
        RelativePoses(**{**ok, "sigmas": [0.1, 0.1, 0.01]})
    with pytest.raises(ValueError, match="exactly one"):
        RelativePoses(**{**ok, "covariance": [np.eye(3)]})
    with pytest.raises(ValueError, match="positive definite"):
        RelativePoses(**{**ok, "sigmas": None, "covariance": [np.diag([1.0, 1.0, -1.0])]})
    with pytest.raises(ValueError, match="symmetric"):
        RelativePoses(**{**ok, "sigmas": None, "covariance": [np.eye(3) + np.triu(np.ones((3, 3)), 1)]})
    with pytest.raises(ValueError, match="NaN"):
        RelativePoses(**{**ok, "dtheta": [np.nan]})
    odo = lanes(1)
    with pytest.raises(ValueError, match="frame 30"):
        solve_pose_graph(odo, RelativePoses(**{**ok, "j": [30]}))
    with pytest.raises(TypeError, match="RelativePoses"):
        solve_pose_graph(odo, {"i": [0]})
    with pytest.raises(ValueError, match="drift"):
        solve_pose_graph(odo, drift="both")
    with pytest.raises(ValueError, match="robust"):
        solve_pose_graph(odo, robust="tukey")
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        solve_pose_graph(odo[:, :2])
    with pytest.raises(ValueError, match="iterate"):
        IncrementalPoseGraph(drift="iterate")
    with pytest.raises(ValueError, match="frame 3"):
        IncrementalPoseGraph().add_frames(odo[:3]).add_closures(RelativePoses(**ok))
    images, features = rotating_panoramas(odo[:, 2]), odo[:, :2]
    with pytest.raises(ValueError, match="solver"):
        fit_pose_graph(images, features, odo, solver="ceres")
    with pytest.raises(ValueError, match="solver='gtsam'"):
        fit_pose_graph(images, features, odo, relative_poses=RelativePoses(**ok))


def test_without_gtsam_the_error_names_the_package(monkeypatch):
    """gtsam is a dependency; a broken install gets an ImportError naming it
    and the heading-only, hand-written way round it."""
    monkeypatch.setitem(sys.modules, "gtsam", None)  # import gtsam now raises ImportError
    assert not has_gtsam()
    with pytest.raises(ImportError, match="pip install gtsam"):
        solve_pose_graph(lanes(1))
    T = lanes(2)
    with pytest.raises(ImportError, match="hand-written"):
        fit_pose_graph(rotating_panoramas(T[:, 2]), T[:, :2], T, refine=0, solver="gtsam")


def test_per_step_noise_fields_weigh_the_odometry():
    """A noise model that keeps its noise in the per-step fields (the
    simulator's mower odometry: heading noise per frame, distance noise as a
    fraction of the step) weighs every step by them in both back ends,
    instead of taking a straight step's heading as exact."""
    from sfanav.odometry.pose_graph import PER_STEP_NOISE, step_distance_sigmas, step_heading_sigmas
    from sfanav.odometry.pose_graph_gtsam import odometry_noise_model, odometry_sigmas
    from sfanav.sim import OdometryNoise

    noise = OdometryNoise.mower(distance_fraction=0.02, heading_deg=0.5, drift_deg_per_m=0.1)
    raw = noise.to_dict()
    assert raw["heading_sigma"] == 0.0 and raw["distance_sigma"] == 0.0  # all of it per step
    odo = np.array([[0.0, 0.0, 0.0], [1.2, 0.0, 0.0], [2.4, 0.0, 0.5]])
    sig = odometry_sigmas(odo, raw)
    d, dth = np.array([1.2, 1.2]), np.array([0.0, 0.5])
    want_h = np.sqrt(raw["step_heading_sigma"] ** 2 + (raw["turn_fraction"] * dth) ** 2
                     + raw["turn_sigma"] ** 2 * np.abs(dth) + 1e-10)
    np.testing.assert_allclose(sig[:, 2], want_h, rtol=1e-12)
    np.testing.assert_allclose(sig[:, 0], np.sqrt((0.02 * d) ** 2 + 1e-10), rtol=1e-12)
    nz = odometry_noise_model(raw)
    assert set(PER_STEP_NOISE) <= set(nz)
    np.testing.assert_allclose(step_heading_sigmas(nz, d, dth), want_h, rtol=1e-12)
    np.testing.assert_allclose(step_distance_sigmas(nz, d), sig[:, 0], rtol=1e-12)
    # a random-walk-only model is unchanged by the per-step terms (they default to zero)
    rw = {"distance_sigma": 0.02, "heading_sigma": 0.01, "turn_sigma": 0.02}
    np.testing.assert_allclose(odometry_sigmas(odo, rw)[:, 2],
                               np.sqrt((0.01**2 + 0.01 * 0.02**2) * d + 0.02**2 * np.abs(dth) + 1e-10), rtol=1e-12)
