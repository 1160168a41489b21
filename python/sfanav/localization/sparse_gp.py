"""The posterior mean of a Gaussian process given more training samples
than it keeps: the deterministic training conditional (DTC).

A GP readout stores at most ``max_train`` samples (its size and query time
grow with them). Thinning a longer run to them throws the rest away; the
DTC (Seeger et al. 2003; Quinonero-Candela and Rasmussen 2005, "A unifying
view of sparse approximate Gaussian process regression") keeps the same
stored samples as inducing points and lets every training sample inform
their weights: the predictive mean ``k(x, Z) w`` with

    w = argmin |y - K_nZ w|^2 + noise * w' K_ZZ w = (K_Zn K_nZ + noise K_ZZ)^-1 K_Zn y,

which is the exact GP's mean when Z holds every training sample. Cost
O(N m^2) for N samples and m inducing points, memory O(m^2 + m chunk).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

try:  # loaded before any threadpool limit (see readouts.py)
    from scipy.linalg import cho_factor, cho_solve, cholesky, solve_triangular
except ImportError:  # pragma: no cover - scipy is a dependency
    cho_factor = cho_solve = cholesky = solve_triangular = None

__all__ = ["dtc_weights"]


def dtc_weights(Kzz: np.ndarray, kernel_rows: Callable[[slice], np.ndarray], Yc: np.ndarray, noise: float,
                chunk: int = 1024) -> np.ndarray:
    """Weights ``w`` (m, d) of m inducing points whose predictions
    ``K(x, Z) w`` are the DTC posterior mean given N training samples.

    Parameters
    ----------
    Kzz : ndarray (m, m)
        The kernel between the inducing points (unit signal variance).
    kernel_rows : callable
        ``kernel_rows(slice)`` -> (rows, m): the kernel between those
        training samples and the inducing points; called once per block of
        ``chunk`` samples.
    Yc : ndarray (N, d)
        The training targets, centred.
    noise : float
        Noise / signal variance, > 0.

    Solved as ``L' w = (V V' + noise I)^-1 V Yc`` with ``K_ZZ = L L'`` and
    ``V = L^-1 K_Zn`` accumulated over blocks: the matrix inverted is bounded
    below by ``noise``, unlike the normal equations. ``K_ZZ`` gets the
    smallest jitter (1e-10 .. 1e-4) that makes it positive definite (it is
    singular where inducing points coincide). Raises LinAlgError if none
    does.

    >>> import numpy as np
    >>> x = np.linspace(0, 1, 50)[:, None]; z = x[::5]
    >>> k = lambda a, b: np.exp(-0.5 * (a - b.T) ** 2 / 0.1 ** 2)
    >>> w = dtc_weights(k(z, z), lambda s: k(x[s], z), np.sin(6 * x), 1e-4)
    >>> bool(np.abs(k(x, z) @ w - np.sin(6 * x)).max() < 1e-2)
    True
    """
    m = len(Kzz)
    L = None
    for jitter in (1e-10, 1e-8, 1e-6, 1e-4):
        try:
            L = cholesky(Kzz + jitter * np.eye(m), lower=True, check_finite=False)
            break
        except np.linalg.LinAlgError:
            continue
    if L is None:
        raise np.linalg.LinAlgError("the inducing points' kernel matrix is not positive definite")
    A = np.zeros((m, m))
    b = np.zeros((m, Yc.shape[1]))
    for s in range(0, len(Yc), chunk):
        V = solve_triangular(L, kernel_rows(slice(s, s + chunk)).T, lower=True, check_finite=False)
        A += V @ V.T
        b += V @ Yc[s : s + chunk]
    A[np.diag_indices_from(A)] += noise
    u = cho_solve(cho_factor(A, lower=True, overwrite_a=True, check_finite=False), b, check_finite=False)
    return solve_triangular(L, u, lower=True, trans="T", check_finite=False)
