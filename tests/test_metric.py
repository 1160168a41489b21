"""Unsupervised metric learning (thesis 5.3.1): costs, gradients, solvers."""

import numpy as np
import pytest

import sfanav
from sfanav import MetricLearner, expand
from sfanav.experiments_odometry import make_line_problem, synthetic_features
from sfanav.metric import metric_cost, plot_metric_lines
from sfanav.metrics import align, med
from sfanav.odometry import lines_from_labels


@pytest.fixture(scope="module")
def problem():
    """10 random lines of at least 8 m in 16 x 18 m, every 0.2 m, noise-free features."""
    return make_line_problem(noise=0.0, random_state=0)


@pytest.fixture(scope="module")
def small():
    """A small random problem for finite differences: 5 lines, 3 outputs."""
    rng = np.random.default_rng(3)
    lab = np.repeat(np.arange(5), 12)
    d = np.tile(np.arange(12) * 0.3, 5)
    F = rng.normal(size=(len(lab), 3))
    Phi = np.hstack([np.ones((len(F), 1)), expand(F, 2)])
    theta = (rng.uniform(0, 6, 5), rng.normal(size=(5, 2)), 0.3 * rng.normal(size=(Phi.shape[1], 2)))
    return Phi, lab, d, rng.uniform(-3, 3, 4), theta


@pytest.mark.parametrize("angle_term", [None, "cos", "signed"])
def test_gradients_match_finite_differences(small, angle_term):
    Phi, lab, d, phi, theta = small
    c, grads = metric_cost(*theta, Phi, lab, d, phi, angle_term=angle_term, angle_weight=2.5, ridge=0.7)
    h = 1e-6
    for b, (param, g) in enumerate(zip(theta, grads)):
        num = np.zeros_like(param)
        for idx in np.ndindex(param.shape):
            plus = [t.copy() for t in theta]
            minus = [t.copy() for t in theta]
            plus[b][idx] += h
            minus[b][idx] -= h
            cp = metric_cost(*plus, Phi, lab, d, phi, angle_term=angle_term, angle_weight=2.5, ridge=0.7)[0]
            cm = metric_cost(*minus, Phi, lab, d, phi, angle_term=angle_term, angle_weight=2.5, ridge=0.7)[0]
            num[idx] = (cp - cm) / (2 * h)
        np.testing.assert_allclose(g, num, rtol=1e-6, atol=1e-6 * np.abs(num).max())


def test_thesis_angle_gradient_needs_the_last_line_case(small):
    """(5.6) as printed: 'if n = 1' one term, 'otherwise' both; the last line has
    no successor, so only the predecessor term applies there (a slip)."""
    Phi, lab, d, phi, (a, O, W) = small
    g_with = metric_cost(a, O, W, Phi, lab, d, phi, angle_term="cos")[1][0]
    g_without = metric_cost(a, O, W, Phi, lab, d, phi, angle_term=None)[1][0]
    extra = g_with - g_without
    cphi = np.cos(phi)
    n = len(a) - 1
    # the predecessor term of (5.6) alone at the last line
    want_last = np.sin(a[n - 1] - a[n]) * (np.cos(a[n - 1] - a[n]) - cphi[n - 1])
    assert extra[n] == pytest.approx(want_last)
    # the first-line case of (5.6)
    want_first = np.sin(a[0] - a[1]) * (cphi[0] - np.cos(a[0] - a[1]))
    assert extra[0] == pytest.approx(want_first)
    # (5.2) read as the row vector (sin a, -cos a) times (W^T s - o)
    R = Phi @ W - O[lab]
    want = np.bincount(lab, d * (np.sin(a)[lab] * R[:, 0] - np.cos(a)[lab] * R[:, 1]))
    np.testing.assert_allclose(g_without, want, rtol=1e-10)


def test_recovers_a_known_linear_map(problem):
    F, xy, lines = problem["features"], problem["xy"], problem["lines"]
    m = MetricLearner(angle_term=None, n_init=3, random_state=0).fit(F, lines, progress=False)
    assert m.weights_.shape == (45, 2) and m.coef_.shape == (44, 2) and m.intercept_.shape == (2,)
    assert m.cost_ < 1e-8 and m.converged_
    P = m.transform(F)
    al = align(P, xy, allow_reflection=True)
    assert al.rmse < 1e-4  # positions up to a rigid motion (and mirror)
    # line orientations up to the same rotation/mirror: relative angles are recovered
    sgn = np.sign(np.linalg.det(al.rotation))
    rel = np.angle(np.exp(1j * (sgn * np.diff(m.alpha_) - np.diff(problem["alpha"]))))
    np.testing.assert_allclose(rel, 0, atol=1e-5)
    # new positions of the same area map correctly too (not only the training lines)
    grid = np.random.default_rng(1).uniform([1, 1], [15, 17], (200, 2))
    np.testing.assert_allclose(al.apply(m.transform(synthetic_features(grid))), grid, atol=1e-3)


