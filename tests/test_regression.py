"""Quadratic regression from slow features to positions, and the protocols."""

import numpy as np
import pytest

import sfanav
from sfanav.localization import RANDOM_SPLITS, TEST_RUN, QuadraticRegression, error_vs_n, evaluate_random_splits, evaluate_test_run


def quadratic_map(F):
    """A known quadratic function of the first three features -> (x, y)."""
    x = 1.0 + 2.0 * F[:, 0] - 0.5 * F[:, 1] + 0.3 * F[:, 0] * F[:, 2] + 0.2 * F[:, 1] ** 2
    y = -2.0 + 0.7 * F[:, 2] + 1.5 * F[:, 0] * F[:, 1] - 0.4 * F[:, 2] ** 2
    return np.c_[x, y]


@pytest.fixture
def data():
    F = np.random.default_rng(0).normal(size=(400, 12))
    return F, quadratic_map(F)


def test_recovers_a_known_quadratic_map(data):
    F, xy = data
    for n in (3, 8, None):
        reg = QuadraticRegression(n_outputs=n).fit(F[:300], xy[:300])
        np.testing.assert_allclose(reg.predict(F[300:]), xy[300:], atol=1e-9)
        assert reg.score(F[300:], xy[300:]) < 1e-9
    reg = QuadraticRegression(n_outputs=3).fit(F, xy)
    assert reg.coef_.shape == (sfanav.expanded_dim(3, 2), 2) and reg.n_features_in_ == 12
    # coefficient of x0*x2 in x: expand's order is x0 x1 x2 x0x0 x0x1 x0x2 x1x1 x1x2 x2x2
    assert reg.coef_[5, 0] == pytest.approx(0.3) and reg.intercept_[0] == pytest.approx(1.0)
    # two outputs are not enough for this map
    assert QuadraticRegression(n_outputs=2).fit(F, xy).score(F, xy) > 0.3


def test_linear_degree_and_ridge(data):
    F, xy = data
    lin = QuadraticRegression(n_outputs=3, degree=1).fit(F, xy)
    assert lin.coef_.shape == (3, 2) and lin.score(F, xy) > 0.1
    ols = QuadraticRegression(3).fit(F, xy)
    ridge = QuadraticRegression(3, ridge=1e3).fit(F, xy)
    assert np.linalg.norm(ridge.coef_) < np.linalg.norm(ols.coef_)
    tiny = QuadraticRegression(3, ridge=1e-10).fit(F, xy)
    np.testing.assert_allclose(tiny.coef_, ols.coef_, atol=1e-8)
    # the intercept is not penalised: a huge ridge predicts the mean
    huge = QuadraticRegression(3, ridge=1e12).fit(F, xy)
    np.testing.assert_allclose(huge.predict(F[:5]), np.repeat(xy.mean(0)[None], 5, 0), atol=1e-6)


def test_regression_errors(data):
    F, xy = data
    with pytest.raises(sfanav.NotFittedError):
        QuadraticRegression().predict(F)
    with pytest.raises(ValueError, match="n_outputs=13, but features have only 12"):
        QuadraticRegression(13).fit(F, xy)
    reg = QuadraticRegression(8).fit(F, xy)
    with pytest.raises(ValueError, match="uses the first 8"):
        reg.predict(F[:, :5])
    with pytest.raises(ValueError, match="features has 400 rows but xy has 399"):
        QuadraticRegression(3).fit(F, xy[:-1])
    bad = F.copy()
    bad[7, 1] = np.inf
    with pytest.raises(ValueError, match=r"features contains NaN or infinity \(at index \(7, 1\)\)"):
        QuadraticRegression(3).fit(bad, xy)
    with pytest.raises(ValueError, match="ridge"):
        QuadraticRegression(3, ridge=-1.0).fit(F, xy)
    with pytest.raises(TypeError, match="n_outputs must be an integer"):
        QuadraticRegression(2.5).fit(F, xy)
    with pytest.raises(ValueError, match="unknown parameter"):
        QuadraticRegression().set_params(alpha=1)


def test_test_run_protocol(data):
    F, xy = data
    res = evaluate_test_run(F[:300], xy[:300], F[300:], xy[300:], n_outputs=3)
    assert res.protocol == TEST_RUN == "test-run" and "separate test run" in res.description
    assert res.metrics["med"] < 1e-9 and res.predictions.shape == (100, 2)
    assert res.metrics["n"] == 100 and res.train_metrics["n"] == 300
    assert "[test-run]" in res.summary()


def test_random_splits_protocol_is_seeded_and_labelled(data):
    F, xy = data
    noisy = xy + np.random.default_rng(1).normal(scale=0.1, size=xy.shape)
    a = evaluate_random_splits(F, noisy, n_outputs=3, n_repeats=20, random_state=7)
    b = evaluate_random_splits(F, noisy, n_outputs=3, n_repeats=20, random_state=7)
    c = evaluate_random_splits(F, noisy, n_outputs=3, n_repeats=20, random_state=8)
    assert a.metrics == b.metrics and a.metrics != c.metrics
    assert a.protocol == RANDOM_SPLITS == "random-splits" and a.n_repeats == 20
    assert "50/50" in a.description and "optimistic" in a.description and "seed 7" in a.description
    assert a.metrics_std is not None and a.metrics_std["med"] > 0
    assert a.metrics["n"] == 200
    # averaged held-out predictions; noise of 0.1 per axis -> MED about 0.125
    assert 0.08 < a.metrics["med"] < 0.2
    assert np.isfinite(a.predictions).all()  # 20 repeats cover every sample (almost surely)
    one = evaluate_random_splits(F, noisy, n_outputs=3, n_repeats=1)
    assert np.isnan(one.predictions[:, 0]).sum() == 200  # half never in a test half
    with pytest.raises(ValueError, match="test_fraction"):
        evaluate_random_splits(F, noisy, test_fraction=1.0)


def test_error_vs_n_finds_the_informative_outputs():
    rng = np.random.default_rng(3)
    F = rng.normal(size=(160, 12))
    xy = quadratic_map(F[:, [0, 2, 3]]) + rng.normal(scale=0.05, size=(160, 2))  # needs s1..s4
    curve = error_vs_n(F[:70], xy[:70], F[70:], xy[70:])
    assert curve.protocol == TEST_RUN
    np.testing.assert_array_equal(curve.ns, np.arange(2, 13))
    assert curve.best_n in (4, 5), curve.test_error
    assert np.all(np.diff(curve.train_error) <= 1e-12)  # nested models: training error never rises
    assert curve.test_error[-1] > 3 * curve.test_error[2]  # n = 12 overfits 70 samples (91 terms)
    splits = error_vs_n(F, xy, ns=[2, 4, 8], n_repeats=10, random_state=0)
    assert splits.protocol == RANDOM_SPLITS and splits.best_n == 4 and splits.test_error_std.shape == (3,)


def test_error_vs_n_errors(data):
    F, xy = data
    with pytest.raises(ValueError, match="ns goes up to 13"):
        error_vs_n(F, xy, F, xy, ns=range(2, 14))
    with pytest.raises(ValueError, match="both features_test and xy_test"):
        error_vs_n(F, xy, F)
    with pytest.raises(ValueError, match="ns is empty"):
        error_vs_n(F, xy, F, xy, ns=[])
    with pytest.raises(ValueError, match="features_test has only 5"):
        error_vs_n(F, xy, F[:, :5], xy, ns=[2, 8])
