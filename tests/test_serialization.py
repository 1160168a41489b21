"""Models and accumulators as bytes (``to_bytes`` / ``from_bytes``, and
pickle through them): exact round trips, checked bytes, and statistics
accumulated in other processes that merge to the single-process result."""

import multiprocessing
import pickle
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sfanav import SFA, Network, Rotation
from sfanav.sfa import Statistics

TINY = {
    "input": {"width": 60, "height": 8, "channels": 3},
    "network": {"precision": "double"},
    "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 6}, {"rf": "full", "out": 5}],
}


def _series(seed, n=60, d=4):
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(size=(n, d)), axis=0)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 40), d=st.integers(1, 6), split=st.floats(0.1, 0.9))
def test_statistics_round_trip_and_merge_equal_the_originals(seed, n, d, split):
    X = _series(seed, n, d)
    k = max(1, min(n - 1, int(split * n)))
    a = Statistics(d).update(X[:k])
    b = Statistics(d).update(X[k:])
    a2 = Statistics.from_bytes(a.to_bytes())
    b2 = pickle.loads(pickle.dumps(b))
    assert a2.get_state().keys() == a.get_state().keys()
    for key, v in a.get_state().items():
        np.testing.assert_array_equal(a2.get_state()[key], v)
    whole = Statistics(d).update(X)
    merged = a2.merge(b2, continuing=True)
    assert merged.n_samples == whole.n_samples and merged.n_pairs == whole.n_pairs
    np.testing.assert_allclose(merged.covariance(), whole.covariance(), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(merged.derivative_covariance(), whole.derivative_covariance(), rtol=1e-9, atol=1e-12)


def _partial(args):
    """A worker's share: statistics of its chunk of one long sequence, as bytes."""
    seed, lo, hi = args
    return Statistics(4).update(_series(seed, 300)[lo:hi]).to_bytes()


def test_statistics_from_other_processes_merge_to_the_single_process_result():
    bounds = [(0, 70), (70, 180), (180, 300)]
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(2, mp_context=ctx) as pool:
        parts = [Statistics.from_bytes(b) for b in pool.map(_partial, [(5, lo, hi) for lo, hi in bounds])]
    merged = parts[0]
    for p in parts[1:]:
        merged.merge(p, continuing=True)  # the chunks continue one sequence
    whole = Statistics(4).update(_series(5, 300))
    assert merged.n_pairs == whole.n_pairs == 299
    np.testing.assert_allclose(merged.covariance(), whole.covariance(), rtol=1e-12)
    np.testing.assert_allclose(merged.derivative_covariance(), whole.derivative_covariance(), rtol=1e-12)
    # without continuing, the pairs across the chunk boundaries are (correctly) missing
    apart = Statistics.from_bytes(_partial((5, 0, 70))).merge(Statistics.from_bytes(_partial((5, 70, 300))))
    assert apart.n_pairs == 298


def test_a_fitted_network_round_trips_exactly():
    rng = np.random.default_rng(0)
    images = rng.integers(0, 255, size=(12, 8, 60, 3), dtype=np.uint8)
    net = Network(TINY).fit(images, Rotation(step=10), progress=False)
    for copy in (Network.from_bytes(net.to_bytes()), pickle.loads(pickle.dumps(net))):
        assert copy.is_fitted_
        np.testing.assert_array_equal(copy.transform(images), net.transform(images))
    unfitted = pickle.loads(pickle.dumps(Network(TINY)))
    assert not unfitted.is_fitted_ and unfitted.config_ == Network(TINY).config_


def test_sfa_round_trips_with_its_statistics():
    X = _series(1, 200, 5)
    sfa = SFA(n_components=3).partial_fit(X[:100])
    copy = pickle.loads(pickle.dumps(sfa))
    sfa.partial_fit(X[100:])
    copy.partial_fit(X[100:])
    np.testing.assert_allclose(copy.transform(X), sfa.transform(X), rtol=1e-10, atol=1e-12)


def test_bad_bytes_are_refused_with_a_clear_error():
    data = Statistics(2).update(_series(0, 10, 2)).to_bytes()
    with pytest.raises(ValueError, match="hold a Statistics model, not a Network"):
        Network.from_bytes(data)
    with pytest.raises(ValueError, match="not a valid sfanav model"):
        Statistics.from_bytes(data[: len(data) // 2])
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0xFF
    with pytest.raises(ValueError, match="not a valid sfanav model|altered"):
        Statistics.from_bytes(bytes(flipped))
    with pytest.raises(TypeError, match="bytes"):
        Statistics.from_bytes("not bytes")
