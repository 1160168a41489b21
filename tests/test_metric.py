"""Unsupervised metric learning (thesis 5.3.1): costs, gradients, solvers."""

import numpy as np
import pytest

import sfanav
from sfanav import MetricLearner, expand
from sfanav.experiments.synthetic_odometry import make_line_problem, synthetic_features
from sfanav.odometry import metric_cost, plot_metric_lines
from sfanav.localization import align, med
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
    from sfanav.experiments.synthetic_odometry import make_odometry_run
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


# ----------------------------------------------------------------- odometry between lines (beyond the thesis)


@pytest.mark.parametrize("angle_term", [None, "cos", "signed"])
def test_transit_term_gradients_match_finite_differences(small, angle_term):
    """The transit term t_n = o_{n+1} - o_n - q_x u(alpha_n) - q_y u'(alpha_n) with
    per-pair weights, and per-pair angle weights."""
    Phi, lab, d, phi, theta = small
    rng = np.random.default_rng(7)
    kw = dict(angle_term=angle_term, angle_weight=rng.uniform(0.5, 3, 4), ridge=0.3,
              transits=rng.normal(size=(4, 2)), transit_weight=rng.uniform(0.5, 3, 4))
    c, grads = metric_cost(*theta, Phi, lab, d, phi, **kw)
    # the term itself, directly
    a, O, _ = theta
    q, w = kw["transits"], kw["transit_weight"]
    t = O[1:] - O[:-1] - q[:, :1] * np.c_[np.cos(a), np.sin(a)][:-1] - q[:, 1:] * np.c_[-np.sin(a), np.cos(a)][:-1]
    c0 = metric_cost(*theta, Phi, lab, d, phi, **{**kw, "transit_weight": 0.0})[0]
    assert c - c0 == pytest.approx(0.5 * np.sum(w * (t**2).sum(1)))
    h = 1e-6
    for b, (param, g) in enumerate(zip(theta, grads)):
        num = np.zeros_like(param)
        for idx in np.ndindex(param.shape):
            plus = [x.copy() for x in theta]
            minus = [x.copy() for x in theta]
            plus[b][idx] += h
            minus[b][idx] -= h
            num[idx] = (metric_cost(*plus, Phi, lab, d, phi, **kw)[0] - metric_cost(*minus, Phi, lab, d, phi, **kw)[0]) / (2 * h)
        np.testing.assert_allclose(g, num, rtol=1e-6, atol=1e-6 * np.abs(num).max())


@pytest.fixture(scope="module")
def odo_run():
    from sfanav.experiments.synthetic_odometry import make_odometry_run

    return make_odometry_run(n_legs=14, random_state=2)


def test_varpro_with_transits_is_a_minimum_of_the_full_cost(odo_run):
    """Variable projection with the transit term (which couples x and y through
    the lateral displacement) and a fixed origin: L-BFGS on all parameters from
    its solution finds nothing lower, and its solution does not depend on the gauge."""
    from sfanav.odometry import segment_lines

    lines = segment_lines(odo_run["odometry"])
    F = odo_run["features"]
    kw = dict(angle_term="signed", angle_weight=2.0, transit_weight=30.0, init="odometry")
    vp = MetricLearner(**kw).fit(F, lines, progress=False)
    assert vp.transit_weights_.shape == (lines.n_lines - 1,) and np.all(vp.transit_weights_ == 30.0)
    lb = MetricLearner(**{**kw, "init": {"alpha": vp.alpha_, "origins": vp.origins_, "weights": vp.weights_}},
                       solver="lbfgs", tol=1e-15, max_iter=2000).fit(F, lines, progress=False)
    assert lb.cost_ == pytest.approx(vp.cost_, rel=1e-7)
    # from a perturbed start, the full L-BFGS comes down to the same minimum
    lb2 = MetricLearner(**{**kw, "init": {"alpha": vp.alpha_ + 0.02, "origins": vp.origins_ + 0.05,
                                          "weights": vp.weights_}},
                        solver="lbfgs", tol=1e-15, max_iter=5000).fit(F, lines, progress=False)
    assert lb2.cost_ == pytest.approx(vp.cost_, rel=1e-5)
    fixed = MetricLearner(**kw, fix_origin={3: (1.0, -2.0)}, fix_alpha={3: 0.5}).fit(F, lines, progress=False)
    assert fixed.cost_ == pytest.approx(vp.cost_, rel=1e-7) and np.allclose(fixed.origins_[3], (1.0, -2.0))
    P, Q = vp.transform(F), fixed.transform(F)
    assert align(Q, P).rmse < 1e-4  # the same map up to a rigid motion (no mirror: signed angles, transits)


