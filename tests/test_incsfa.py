"""IncSFA (sfanav.sfa.incsfa), the online SFA peer: it recovers the slow
sources a batch SFA (scipy's generalised eigensolver) finds, slowest first;
its outputs are whitened; bad input."""

import numpy as np
import pytest
from scipy.linalg import eigh

from sfanav.sfa.incsfa import IncSFA


def mixture(n=6000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    S = np.c_[np.sin(2 * np.pi * t / 400), np.sin(2 * np.pi * t / 40 + 1.0), rng.standard_normal((n, 4))]
    A = rng.standard_normal((6, 6)) + 3 * np.eye(6)
    return S @ A.T + 5.0, S


def batch_sfa(X, J):
    C = np.cov(X.T)
    dX = np.diff(X, axis=0)
    Cd = dX.T @ dX / len(dX)
    _, W = eigh(Cd, C)
    return (X - X.mean(axis=0)) @ W[:, :J]


def test_incsfa_matches_batch_sfa_slowest_first():
    X, S = mixture()
    node = IncSFA(n_components=2, n_whitened=6)
    for _ in range(4):
        node.partial_fit(X)
    Y = node.transform(X)
    B = batch_sfa(X, 2)
    for k in range(2):  # each output is the batch feature (and the k-th source), up to sign
        assert abs(np.corrcoef(Y[:, k], B[:, k])[0, 1]) > 0.97, k
        assert abs(np.corrcoef(Y[:, k], S[:, k])[0, 1]) > 0.97, k
    assert node.delta_[0] < node.delta_[1]
    # whitened outputs: unit variance, uncorrelated (to the accuracy of a stochastic estimate)
    np.testing.assert_allclose(np.cov(Y.T), np.eye(2), atol=0.15)
    assert node.n_samples_ == 4 * len(X)


def test_incsfa_is_worse_after_one_short_pass_and_improves_with_more():
    """An approximation: its error against the batch solution shrinks with the
    passes it sees (the exact updates need one)."""
    X, _ = mixture(2000, seed=1)
    B = batch_sfa(X, 1)[:, 0]
    node = IncSFA(n_components=1, n_whitened=6)
    c = []
    for _ in range(4):
        node.partial_fit(X)
        c.append(abs(np.corrcoef(node.transform(X)[:, 0], B)[0, 1]))
    assert c[-1] > 0.95 and c[-1] >= c[0] - 1e-9, c


def test_bad_input_raises_clear_errors():
    X, _ = mixture(200)
    with pytest.raises(ValueError, match="n_whitened"):
        IncSFA(2, 8).partial_fit(X)
    with pytest.raises(ValueError, match="n_whitened"):
        IncSFA(3, 2).partial_fit(X)
    with pytest.raises(ValueError, match="at least 2 rows"):
        IncSFA(1, 2).partial_fit(X[:1])
    bad = X.copy()
    bad[5, 2] = np.nan
    with pytest.raises(ValueError, match="NaN|finite"):
        IncSFA(1, 2).partial_fit(bad)
    with pytest.raises(ValueError, match="mca_rate"):
        IncSFA(1, 2, mca_rate=2.0).partial_fit(X)
    with pytest.raises(ValueError, match="min_rate"):
        IncSFA(1, 2, min_rate=1.0).partial_fit(X)
    node = IncSFA(1, 2)
    with pytest.raises(ValueError, match="not seen enough"):
        node.transform(X)
    node.partial_fit(X)
    with pytest.raises(ValueError, match="fitted on 6"):
        node.partial_fit(X[:, :3])
    with pytest.raises(ValueError, match="fitted on 6"):
        node.transform(X[:, :3])
    with pytest.raises(TypeError):
        node.partial_fit("stream")
