"""Incremental Slow Feature Analysis (IncSFA), the published online SFA, as a
peer of sfanav's exact updates.

Kompella, Luciw and Schmidhuber (2012), "Incremental Slow Feature Analysis:
Adaptive Low-Complexity Slow Feature Updating from High-Dimensional Input
Streams", Neural Computation 24(11). Each sample updates, in O(D K):

1. the mean, by an amnesic average (rate ``(1 + amnesic) / t``, floored at
   ``min_rate`` so that a stream whose statistics change keeps adapting);
2. the principal components of the centred input by candid covariance-free
   incremental PCA (CCIPCA: ``v_i <- (1 - r) v_i + r (u . v_i / |v_i|) u``,
   then ``u`` deflated by ``v_i``), which give the whitening
   ``z = diag(|v_i|)^-1/2 V^T u`` of the ``n_whitened`` leading directions;
3. the minor components of the whitened derivative ``dz = z_t - z_{t-1}``
   by covariance-free incremental minor component analysis (CIMCA:
   ``w_i <- (1 - eta) w_i - eta ((dz . w_i) dz + gamma sum_{j<i} (w_j . w_i) w_j)``,
   normalised), ``gamma`` and ``eta`` scaled by a running estimate of the
   derivative's power so that the iteration stays stable.

The slow features are ``y = W z``. Unlike sfanav's nodes, which accumulate
exact, mergeable statistics and solve a generalised eigenproblem
(:mod:`sfanav.sfa.node`), IncSFA keeps no statistics: it is an approximation
whose quality depends on its learning rates and on how many passes it sees,
and two streams cannot be merged. It is here as the peer of the exact
updates; docs/updates.md says what has been measured with it.

Examples
--------
>>> t = np.arange(4000.0)
>>> slow, fast = np.sin(2 * np.pi * t / 400), np.sin(2 * np.pi * t / 7)
>>> X = np.c_[slow + fast, slow - 0.5 * fast, fast]
>>> node = IncSFA(n_components=1, n_whitened=3)
>>> for _ in range(3):
...     node = node.partial_fit(X)
>>> y = node.transform(X)[:, 0]
>>> bool(abs(np.corrcoef(y, slow)[0, 1]) > 0.99)
True
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import NotFittedError, as_matrix, check_int, check_nonneg_float, check_positive_float

__all__ = ["IncSFA"]


class IncSFA:
    """Incremental SFA on a stream of samples (scikit-learn style).

    Parameters
    ----------
    n_components : int
        Slow features to learn (J).
    n_whitened : int
        Principal directions kept for the whitening (K >= J, <= the input's
        dimension).
    amnesic : float, default 2
        CCIPCA's amnesic parameter ``l``: the rate of the t-th sample is
        ``(1 + l) / t``; larger forgets old samples faster.
    min_rate : float, default 0
        Floor of that rate (0: a stationary stream; e.g. 1e-3 to keep
        tracking a changing one).
    mca_rate : float, default 0.5
        CIMCA's step as a fraction of the stable bound ``1 / (2 p)``, ``p``
        the running mean of ``|dz|^2``. Two slow features whose derivative
        variances (in the whitened space) differ by ``g`` separate in about
        ``4 p / (mca_rate g)`` samples: features of similar slowness need
        many passes.
    seed : int, default 0
        Initial slow directions (random unit vectors).

    Attributes
    ----------
    mean_ : (D,) running mean of the input.
    components_ : (K, D) unnormalised principal vectors (their norms are
        the eigenvalue estimates).
    slow_ : (J, K) slow directions in the whitened space, slowest first.
    delta_ : (J,) running estimates of each output's mean squared
        derivative (the slowness; smaller is slower).
    n_samples_ : samples seen.

    Raises ValueError (TypeError for non-numeric data) for a sequence that
    is not (N, D) with N >= 2, a dimension that changes between calls,
    n_whitened outside [n_components, D], NaN or infinity.
    """

    def __init__(self, n_components: int, n_whitened: int, *, amnesic: float = 2.0, min_rate: float = 0.0,
                 mca_rate: float = 0.5, seed: int = 0) -> None:
        self.n_components = n_components
        self.n_whitened = n_whitened
        self.amnesic = amnesic
        self.min_rate = min_rate
        self.mca_rate = mca_rate
        self.seed = seed
        self.n_samples_ = 0

    def __repr__(self) -> str:
        return (f"IncSFA(n_components={self.n_components!r}, n_whitened={self.n_whitened!r}, "
                f"amnesic={self.amnesic!r}, min_rate={self.min_rate!r}, mca_rate={self.mca_rate!r})")

    # ------------------------------------------------------------ fitting
    def _check(self, X: Any) -> np.ndarray:
        A = as_matrix(X, "X", min_rows=2)
        J = check_int(self.n_components, "n_components")
        K = check_int(self.n_whitened, "n_whitened")
        D = A.shape[1]
        if not J <= K <= D:
            raise ValueError(f"n_whitened must lie between n_components ({J}) and the input's dimension ({D}), "
                             f"got {K}")
        check_nonneg_float(self.amnesic, "amnesic")
        if not 0.0 <= check_nonneg_float(self.min_rate, "min_rate") < 1.0:
            raise ValueError(f"min_rate must lie in [0, 1), got {self.min_rate!r}")
        if not 0.0 < check_positive_float(self.mca_rate, "mca_rate") <= 1.0:
            raise ValueError(f"mca_rate must lie in (0, 1], got {self.mca_rate!r}")
        if self.n_samples_ and A.shape[1] != self.mean_.shape[0]:
            raise ValueError(f"X has {A.shape[1]} columns, but this IncSFA was fitted on {self.mean_.shape[0]}")
        return A

    def partial_fit(self, X: Any) -> "IncSFA":
        """Learns from one sequence X (N, D), samples in temporal order;
        derivatives join consecutive rows of X only (no pair joins two
        calls). Returns ``self``."""
        A = self._check(X)
        J, K = int(self.n_components), int(self.n_whitened)
        if self.n_samples_ == 0:
            D = A.shape[1]
            self.mean_ = A[0].copy()
            self.components_ = np.zeros((K, D))
            rng = np.random.default_rng(self.seed)
            W = rng.standard_normal((J, K))
            self.slow_ = W / np.linalg.norm(W, axis=1, keepdims=True)
            self.delta_ = np.zeros(J)
            self._power = 0.0
            self._n_deriv = 0
        prev = None
        for x in A:
            z = self._update_pca(x)
            if prev is not None and z is not None:
                self._update_mca(z - prev)
            prev = z
        return self

    def _rate(self) -> float:
        t = self.n_samples_
        return max((1.0 + float(self.amnesic)) / t if t > 1 + self.amnesic else 1.0 / t, float(self.min_rate))

    def _update_pca(self, x: np.ndarray) -> np.ndarray | None:
        """One CCIPCA step; the whitened sample (K,) once every direction has
        been initialised, else None."""
        self.n_samples_ += 1
        r = self._rate()
        self.mean_ += r * (x - self.mean_)
        u = x - self.mean_
        V = self.components_
        K = len(V)
        for i in range(min(K, self.n_samples_ - 1)):
            n = np.linalg.norm(V[i])
            if n == 0.0:  # the i-th direction starts at the first residual it sees
                V[i] = u
                u = np.zeros_like(u)
                continue
            V[i] = (1.0 - r) * V[i] + r * (u @ V[i] / n) * u
            n = np.linalg.norm(V[i])
            if n > 0.0:
                e = V[i] / n
                u = u - (u @ e) * e
        return self._whiten(x) if self.n_samples_ > K + 1 else None

    def _whiten(self, X: np.ndarray) -> np.ndarray:
        V = self.components_
        lam = np.linalg.norm(V, axis=1)
        scale = np.where(lam > 1e-12 * max(float(lam.max()), 1e-300), 1.0 / np.sqrt(np.maximum(lam, 1e-300)), 0.0)
        E = V / np.maximum(lam, 1e-300)[:, None]
        return ((X - self.mean_) @ E.T) * scale

    def _update_mca(self, dz: np.ndarray) -> None:
        self._n_deriv += 1
        p = float(dz @ dz)
        self._power += (p - self._power) / min(self._n_deriv, 1000)
        if self._power <= 0.0:
            return
        gamma = self._power  # >= the derivative covariance's largest eigenvalue (its trace, on average)
        eta = float(self.mca_rate) / (2.0 * (self._power + gamma))
        W = self.slow_
        for i in range(len(W)):
            w = W[i]
            g = (dz @ w) * dz
            for j in range(i):
                g = g + gamma * (W[j] @ w) * W[j]
            w = (1.0 - eta) * w - eta * g
            W[i] = w / max(np.linalg.norm(w), 1e-300)
            self.delta_[i] += (float(dz @ W[i]) ** 2 - self.delta_[i]) / min(self._n_deriv, 1000)

    # ------------------------------------------------------------ output
    def transform(self, X: Any) -> np.ndarray:
        """The slow features (N, J) of samples X (N, D), slowest first."""
        if self.n_samples_ <= int(self.n_whitened) + 1:
            raise NotFittedError("this IncSFA has not seen enough samples; call partial_fit with a longer sequence")
        A = as_matrix(X, "X", min_rows=0)
        if A.shape[1] != self.mean_.shape[0]:
            raise ValueError(f"X has {A.shape[1]} columns, but this IncSFA was fitted on {self.mean_.shape[0]}")
        return self._whiten(A) @ self.slow_.T