def test_odometry_variances_follow_the_noise_model():
    from sfanav.odometry import DEFAULT_ODOMETRY_NOISE, odometry_variances
    from sfanav.odometry import lines_from_odometry

    # two lines along x (1 m each, 11 samples), a turn on the spot by pi between them, no drive
    P = np.zeros((24, 3))
    P[:11, 0] = np.arange(11) * 0.1
    P[11, :] = (1.0, 0.0, np.pi / 2)
    P[12:, 0] = 1.0 - np.arange(12) * 0.1 / 1.0
    P[12:, 2] = np.pi
    P[12:13, 0] = 1.0
    lines = lines_from_odometry(np.r_[np.zeros(11, int), -1, np.ones(12, int)], P)
    assert lines.n_lines == 2 and lines.transit_lengths[0] == pytest.approx(0.0)
    assert lines.transit_turns[0] == pytest.approx(np.pi)
    assert lines.relative_angles[0] == pytest.approx(np.pi)
    np.testing.assert_allclose(lines.transits(), [[1.0, 0.0]], atol=1e-12)  # line 1 starts 1 m ahead of line 0
    var_a, var_t = odometry_variances(lines, {"distance_sigma": 0.02, "heading_sigma": 0.0, "turn_sigma": 0.1})
    S = lines.path_lengths()
    np.testing.assert_allclose(S, [1.0, 1.1])
    assert var_a[0] == pytest.approx(0.01 * np.pi)
    # transit displacement from the end of line 0 (x = 1) to the start of line 1 (x = 1): zero, so only distance
    assert var_t[0] == pytest.approx(0.5 * 0.02**2 * (1.0 / 3 + 1.1 / 3))
    # defaults and the simulator's noise object
    from sfanav.sim import OdometryNoise

    np.testing.assert_allclose(odometry_variances(lines)[0], odometry_variances(lines, OdometryNoise())[0])
    assert DEFAULT_ODOMETRY_NOISE["turn_sigma"] == OdometryNoise().turn_sigma
    with pytest.raises(ValueError, match="needs the transits"):
        odometry_variances(lines_from_labels(lines.labels, lines.distances))
    with pytest.raises(ValueError, match="heading_sigma"):
        odometry_variances(lines, {"heading_sigma": -1.0})
    with pytest.raises(TypeError, match="odometry_noise must be a mapping"):
        odometry_variances(lines, 0.1)


@pytest.fixture(scope="module")
def lanes():
    """The 5.3.1-real situation on synthetic features: serpentine lanes 0.4 m apart with
    turns on the spot (along x, then along y), the simulator's odometry noise, and
    features of a smoothly warped position plus noise (no exact quadratic map)."""
    from sfanav.sim import OdometryNoise, simulate_odometry
    from sfanav.sim import trajectories as T
    from sfanav.odometry import segment_lines

    P = np.asarray(T.grid((4.0, 4.0), spacing=0.4, step=0.03, turn="spot", margin=0.3).poses)
    xy = P[:, :2]
    odo = simulate_odometry(P, OdometryNoise(), 0)
    warped = xy + 0.1 * np.c_[np.sin(2.1 * xy[:, 1] + 0.3), np.sin(1.7 * xy[:, 0] + 1.0)]
    F = synthetic_features(warped + 2.0, area=(4.0, 4.0), noise=0.05, random_state=1)
    return F, xy, segment_lines(odo)


def test_noise_weighted_cost_does_not_bend_where_the_thesis_cost_does(lanes):
    from sfanav.localization import QuadraticRegression

    F, xy, lines = lanes
    on = lines.mask
    assert lines.n_lines == 18 and lines.transit_lengths is not None

    def aligned_med(m):
        P = m.transform(F[on])
        return med(align(P, xy[on], allow_reflection=True).apply(P), xy[on])

    sup = QuadraticRegression(8).fit(F[on], xy[on]).score(F[on], xy[on])
    thesis = MetricLearner(init="odometry", angle_term="cos").fit(F, lines, progress=False)
    ml = MetricLearner(init="odometry", angle_weight="noise", transit_weight="noise").fit(F, lines, progress=False)
    # the thesis's cost (5.5) at its minimum bends the lanes; the likelihood with the odometry between them does not
    assert aligned_med(thesis) > 3 * sup
    assert aligned_med(ml) < 1.2 * sup
    assert ml.angle_term_ == "signed" and ml.noise_iterations_ > 1
    # sigma_f is the ML estimate: the residual variance of the final fit (per coordinate, dof-corrected)
    R = ml.line_points()[on] - ml.transform(F[on])
    n_par = 3 * lines.n_lines + 2 * ml.weights_.shape[0]
    assert ml.feature_noise_ == pytest.approx(np.sqrt((R**2).sum() / (2 * on.sum() - n_par)), rel=2e-3)
    from sfanav.odometry import odometry_variances

    var_a, var_t = odometry_variances(lines)
    np.testing.assert_allclose(ml.angle_weights_, ml.feature_noise_**2 / var_a, rtol=1e-12)
    np.testing.assert_allclose(ml.transit_weights_, ml.feature_noise_**2 / var_t, rtol=1e-12)
    # a given sigma_f: one fit, those weights
    fixed = MetricLearner(init="odometry", angle_weight="noise", transit_weight="noise",
                          feature_noise=0.05).fit(F, lines, progress=False)
    assert fixed.noise_iterations_ == 1 and fixed.feature_noise_ == 0.05
    np.testing.assert_allclose(fixed.transit_weights_, 0.05**2 / var_t)
    # the weights are plain numbers in the model file
    assert aligned_med(ml) == pytest.approx(aligned_med(sfanav.load(ml.save(
        __import__("tempfile").mkdtemp() + "/m.sfa"))))


