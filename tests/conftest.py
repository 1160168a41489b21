import numpy as np
import pytest


def correlated(n: int, d: int, seed: int = 0, dtype=np.float64) -> np.ndarray:
    """Correlated time series: mixed random walks plus noise."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.standard_normal((n, d)) * 0.05, axis=0)
    x = (walk + 0.3 * rng.standard_normal((n, d))) @ rng.standard_normal((d, d))
    return x.astype(dtype)


def toy(n: int = 5000):
    """Wiskott & Sejnowski (2002): x1 = sin t + cos^2 11t, x2 = cos 11t."""
    t = np.linspace(0, 2 * np.pi, n)
    return np.c_[np.sin(t) + np.cos(11 * t) ** 2, np.cos(11 * t)], np.sin(t)


@pytest.fixture
def data():
    return correlated(3000, 6, seed=1)
