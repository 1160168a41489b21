"""Relative-pose closures of the pose graph's place pairs
(sfanav.odometry.pair_closures, fit_pose_graph(pair_closures="relative-pose")):
on a tiny rendered serpentine they improve on heading-only closures; the
local gradient; bad input."""

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from sfanav import sim  # noqa: E402
from sfanav.localization import align  # noqa: E402
from sfanav.loopclosure import RelativePoses as Measured  # noqa: E402
from sfanav.loopclosure import relative_poses  # noqa: E402
from sfanav.odometry import fit_pose_graph  # noqa: E402
from sfanav.odometry.pair_closures import (  # noqa: E402
    CORRELATION_RADIUS,
    WARP_OPTIONS,
    decorrelate,
    local_gradients,
    pair_relative_poses,
)
from sfanav.odometry.pose_graph_gtsam import HEADING_ONLY_SIGMA, RelativePoses  # noqa: E402


def lanes(n_lanes=5, per_lane=8):
    """A serpentine of 1 m steps on lanes 1 m apart (headings 0 / pi)."""
    out = []
    for k in range(n_lanes):
        x = np.arange(per_lane) - (per_lane - 1) / 2
        x = x if k % 2 == 0 else x[::-1]
        out.append(np.c_[x, np.full(per_lane, k - (n_lanes - 1) / 2), np.full(per_lane, np.pi * (k % 2))])
    return np.concatenate(out)


def odometry(T, rng, distance=0.03, heading_deg=1.0, drift_deg=0.5):
    """Each true step (in the frame of its start) scaled by a random
    distance error and turned by the accumulated heading error."""
    d = np.hypot(*np.diff(T[:, :2], axis=0).T)
    turn = np.angle(np.exp(1j * np.diff(T[:, 2])))
    th = T[0, 2] + np.r_[0.0, np.cumsum(turn + np.radians(heading_deg) * rng.standard_normal(len(d))
                                        + np.radians(drift_deg) * d)]
    dxy = np.diff(T[:, :2], axis=0) * (1 + distance * rng.standard_normal(len(d)))[:, None]
    c, s = np.cos(T[:-1, 2]), np.sin(T[:-1, 2])
    lx, ly = c * dxy[:, 0] + s * dxy[:, 1], -s * dxy[:, 0] + c * dxy[:, 1]
    cn, sn = np.cos(th[:-1]), np.sin(th[:-1])
    xy = T[0, :2] + np.r_[np.zeros((1, 2)), np.cumsum(np.c_[cn * lx - sn * ly, sn * lx + cn * ly], axis=0)]
    return np.c_[xy, th]


def mean_error(P, T):
    return float(np.mean(np.hypot(*(align(P, T).apply(P) - T).T)))


@pytest.fixture(scope="module")
def scene():
    """40 rendered 120x16 gray panoramas of a serpentine in a garden with
    objects inside, smooth features of the true position, a drifting
    odometry."""
    T = lanes()
    w = sim.World.generate(3, area=(10, 10), n_objects=20, depth=8.0, inner={"tree": 1, "bush": 2, "pole": 2})
    r, cam = sim.Renderer(w), sim.PanoramicCamera(120, 16, rgb=False)
    X = np.array([r.render(cam, p) for p in T])
    rng = np.random.default_rng(1)
    F = np.c_[T[:, :2] / 3.0, T[:, :2] / 2.0 + 0.05 * T[:, :2] ** 2] + 0.01 * rng.standard_normal((len(T), 4))
    return X, F, odometry(T, rng), T


def test_relative_pose_closures_improve_on_heading_only(scene):
    X, F, odo, T = scene
    kw = dict(refine=0, min_travel=3.0, n_outputs=4, solver="gtsam")
    heading = fit_pose_graph(X, F, odo, **kw)
    full = fit_pose_graph(X, F, odo, pair_closures="relative-pose", **kw)
    e0, e1 = mean_error(heading.poses[:, :2], T[:, :2]), mean_error(full.poses[:, :2], T[:, :2])
    assert e1 < 0.85 * e0, (e0, e1)
    assert len(full.weights) == len(full.pairs) and full.n_inliers > 0.8 * len(full.pairs)
    # min-warping's closures (pair_options' warp) improve on heading-only alike, and reach the warping
    warp = {**WARP_OPTIONS, "method": "min-warping"}
    mw = fit_pose_graph(X, F, odo, pair_closures="relative-pose", pair_options={"warp": warp}, **kw)
    e2 = mean_error(mw.poses[:, :2], T[:, :2])
    assert e2 < 0.85 * e0 and not np.allclose(mw.poses, full.poses), (e0, e1, e2)
    # the hand-written path is unchanged by the option's existence
    hw = fit_pose_graph(X, F, odo, refine=0, min_travel=3.0, n_outputs=4)
    assert mean_error(hw.poses[:, :2], T[:, :2]) == pytest.approx(e0, abs=0.02)


