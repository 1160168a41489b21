"""Property-based tests (hypothesis)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import sfanav
from conftest import correlated

settings.register_profile("ci", max_examples=25, deadline=None)
settings.load_profile("ci")


@given(n=st.integers(3, 400), d=st.integers(1, 5), cuts=st.lists(st.integers(1, 399), max_size=4), seed=st.integers(0, 10**6))
def test_any_chunking_equals_one_pass(n, d, cuts, seed):
    X = correlated(n, d, seed)
    idx = sorted({c % n for c in cuts} - {0})
    chunks = np.split(X, idx)
    whole = sfanav.Statistics(d).update(X)
    st_ = sfanav.Statistics(d)
    for c in chunks:
        st_.update(c)
    assert st_.n_pairs == n - 1
    np.testing.assert_allclose(st_.covariance(), whole.covariance(), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(st_.derivative_covariance(), whole.derivative_covariance(), rtol=1e-9, atol=1e-12)


@given(d=st.integers(1, 6), degree=st.integers(1, 3), seed=st.integers(0, 10**6))
def test_expansion_matches_monomials(d, degree, seed):
    from itertools import combinations_with_replacement

    X = np.random.default_rng(seed).standard_normal((3, d))
    cols = [
        np.prod(X[:, list(c)], axis=1)
        for k in range(1, degree + 1)
        for c in combinations_with_replacement(range(d), k)
    ]
    np.testing.assert_allclose(sfanav.expand(X, degree), np.stack(cols, axis=1), rtol=1e-12)
    assert sfanav.expanded_dim(d, degree) == len(cols)


@given(n=st.integers(30, 300), d=st.integers(2, 5), m=st.integers(1, 2), scale=st.floats(1e-6, 1e6), seed=st.integers(0, 10**6))
def test_constraints_hold_at_any_scale(n, d, m, scale, seed):
    X = correlated(n, d, seed) * scale
    model = sfanav.SFA(m).fit(X)
    y = model.transform(X)
    np.testing.assert_allclose(y.mean(axis=0), 0, atol=1e-7)
    np.testing.assert_allclose(y.T @ y / n, np.eye(m), atol=1e-7)
    assert np.all(np.diff(model.delta_values_) >= -1e-12)
