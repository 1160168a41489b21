"""Behaviour of sfanav.SFA: analytic solution, constraints, reference solver, streaming."""

import numpy as np
import pytest
import scipy.linalg

import sfanav
from conftest import correlated, toy


def test_toy_problem_quadratic_sfa_recovers_sin_t():
    X, s = toy()
    y = sfanav.SFA(1, degree=2).fit_transform(X)
    assert abs(np.corrcoef(y[:, 0], s)[0, 1]) > 0.99


def test_toy_problem_linear_sfa_cannot():
    X, s = toy()
    y = sfanav.SFA(1).fit_transform(X)
    assert abs(np.corrcoef(y[:, 0], s)[0, 1]) < 0.9


@pytest.mark.parametrize(
    "params", [dict(degree=1), dict(degree=2), dict(degree=3), dict(degree=2, reduce_to=4)]
)
def test_training_outputs_satisfy_constraints(params):
    X = correlated(4000, 6, seed=2)
    m = sfanav.SFA(4, **params).fit(X)
    y = m.transform(X)
    np.testing.assert_allclose(y.mean(axis=0), 0, atol=1e-8)
    np.testing.assert_allclose(y.T @ y / len(y), np.eye(4), atol=1e-8)
    d = m.delta_values_
    assert np.all(np.diff(d) >= 0)
    np.testing.assert_allclose(np.mean(np.diff(y, axis=0) ** 2, axis=0), d, rtol=1e-8)
    np.testing.assert_allclose(m.beta_values_, np.sqrt(d) / (2 * np.pi))


def test_delta_matches_scipy_generalized_eigh():
    X = correlated(5000, 10, seed=3)
    m = sfanav.SFA(10).fit(X)
    C = np.cov(X, rowvar=False, bias=True)
    dX = np.diff(X, axis=0)
    Cdot = dX.T @ dX / len(dX)
    ref = scipy.linalg.eigh(Cdot, C, eigvals_only=True)
    np.testing.assert_allclose(m.delta_values_, ref, rtol=1e-9)


def test_solver_matches_scipy_on_random_spd():
    rng = np.random.default_rng(4)
    G, H = rng.standard_normal((2, 15, 15))
    B = G @ G.T + 0.1 * np.eye(15)
    A = H @ H.T
    vals, vecs, rank, dropped = sfanav._core.solve_generalized(A, B, 15, 1e-12)
    np.testing.assert_allclose(vals, scipy.linalg.eigh(A, B, eigvals_only=True), rtol=1e-9)
    np.testing.assert_allclose(vecs.T @ B @ vecs, np.eye(15), atol=1e-9)
    assert rank == 15 and dropped.size == 0


def test_chunked_partial_fit_equals_fit():
    X = correlated(3000, 5, seed=5)
    a = sfanav.SFA(3, degree=2).fit(X)
    b = sfanav.SFA(3, degree=2)
    for chunk in np.array_split(X, 7):
        b.partial_fit(chunk)
    np.testing.assert_allclose(b.delta_values_, a.delta_values_, rtol=1e-9)
    np.testing.assert_allclose(b.transform(X), a.transform(X), atol=1e-7)


def test_two_stage_partial_fit_equals_fit():
    X = correlated(3000, 8, seed=6)
    a = sfanav.SFA(3, degree=2, reduce_to=5).fit(X)
    b = sfanav.SFA(3, degree=2, reduce_to=5)
    for _ in range(2):
        for i, chunk in enumerate(np.array_split(X, 4)):
            b.partial_fit(chunk, new_sequence=(i == 0))
        if b._node.training_stage == 0:
            b.finish_stage()
    np.testing.assert_allclose(b.delta_values_, a.delta_values_, rtol=1e-9)
    assert a.n_passes_ == 2


def test_sequences_do_not_mix():
    X = correlated(2000, 4, seed=7)
    Y = correlated(2000, 4, seed=8) + 50.0  # a jump between the two runs
    as_list = sfanav.SFA(2).fit([X, Y])
    streamed = sfanav.SFA(2).partial_fit(X).partial_fit(Y, new_sequence=True)
    np.testing.assert_allclose(as_list.delta_values_, streamed.delta_values_, rtol=1e-10)
    glued = sfanav.SFA(2).fit(np.vstack([X, Y]))
    # The jump makes a fast derivative pair only when the runs are glued.
    assert not np.allclose(glued.delta_values_, as_list.delta_values_, rtol=1e-3)
    assert as_list.statistics_.n_pairs == 2 * 1999


def test_float32_in_float32_out_and_close_to_float64():
    X = correlated(3000, 5, seed=9)
    m64 = sfanav.SFA(3).fit(X)
    m32 = sfanav.SFA(3).fit(X.astype(np.float32))
    y = m32.transform(X.astype(np.float32))
    assert y.dtype == np.float32
    np.testing.assert_allclose(m32.delta_values_, m64.delta_values_, rtol=1e-4)


def test_strided_input_is_read_without_copy_and_correctly():
    X = correlated(4000, 12, seed=10)
    view = X[::2, ::3]  # non-contiguous
    a = sfanav.SFA(3).fit(view)
    b = sfanav.SFA(3).fit(np.ascontiguousarray(view))
    np.testing.assert_allclose(a.delta_values_, b.delta_values_, rtol=1e-12)
    np.testing.assert_allclose(a.transform(view), b.transform(view), atol=1e-10)
    fortran = np.asfortranarray(X)
    np.testing.assert_allclose(
        sfanav.SFA(3).fit(fortran).delta_values_, sfanav.SFA(3).fit(X).delta_values_, rtol=1e-10
    )