def test_solvers_reach_the_same_cost():
    prob = make_line_problem(noise=0.02, random_state=0)
    F, lines, xy = prob["features"], prob["lines"], prob["xy"]
    vp = MetricLearner(angle_term=None, n_init=3, random_state=0).fit(F, lines, progress=False)
    # from the varpro solution's orientations, perturbed, the full L-BFGS and the thesis's GD agree
    start = {"alpha": vp.alpha_ + 0.05, "origins": vp.origins_, "weights": vp.weights_}
    lb = MetricLearner(angle_term=None, solver="lbfgs", init=start, tol=1e-12, max_iter=3000).fit(
        F, lines, progress=False)
    gd = MetricLearner(angle_term=None, solver="gd", init=start, learning_rate=5e-5, max_iter=3000,
                       tol=1e-10).fit(F, lines, progress=False)
    # preconditioned gradient descent from the same random start as varpro
    pre = MetricLearner(angle_term=None, solver="gd", precondition=True, random_state=0).fit(F, lines, progress=False)
    assert lb.cost_ == pytest.approx(vp.cost_, rel=1e-4)
    assert gd.cost_ == pytest.approx(vp.cost_, rel=2e-2)
    assert pre.cost_ == pytest.approx(vp.cost_, rel=1e-3) and pre.converged_ and pre.n_iter_ < 3000
    assert gd.cost_history_[0] > gd.cost_history_[-1] and len(gd.cost_history_) == gd.n_iter_ + 1
    for m in (vp, lb, gd, pre):
        assert m.fit_time_ > 0 and m.n_iter_ > 0
        P = m.transform(F)
        assert med(align(P, xy, allow_reflection=True).apply(P), xy) < 0.5


def test_gd_defaults_snapshots_and_plot(problem, tmp_path):
    F, lines = problem["features"], problem["lines"]
    m = MetricLearner(solver="gd", angle_term=None, max_iter=120, snapshot_iterations=(0, 50, 100), random_state=1)
    m.fit(F, lines, progress=False)
    assert m.learning_rate_ == 1e-5 and m.momentum == 0.95
    assert sorted(m.snapshots_) == [0, 50, 100, 120] and not m.converged_ and m.n_iter_ == 120
    assert m.cost_history_[-1] < 0.1 * m.cost_history_[0]
    png = plot_metric_lines(m, F, tmp_path / "lines.png", iterations=(0, 50, 120))
    assert png.exists() and png.stat().st_size > 1000
    with pytest.raises(ValueError, match="no snapshot at iteration"):
        plot_metric_lines(m, F, tmp_path / "x.png", iterations=(7,))
    # diverging learning rate: a clear error
    with pytest.raises(FloatingPointError, match="lower learning_rate"):
        MetricLearner(solver="gd", angle_term=None, learning_rate=1.0, max_iter=50).fit(F, lines, progress=False)


def test_fixed_parameters_and_odometry_init(problem):
    F, lines = problem["features"], problem["lines"]
    m = MetricLearner(angle_term=None, fix_alpha={0: 0.3}, fix_origin={0: (1.0, 2.0)}, n_init=3,
                      random_state=0).fit(F, lines, progress=False)
    assert m.alpha_[0] == 0.3 and np.allclose(m.origins_[0], (1.0, 2.0)) and m.cost_ < 1e-8
    # the frame is now pinned to line 0: its samples map onto the fixed line
    on0 = lines.labels == 0
    want = np.array([1.0, 2.0]) + lines.distances[on0, None] * np.array([np.cos(0.3), np.sin(0.3)])
    np.testing.assert_allclose(m.transform(F[on0]), want, atol=1e-4)
    for solver in ("gd", "lbfgs"):
        g = MetricLearner(solver=solver, angle_term=None, fix_alpha={0: 0.3}, fix_origin={0: (1.0, 2.0)},
                          max_iter=20, random_state=0).fit(F, lines, progress=False)
        assert g.alpha_[0] == 0.3 and np.allclose(g.origins_[0], (1.0, 2.0))
    # initialisation from odometry headings and origins (here: the truth)
    true_lines = lines_from_labels(lines.labels, lines.distances, lines.relative_angles,
                                   headings=problem["alpha"], origins=problem["xy"][
                                       [np.flatnonzero(lines.labels == n)[0] for n in range(lines.n_lines)]])
    o = MetricLearner(init="odometry", solver="gd", max_iter=5).fit(F, true_lines, progress=False)
    assert o.cost_history_[0] < 1e-6  # already at the solution
    np.testing.assert_allclose(o.transform(F), problem["xy"], atol=1e-3)