def test_closure_method_auto_keeps_the_map_its_closures_fit_better(scene):
    X, F, odo, T = scene
    kw = dict(min_travel=3.0, n_outputs=4, solver="gtsam", pair_closures="relative-pose")
    fits = {m: fit_pose_graph(X, F, odo, closure_method=m, refine=1, **kw) for m in ("warping", "min-warping")}
    assert {m: g.closure_method for m, g in fits.items()} == {"warping": "warping", "min-warping": "min-warping"}
    misfits = {m: g.misfit for m, g in fits.items()}
    assert all(np.isfinite(v) and v > 0 for v in misfits.values()) and misfits["warping"] != misfits["min-warping"]
    # the misfit is closure_misfit of the final map against its own closures
    from sfanav.odometry.pose_graph import closure_misfit
    g = fits["warping"]
    assert g.misfit == closure_misfit(g.poses[:, :2], g.poses[:, 2], g.closures)
    auto = fit_pose_graph(X, F, odo, closure_method="auto", refine=1, **kw)
    best = min(misfits, key=misfits.get)
    assert auto.closure_method == best
    np.testing.assert_array_equal(auto.poses, fits[best].poses)
    assert auto.method_misfits == pytest.approx(misfits)
    info = auto.info()
    assert info["closure method"] == best and set(info["closure misfit by method"]) == {"warping", "min-warping"}
    kw["refine"] = 1
    # the old spelling through pair_options' warp is the same fit as closure_method
    warp = {**WARP_OPTIONS, "method": "min-warping"}
    old = fit_pose_graph(X, F, odo, pair_options={"warp": warp}, **kw)
    np.testing.assert_array_equal(old.poses, fits["min-warping"].poses)
    assert old.closure_method == "min-warping"
    # heading-only closures: no relative-pose closures, no method, no misfit
    h = fit_pose_graph(X, F, odo, refine=0, min_travel=3.0, n_outputs=4, solver="gtsam", closure_method="auto")
    assert h.closures is None and h.closure_method is None and np.isnan(h.misfit)
    with pytest.raises(ValueError, match="closure_method must be one of"):
        fit_pose_graph(X, F, odo, closure_method="both", **kw)
    with pytest.raises(ValueError, match="given twice"):
        fit_pose_graph(X, F, odo, closure_method="auto", pair_options={"warp": warp}, **kw)


def test_pair_closures_measure_relative_poses_with_honest_sigmas(scene):
    X, F, odo, T = scene
    g = fit_pose_graph(X, F, odo, refine=0, min_travel=3.0, n_outputs=4, solver="gtsam")
    i, j = g.pairs.past, g.pairs.current
    C = pair_relative_poses(X, F, g.poses[:, :2], i, j, g.relative_heading, np.radians(5), use_gradient=True)
    assert isinstance(C, RelativePoses) and len(C) == len(i)
    full = C.covariance[:, 0, 0] < HEADING_ONLY_SIGMA**2 / 2
    assert full.sum() > len(C) / 2
    c, s = np.cos(T[i, 2]), np.sin(T[i, 2])
    d = T[j, :2] - T[i, :2]
    tx, ty = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    e = np.hypot(C.dx - tx, C.dy - ty)[full]
    sd = np.sqrt(C.covariance[full, 0, 0] + C.covariance[full, 1, 1])
    assert np.median(e) < 0.6 and np.median(e / sd) < 2.0, (np.median(e), np.median(e / sd))
    # heading-only pairs keep the compass's heading
    np.testing.assert_allclose(C.dtheta[~full], g.relative_heading[~full])
    # the map's own distance alone (the default): the same bearings, the map's lengths
    M = pair_relative_poses(X, F, g.poses[:, :2], i, j, g.relative_heading, np.radians(5))
    both = (M.covariance[:, 0, 0] < HEADING_ONLY_SIGMA**2 / 2) & full
    np.testing.assert_allclose(np.hypot(M.dx, M.dy)[both], np.hypot(*(g.poses[j, :2] - g.poses[i, :2]).T)[both],
                               rtol=1e-6, atol=1e-3)