def test_large_offset_does_not_cancel():
    X = correlated(3000, 4, seed=11)
    a = sfanav.SFA(3).fit(X)
    b = sfanav.SFA(3).fit(X + 1e8)
    np.testing.assert_allclose(b.delta_values_, a.delta_values_, rtol=1e-5)


def test_rank_deficit_is_reported():
    X = correlated(2000, 3, seed=12)
    X = np.c_[X, X[:, 0] + X[:, 1], np.zeros(len(X))]  # 2 dependent columns
    m = sfanav.SFA(3).fit(X)
    assert m.rank_deficit_ == 2
    assert np.all(np.isfinite(m.transform(X)))


def test_sign_convention_is_deterministic():
    X = correlated(2000, 5, seed=13)
    a, b = sfanav.SFA(3).fit(X), sfanav.SFA(3).fit(X.copy())
    np.testing.assert_array_equal(a.transform(X), b.transform(X))


def test_fitted_attributes_and_repr():
    m = sfanav.SFA(2, degree=2, reduce_to=3)
    assert not hasattr(m, "delta_values_")
    m.fit(correlated(500, 4, seed=14))
    assert m.n_features_in_ == 4
    assert m.n_components_ == 2
    assert m.rank_deficits_ == [0, 0]
    assert repr(m) == "SFA(n_components=2, degree=2, reduce_to=3)"
    assert m.get_params()["reduce_to"] == 3


def test_expand_order_and_dim():
    X = np.array([[2.0, 3.0, 5.0]])
    np.testing.assert_array_equal(
        sfanav.expand(X, 2), [[2, 3, 5, 4, 6, 10, 9, 15, 25]]
    )
    assert sfanav.expanded_dim(23, 2) == 299
    assert sfanav.expand(np.ones((4, 10), np.float32), 3).shape == (4, 285)
    assert sfanav.expand(np.ones((4, 10), np.float32), 3).dtype == np.float32


def test_statistics_merge_equals_one_pass():
    X = correlated(5000, 6, seed=15)
    whole = sfanav.Statistics(6).update(X)
    parts = [sfanav.Statistics(6).update(c) for c in np.array_split(X, 5)]
    merged = parts[0]
    for p in parts[1:]:
        merged.merge(p, continuing=True)
    np.testing.assert_allclose(merged.covariance(), whole.covariance(), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(
        merged.derivative_covariance(), whole.derivative_covariance(), rtol=1e-10, atol=1e-12
    )
    np.testing.assert_allclose(merged.mean(), X.mean(axis=0), atol=1e-12)
    np.testing.assert_allclose(whole.covariance(), np.cov(X, rowvar=False, bias=True), rtol=1e-10, atol=1e-12)
    assert merged.n_pairs == whole.n_pairs == 4999


def test_statistics_weighted_pairs_match_repetition():
    rng = np.random.default_rng(16)
    A, B = rng.standard_normal((2, 40, 3))
    w = rng.integers(0, 4, 40).astype(float)
    st = sfanav.Statistics(3).add_pairs(A, B, w)
    rep = sfanav.Statistics(3).add_pairs(np.repeat(A, w.astype(int), 0), np.repeat(B, w.astype(int), 0))
    np.testing.assert_allclose(st.derivative_covariance(), rep.derivative_covariance(), rtol=1e-12)


def test_gil_is_released_during_fit():
    import threading
    import time

    X = correlated(200_000, 60, seed=17)
    ticks = []
    stop = threading.Event()

    def ticker():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=ticker)
    t.start()
    t0 = time.perf_counter()
    sfanav.SFA(5).fit(X)
    t1 = time.perf_counter()
    stop.set()
    t.join()
    during = [x for x in ticks if t0 < x < t1]
    # With the GIL held for the whole fit the ticker could not run at all.
    assert len(during) >= 3


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_contiguous_float_input_is_not_copied(dtype):
    import tracemalloc

    X = correlated(100_000, 25, seed=18, dtype=dtype)  # 10-20 MB
    model = sfanav.SFA(3).fit(X[:1000])
    tracemalloc.start()
    sfanav.SFA(3).fit(X)
    sfanav.Statistics(25).update(X)
    model.transform(X[:10])
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # NumPy reports its allocations to tracemalloc: a copy of X would show here.
    assert peak < X.nbytes / 20, peak


@pytest.mark.parametrize("params", [dict(), dict(degree=2, reduce_to=10), dict(degree=2, precision="mixed")])
def test_results_do_not_depend_on_the_thread_count(params):
    # bit-identical: the accumulation's partition and the solve's blocking
    # follow the data's shape, never the number of threads
    X = correlated(20_000, 30, seed=19)
    ref = sfanav.SFA(3, **params).fit(X)
    try:
        for n in (1, 2, 3):
            sfanav.set_num_threads(n)
            assert sfanav.get_num_threads() == n
            m = sfanav.SFA(3, **params).fit(X)
            np.testing.assert_array_equal(m.delta_values_, ref.delta_values_)
            np.testing.assert_array_equal(m.transform(X[:200]), ref.transform(X[:200]))
    finally:
        sfanav.set_num_threads(0)


def test_mixed_precision_close_to_double():
    X = correlated(20_000, 30, seed=20)
    a = sfanav.SFA(5).fit(X)
    b = sfanav.SFA(5, precision="mixed").fit(X)
    np.testing.assert_allclose(b.delta_values_, a.delta_values_, rtol=1e-3)
    assert not np.array_equal(b.delta_values_, a.delta_values_)
    with pytest.raises(ValueError, match="precision"):
        sfanav.SFA(5, precision="half").fit(X)
