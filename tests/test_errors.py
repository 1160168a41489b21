"""Bad input raises a clear ValueError/TypeError, never a panic or a NaN."""

import numpy as np
import pytest

import sfanav
from conftest import correlated


@pytest.fixture
def fitted():
    return sfanav.SFA(2).fit(correlated(500, 4, seed=1))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_training_data(bad):
    X = correlated(100, 3)
    X[17, 2] = bad
    with pytest.raises(ValueError, match=r"NaN or infinity .*row 17, column 2"):
        sfanav.SFA(2).fit(X)


def test_non_finite_transform_data(fitted):
    X = correlated(10, 4)
    X[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        fitted.transform(X)


@pytest.mark.parametrize("shape", [(10,), (2, 3, 4), ()])
def test_wrong_ndim(shape):
    with pytest.raises(ValueError, match="2-D"):
        sfanav.SFA(1).fit(np.ones(shape))


def test_too_few_samples():
    with pytest.raises(ValueError, match="at least 2 samples"):
        sfanav.SFA(1).fit(np.ones((1, 3)))


def test_transform_before_fit():
    with pytest.raises(sfanav.NotFittedError, match="not fitted"):
        sfanav.SFA(1).transform(np.ones((3, 2)))
    assert issubclass(sfanav.NotFittedError, ValueError)


def test_feature_count_mismatch(fitted):
    with pytest.raises(ValueError, match="3 features, but this SFA was fitted with 4"):
        fitted.transform(np.ones((5, 3)))
    with pytest.raises(ValueError, match="number of features"):
        fitted.partial_fit(np.ones((5, 3)))


def test_singular_beyond_tolerance():
    X = np.tile(correlated(300, 1), (1, 4))  # four copies of one signal: rank 1
    with pytest.raises(ValueError, match="singular problem.*only 1 of 4 directions"):
        sfanav.SFA(2).fit(X)
    with pytest.raises(ValueError, match="singular"):
        sfanav.SFA(1).fit(np.ones((50, 3)))  # constant data


def test_bad_dtype_and_params():
    with pytest.raises(TypeError, match="real numbers"):
        sfanav.SFA(1).fit(np.array([["a", "b"], ["c", "d"]]))
    with pytest.raises(TypeError, match="real numbers"):
        sfanav.SFA(1).fit(np.ones((5, 2), dtype=complex))
    with pytest.raises(ValueError, match="n_components must be at least 1"):
        sfanav.SFA(0).fit(correlated(50, 3))
    with pytest.raises(TypeError, match="integer"):
        sfanav.SFA(1.5).fit(correlated(50, 3))
    with pytest.raises(ValueError, match="degree must be between 1 and"):
        sfanav.SFA(1, degree=9).fit(correlated(50, 3))
    with pytest.raises(ValueError, match="tol"):
        sfanav.SFA(1, tol=2.0).fit(correlated(50, 3))
    with pytest.raises(ValueError, match="reduce_to \\(5\\) exceeds"):
        sfanav.SFA(1, degree=2, reduce_to=5).fit(correlated(50, 3))
    with pytest.raises(ValueError, match="n_components \\(10\\) exceeds"):
        sfanav.SFA(10).fit(correlated(50, 3))


def test_integer_input_is_accepted():
    X = np.arange(200).reshape(100, 2) % 7
    X[:, 1] = X[:, 1] ** 2 % 5
    assert sfanav.SFA(1).fit(X).transform(X).dtype == np.float64


def test_statistics_errors():
    st = sfanav.Statistics(3)
    with pytest.raises(ValueError, match="number of training samples"):
        st.covariance()
    with pytest.raises(ValueError, match="weights must be finite and non-negative"):
        st.add_samples(np.ones((2, 3)), weights=np.array([1.0, -1.0]))
    with pytest.raises(ValueError, match="weights must be 1-D of length 2"):
        st.add_samples(np.ones((2, 3)), weights=np.ones(3))
    with pytest.raises(ValueError, match="number of pair ends"):
        st.add_pairs(np.ones((2, 3)), np.ones((3, 3)))
    with pytest.raises(ValueError, match="dimension of the merged"):
        st.merge(sfanav.Statistics(2))
    with pytest.raises(TypeError):
        st.merge("nope")


def test_expand_errors():
    with pytest.raises(ValueError, match="degree must be between"):
        sfanav._core.expand(np.ones((2, 2)), 0)
    with pytest.raises(ValueError, match="at least 1"):
        sfanav.expand(np.ones((2, 2)), 0)
    with pytest.raises(TypeError, match="2-D float32 or float64"):
        sfanav._core.expand(np.ones((2, 2), dtype=np.int64), 2)
