"""The DTC posterior mean (sfanav.localization.sparse_gp) and the GP and
kernel-ridge readouts that use it for runs longer than they keep."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sfanav.localization import GPReadout, KernelRidgeReadout
from sfanav.localization.sparse_gp import dtc_weights


def _k(a, b, ls=0.3):
    d2 = ((a[:, None, :] - b[None]) ** 2).sum(axis=2)
    return np.exp(-0.5 * d2 / ls**2)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(5, 80), m=st.integers(2, 30), noise=st.floats(1e-4, 1.0), chunk=st.integers(1, 50),
       seed=st.integers(0, 10**6))
def test_dtc_weights_solve_the_normal_equations(n, m, noise, chunk, seed):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, (n, 2))
    Z = rng.uniform(-1, 1, (min(m, n), 2))
    Y = rng.normal(size=(n, 2))
    w = dtc_weights(_k(Z, Z), lambda s: _k(X[s], Z), Y, noise, chunk)
    Knz, Kzz = _k(X, Z), _k(Z, Z)
    # the objective's gradient vanishes: K_zn (K_nz w - Y) + noise K_zz w = 0 (up to the jitter on K_zz)
    grad = Knz.T @ (Knz @ w - Y) + noise * Kzz @ w
    assert np.abs(grad).max() < 1e-6 * (1 + np.abs(Knz.T @ Y).max())


def test_with_every_sample_inducing_it_is_the_exact_gp():
    rng = np.random.default_rng(0)
    X = rng.uniform(-1, 1, (60, 2))
    Y = np.column_stack([np.sin(3 * X[:, 0]), np.cos(2 * X[:, 1])]) + 0.05 * rng.normal(size=(60, 2))
    K = _k(X, X)
    w = dtc_weights(K, lambda s: _k(X[s], X), Y, 0.01, chunk=7)
    exact = np.linalg.solve(K + 0.01 * np.eye(60), Y)
    np.testing.assert_allclose(K @ w, K @ exact, atol=1e-6)


def test_coinciding_inducing_points_get_jitter_not_an_error():
    X = np.linspace(0, 1, 20)[:, None]
    Z = np.vstack([X[::4], X[::4]])  # every inducing point twice: K_zz singular
    w = dtc_weights(_k(Z, Z), lambda s: _k(X[s], Z), np.sin(4 * X), 1e-3)
    assert np.all(np.isfinite(w)) and np.abs(_k(X, Z) @ w - np.sin(4 * X)).max() < 0.05


@pytest.mark.parametrize("make", [lambda mt: GPReadout(2, length_scale=[0.5, 0.5], noise=1e-2, max_train=mt),
                                  lambda mt: KernelRidgeReadout(2, gamma=2.0, alpha=1e-2, max_train=mt)])
def test_thinned_readouts_use_every_sample(make):
    """A readout keeping 40 of 400 samples: its predictions minimise the DTC
    objective over all 400 (checked through the normal equations with its own
    kernel), and they are closer to the readout keeping every sample than an
    exact fit on the 40 kept samples alone (the thinning before)."""
    rng = np.random.default_rng(3)
    X = rng.uniform(-2, 2, (400, 2))
    Y = np.column_stack([np.sin(X[:, 0]) + X[:, 1], np.cos(X[:, 1]) * X[:, 0]]) + 0.1 * rng.normal(size=(400, 2))
    keep = np.unique(np.linspace(0, 399, 40).round().astype(int))
    thinned, full, subset = make(40).fit(X, Y), make(10**6).fit(X, Y), make(10**6).fit(X[keep], Y[keep])
    T = rng.uniform(-2, 2, (200, 2))
    p_thin, p_full, p_sub = thinned.predict(T), full.predict(T), subset.predict(T)
    assert np.abs(p_thin - p_full).mean() < 0.8 * np.abs(p_sub - p_full).mean()
    assert len(thinned.X_) == 40