def test_noise_weights_bad_inputs(problem, lanes):
    F, lines = problem["features"], problem["lines"]
    with pytest.raises(ValueError, match="angle_weight must be a number"):
        MetricLearner(angle_weight="ml").fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="transit_weight must be a number"):
        MetricLearner(transit_weight="likelihood").fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="transit_weight needs the odometry origins"):
        MetricLearner(transit_weight=1.0).fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="needs the transits"):
        MetricLearner(angle_weight="noise").fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="feature_noise must be > 0"):
        MetricLearner(angle_weight="noise", feature_noise=0.0).fit(F, lines, progress=False)
    Fl, _, ll = lanes
    with pytest.raises(TypeError, match="odometry_noise must be a mapping"):
        MetricLearner(init="odometry", angle_weight="noise", odometry_noise=[0.01]).fit(Fl, ll, progress=False)


def test_heading_drift_is_estimated_and_removed(odo_run):
    """A systematic heading drift (0.002 rad per 4 cm step = 0.05 rad/m) biases every
    measured heading change; heading_drift='estimate' recovers it and the map improves."""
    from sfanav.experiments.synthetic_odometry import make_odometry_run
    from sfanav.odometry.metric_cost import LineProblem as _Problem, VarPro as _VarPro
    from sfanav.odometry import segment_lines

    run = make_odometry_run(n_legs=14, random_state=0)  # heading_bias 0.002 rad per moving step
    lines = segment_lines(run["odometry"])
    on = lines.mask
    F, xy = run["features"], run["xy"]

    def aligned_med(m):
        P = m.transform(F[on])
        return med(align(P, xy[on], allow_reflection=True).apply(P), xy[on])

    kw = dict(init="odometry", angle_weight="noise", transit_weight="noise")
    plain = MetricLearner(**kw).fit(F, lines, progress=False)
    est = MetricLearner(**kw, heading_drift="estimate").fit(F, lines, progress=False)
    known = MetricLearner(**kw, heading_drift=0.05).fit(F, lines, progress=False)
    assert plain.heading_drift_ == 0.0 and known.heading_drift_ == 0.05
    assert 0.04 < est.heading_drift_ < 0.06
    assert aligned_med(est) < 0.6 * aligned_med(plain) and aligned_med(known) < 0.6 * aligned_med(plain)
    # the estimate is a stationary point in the drift too: d cost / d drift = 0 there (finite differences)
    S = lines.path_lengths()
    p = S[:-1] / 2 + lines.transit_lengths + S[1:] / 2
    Phi = est._design(F[on], 8, 2)

    def cost(drift):
        pb = _Problem(Phi, lines.labels[on], lines.distances[on], lines.relative_angles, "signed", est.angle_weights_,
                      {}, {}, 0.0, lines.transits(), est.transit_weights_, p, drift)
        vp = _VarPro(pb)
        return vp.cost(est.alpha_)[0], vp.drift_gradient(est.alpha_), pb

    c0, g0, pb = cost(est.heading_drift_)
    assert c0 == pytest.approx(est.cost_, rel=1e-9) and c0 == pytest.approx(pb.cost(est.alpha_, est.origins_, est.weights_)[0])
    h = 1e-6
    g_num = (cost(0.03 + h)[0] - cost(0.03 - h)[0]) / (2 * h)
    assert cost(0.03)[1] == pytest.approx(g_num, rel=1e-6)
    assert abs(g0) < 1e-3 * abs(g_num)
    with pytest.raises(ValueError, match="needs solver='varpro'"):
        MetricLearner(**kw, heading_drift="estimate", solver="lbfgs").fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="needs angle_term='signed'"):
        MetricLearner(**kw, heading_drift="estimate", angle_term="cos").fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="heading_drift must be a number"):
        MetricLearner(**kw, heading_drift="auto").fit(F, lines, progress=False)
    with pytest.raises(ValueError, match="heading_drift must be finite"):
        MetricLearner(**kw, heading_drift=float("nan")).fit(F, lines, progress=False)
    bare = lines_from_labels(lines.labels, lines.distances, lines.relative_angles)
    with pytest.raises(ValueError, match="heading_drift needs the transits"):
        MetricLearner(angle_term="signed", heading_drift=0.01).fit(F, bare, progress=False)