def test_decorrelate_counts_the_closures_of_a_place_as_one():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((6, 3, 3))
    cov = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(3)
    mid = np.array([[0.0, 0.0], [0.3, 0.0], [0.0, 0.4], [5.0, 5.0], [5.2, 5.0], [9.0, 0.0]])
    out = decorrelate(cov, mid, 1.0)
    n = np.array([3, 3, 3, 2, 2, 1])
    D = np.zeros((6, 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = np.sqrt(n)
    D[:, 2, 2] = 1.0
    np.testing.assert_allclose(out, D @ cov @ D, rtol=1e-12)  # position block x n, heading kept
    np.testing.assert_allclose(out[:, 2, 2], cov[:, 2, 2])
    assert np.all(np.linalg.eigvalsh(out) > 0)  # still positive definite
    np.testing.assert_array_equal(cov, A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(3))  # input untouched
    # the information of n fully correlated closures of one place: that of one
    info = np.linalg.inv(out[:3, :2, :2]).sum(axis=0)
    np.testing.assert_allclose(np.trace(info), np.trace(np.linalg.inv(cov[:3, :2, :2]).mean(axis=0)), rtol=1e-12)
    assert decorrelate(np.zeros((0, 3, 3)), np.zeros((0, 2)), 1.0).shape == (0, 3, 3)
    with pytest.raises(ValueError, match="midpoints"):
        decorrelate(cov, mid[:3], 1.0)
    with pytest.raises(ValueError, match="radius"):
        decorrelate(cov, mid, 0.0)


def test_pair_closures_correlation_radius_inflates_the_relative_poses(scene):
    X, F, odo, T = scene
    g = fit_pose_graph(X, F, odo, refine=0, min_travel=3.0, n_outputs=4, solver="gtsam")
    i, j, xy = g.pairs.past, g.pairs.current, g.poses[:, :2]
    C = pair_relative_poses(X, F, xy, i, j, g.relative_heading, np.radians(5), correlation_radius=None)
    D = pair_relative_poses(X, F, xy, i, j, g.relative_heading, np.radians(5), correlation_radius=1.5)
    E = pair_relative_poses(X, F, xy, i, j, g.relative_heading, np.radians(5))  # the default: decorrelated
    full = C.covariance[:, 0, 0] < HEADING_ONLY_SIGMA**2 / 2
    r = CORRELATION_RADIUS
    np.testing.assert_allclose(E.covariance[full], decorrelate(C.covariance[full], 0.5 * (xy[i] + xy[j])[full], r))
    assert full.sum() > 3
    np.testing.assert_allclose(D.covariance[full], decorrelate(C.covariance[full], 0.5 * (xy[i] + xy[j])[full], 1.5))
    np.testing.assert_array_equal(D.covariance[~full], C.covariance[~full])  # heading-only ones stay
    np.testing.assert_array_equal(D.dx, C.dx)
    with pytest.raises(ValueError, match="correlation_radius"):
        pair_relative_poses(X, F, xy, i, j, g.relative_heading, np.radians(5), correlation_radius=-1.0)


def test_local_gradients_recover_a_linear_field():
    rng = np.random.default_rng(0)
    X = rng.uniform(-3, 3, (60, 2))
    G = np.array([[1.0, 0.5], [-0.3, 2.0], [0.0, 1.0]])
    F = X @ G.T + 0.2
    out = local_gradients(F, X, [0, 5, 9], n_neighbors=10)
    np.testing.assert_allclose(out, np.broadcast_to(G, (3, 3, 2)), atol=1e-9)
    line = np.c_[np.arange(20.0), np.zeros(20)]
    assert np.isnan(local_gradients(line @ G[:, :2].T, line, [3], n_neighbors=5)).all()


def test_exported_from_loopclosure():
    assert callable(relative_poses) and Measured.__name__ == "RelativePoses"


def test_bad_input_raises_clear_errors(scene):
    X, F, odo, T = scene
    with pytest.raises(ValueError, match="needs solver='gtsam'"):
        fit_pose_graph(X, F, odo, pair_closures="relative-pose")
    with pytest.raises(ValueError, match="pair_closures"):
        fit_pose_graph(X, F, odo, pair_closures="bearing", solver="gtsam")
    xy = odo[:, :2]
    with pytest.raises(ValueError, match="one length"):
        pair_relative_poses(X, F, xy, [0, 1], [20, 21], [0.0], 0.1)
    with pytest.raises(ValueError, match="positions"):
        pair_relative_poses(X, F, xy[:5], [0], [20], [0.0], 0.1)
    with pytest.raises(ValueError, match="map_distance_sigma"):
        pair_relative_poses(X, F, xy, [0], [20], [0.0], 0.1, map_distance_sigma=0.0)
    with pytest.raises(ValueError, match="compass_sigma"):
        pair_relative_poses(X, F, xy, [0], [20], [0.0], -1.0)
    with pytest.raises(ValueError, match="positions"):
        local_gradients(F, xy[:, :1], [0])