def test_save_and_load(problem, tmp_path):
    F, lines = problem["features"], problem["lines"]
    m = MetricLearner(angle_term=None, fix_alpha={0: 0.0}, random_state=0).fit(F, lines, progress=False)
    path = m.save(tmp_path / "metric.sfa")
    back = sfanav.load(path)
    assert isinstance(back, MetricLearner) and back.fix_alpha == {0: 0.0}
    np.testing.assert_allclose(back.transform(F), m.transform(F))
    assert back.n_iter_ == m.n_iter_ and back.cost_ == m.cost_ and back.lines_.n_lines == lines.n_lines
    np.testing.assert_allclose(back.line_points(), m.line_points())


def test_bad_inputs(problem):
    F, lines = problem["features"], problem["lines"]
    with pytest.raises(sfanav.NotFittedError):
        MetricLearner().transform(F)
    with pytest.raises(ValueError, match="rows but the odometry/lines have"):
        MetricLearner().fit(F[:-1], lines, progress=False)
    with pytest.raises(ValueError, match="no line found"):
        MetricLearner().fit(F[:20], np.zeros((20, 3)), progress=False)
    few = lines_from_labels(np.r_[np.zeros(10, int), np.ones(10, int)], np.r_[np.arange(10.0), np.arange(10.0)])
    with pytest.raises(ValueError, match="too few points on lines"):
        MetricLearner().fit(F[:20], few, progress=False)
    with pytest.raises(ValueError, match="only 3 columns"):
        MetricLearner(n_outputs=8).fit(F[:, :3], lines, progress=False)
    with pytest.raises(ValueError, match="needs the measured relative angles"):
        MetricLearner(angle_term="cos").fit(F, lines_from_labels(lines.labels, lines.distances), progress=False)
    with pytest.raises(ValueError, match="needs the odometry headings"):
        MetricLearner(init="odometry").fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="only 10 lines"):
        MetricLearner(fix_alpha={12: 0.0}).fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="solver must be"):
        MetricLearner(solver="adam").fit(F, lines, progress=False)
    with pytest.raises(TypeError, match="fix_origin must be a mapping"):
        MetricLearner(fix_origin=[(0, 0)]).fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="odometry must be poses"):
        MetricLearner().fit(F, np.zeros((len(F), 2)), progress=False)
    m = MetricLearner(angle_term=None, random_state=0).fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="fitted with 8"):
        m.transform(F[:, :5])


def test_fit_on_odometry_poses_segments_them():
    from sfanav.experiments_odometry import make_odometry_run
    from sfanav.odometry import segment_lines

    run = make_odometry_run(n_legs=10, random_state=4)
    seg = {"min_points": 12}
    a = MetricLearner(init="odometry", segmentation=seg).fit(run["features"], run["odometry"], progress=False)
    b = MetricLearner(init="odometry").fit(run["features"], segment_lines(run["odometry"], **seg), progress=False)
    assert a.lines_.n_lines == b.lines_.n_lines and a.angle_term_ == "cos"
    np.testing.assert_allclose(a.transform(run["features"]), b.transform(run["features"]))
    # learned from odometry alone, the map is metric: after a rigid alignment it matches the truth
    P = a.transform(run["features"])
    assert med(align(P, run["xy"], allow_reflection=True).apply(P), run["xy"]) < 0.3


def test_varpro_is_a_minimum_of_the_full_cost_with_ridge_and_fixed_origin(problem):
    """The eliminated origins and W are optimal: L-BFGS on all parameters, started
    at the varpro solution, finds nothing lower (ridge and a fixed origin included)."""
    F, lines = problem["features"], problem["lines"]
    kw = dict(angle_term=None, ridge=0.5, fix_origin={2: (3.0, -1.0)})
    vp = MetricLearner(n_init=2, random_state=0, **kw).fit(F, lines, progress=False)
    lb = MetricLearner(solver="lbfgs", init={"alpha": vp.alpha_, "origins": vp.origins_, "weights": vp.weights_},
                       tol=1e-14, max_iter=500, **kw).fit(F, lines, progress=False)
    assert np.allclose(vp.origins_[2], (3.0, -1.0)) and vp.cost_ > 1.0  # the ridge costs something
    assert lb.cost_ == pytest.approx(vp.cost_, rel=1e-7)
