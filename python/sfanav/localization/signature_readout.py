"""A Gaussian-process readout that reads the slow features and an appearance
signature of the same image together.

:class:`SignatureGPReadout` regresses position on two blocks of one feature
row: the slowest outputs of the network (the first ``n_outputs`` columns)
and an appearance signature (the last ``n_signature`` columns, e.g. the
rotation-invariant Fourier signature of the panorama,
:class:`sfanav.localization.FourierSignature`). Its kernel is the product

    k(a, b) = exp(-sum_i (s_a,i - s_b,i)^2 / (2 l_i^2)) * exp(-|g_a - g_b|_1 / l_g)

of an ARD squared-exponential kernel on the standardised slow features
``s`` and a Laplacian kernel on the L1 distance between signatures ``g``
(relative to the median distance between training signatures). A product
of positive-definite kernels is positive definite, and it contains both
parts: a slow feature whose length scale grows to its bound drops out, and
so does the signature when ``l_g`` does. All hyperparameters (the length
scales, ``l_g`` and the noise-to-signal ratio) maximise the log marginal
likelihood of the training run with the signal variance profiled out
(Rasmussen and Williams 2006, ch. 5), by L-BFGS-B with analytic gradients.
Why a product of these two kernels, and what it measured: docs/gardens-suite.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import NotFittedError, as_matrix, check_int, check_same_length
from .._threads import one_blas_thread
from .._sampling import evenly_spaced
from .signature_distance import l1_distances
from .sparse_gp import dtc_weights

try:  # loaded before any threadpool limit (see readouts.py)
    from scipy.linalg import cho_factor, cho_solve
    from scipy.linalg.lapack import dpotri
    from scipy.optimize import minimize
    from scipy.spatial.distance import cdist
except ImportError:  # pragma: no cover - scipy is a dependency
    cho_factor = cho_solve = minimize = cdist = dpotri = None

_LOG_BOUNDS = {"length": (np.log(1e-2), np.log(1e3)), "signature": (np.log(1e-3), np.log(1e4)),
               "noise": (np.log(1e-8), np.log(1.0))}


# the largest float32 table of every training sample's signature distance to the kept samples a fit keeps
# (a 12000-sample run with 3000 kept: 144 MB); longer runs recompute the distances per block
_DISTANCE_CACHE_BYTES = 2**29


class SignatureGPReadout:
    """GP regression of position on slow features and an appearance signature
    (product kernel, type-II maximum likelihood).

    Parameters
    ----------
    n_outputs : int
        Slow features read: the first ``n_outputs`` columns of the features
        (0: the signature alone).
    n_signature : int
        Length of the signature: the last ``n_signature`` columns.
    max_fit : int, default 800
        Evenly spaced training samples the hyperparameters are fitted on
        (each step of the optimiser is cubic in their number; of the
        ``max_train`` evenly spaced ones in a longer run).
    max_train : int, default 3000
        Training samples the model keeps (its size and query time grow with
        them). Longer runs are not thinned away: the posterior mean is then
        the deterministic training conditional's (DTC; Quinonero-Candela and
        Rasmussen 2005) with ``max_train`` inducing samples, chosen
        farthest-first in the learned kernel, and every training sample as
        data; the exact GP's when every sample is kept (docs/localization.md).
    length_scale, signature_scale, noise : optional
        Fixed kernel hyperparameters (all three or none): ``length_scale``
        (n_outputs,) in standard deviations of the slow features,
        ``signature_scale`` in median signature distances, ``noise`` (noise /
        signal variance). Given, :meth:`fit` only solves the posterior (one
        Cholesky factorisation) instead of learning them; an updated
        localizer keeps its readout's kernel this way.

    Fitted attributes: ``inducing_`` (m,): the indices of the training
    samples kept (None after loading); ``training_predictions_`` ((N, 2): the posterior mean at
    the N training samples, computed from the fit; None after loading, and
    when a run too long for the distance cache was thinned);
    ``length_scale_`` (n_outputs,); ``signature_scale_`` (``l_g``, in units
    of ``distance_unit_``, the median L1 distance between training
    signatures); ``noise_`` (noise / signal variance);
    ``log_marginal_likelihood_``.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.uniform(-1, 1, (200, 2))
    >>> F = np.hstack([xy + 0.01 * rng.normal(size=(200, 2)), np.abs(xy) + 1])  # 2 slow, 2 signature
    >>> r = SignatureGPReadout(n_outputs=2, n_signature=2).fit(F, xy)
    >>> bool(np.abs(r.predict(F[:5]) - xy[:5]).max() < 0.1)
    True
    """

    def __init__(self, n_outputs: int = 12, n_signature: int = 1, max_fit: int = 800, max_train: int = 3000,
                 length_scale: Any = None, signature_scale: float | None = None, noise: float | None = None) -> None:
        self.n_outputs = check_int(n_outputs, "n_outputs", minimum=0)
        self.n_signature = check_int(n_signature, "n_signature", minimum=1)
        self.max_fit = check_int(max_fit, "max_fit", minimum=3)
        self.max_train = check_int(max_train, "max_train", minimum=3)
        given = [v is not None for v in (length_scale, signature_scale, noise)]
        if any(given) and not all(given):
            raise ValueError("give length_scale, signature_scale and noise (fixed hyperparameters) or none (learned)")
        self.length_scale = self.signature_scale = self.noise = None
        if all(given):
            ls = np.asarray(length_scale, float).reshape(-1)
            if ls.shape != (self.n_outputs,) or not np.all(np.isfinite(ls)) or np.any(ls <= 0):
                raise ValueError(f"length_scale must be {self.n_outputs} positive finite numbers, got {length_scale!r}")
            for name, v in (("signature_scale", signature_scale), ("noise", noise)):
                if not (np.isfinite(float(v)) and float(v) > 0):  # type: ignore[arg-type]
                    raise ValueError(f"{name} must be a positive finite number, got {v!r}")
            self.length_scale = [float(v) for v in ls]
            self.signature_scale, self.noise = float(signature_scale), float(noise)  # type: ignore[arg-type]

    def hyperparameters(self) -> dict[str, Any]:
        """The fitted kernel as constructor parameters (``length_scale``,
        ``signature_scale``, ``noise``): ``SignatureGPReadout(m, q,
        **r.hyperparameters())`` fits with this readout's kernel."""
        if not hasattr(self, "dual_"):
            raise NotFittedError("this SignatureGPReadout is not fitted; call fit first")
        return {"length_scale": [float(v) for v in self.length_scale_],
                "signature_scale": float(self.signature_scale_), "noise": float(self.noise_)}

    def __repr__(self) -> str:
        return f"SignatureGPReadout(n_outputs={self.n_outputs}, n_signature={self.n_signature})"

    # ------------------------------------------------------------ blocks
    def _split(self, features: Any, name: str = "features") -> tuple[np.ndarray, np.ndarray]:
        X = as_matrix(features, name)
        need = self.n_outputs + self.n_signature
        if X.shape[1] < need:
            raise ValueError(f"{name} have {X.shape[1]} columns; this readout reads {self.n_outputs} slow features "
                             f"and a signature of {self.n_signature} values ({need} columns)")
        return X[:, : self.n_outputs], X[:, X.shape[1] - self.n_signature :]

    @staticmethod
    def _sq_dists(A: np.ndarray, B: np.ndarray) -> np.ndarray:
        if A.shape[1] == 0:
            return np.zeros((len(A), len(B)))
        d2 = (A**2).sum(axis=1)[:, None] + (B**2).sum(axis=1)[None, :] - 2.0 * A @ B.T
        return np.maximum(d2, 0.0)

    def _l1(self, A: np.ndarray, B: np.ndarray, chunk: int = 128, dtype: Any = np.float64) -> np.ndarray:
        """L1 distances (len(A), len(B)) as ``dtype``
        (:func:`~sfanav.localization.signature_distance.l1_distances`): the
        signature distances are most of a fit's and an update's time."""
        return l1_distances(A, B, chunk, dtype)

    # ------------------------------------------------------------ likelihood
    def _neg_lml(self, theta: np.ndarray, S: np.ndarray, Dg: np.ndarray, Y: np.ndarray) -> tuple[float, np.ndarray]:
        """Negative profiled log marginal likelihood and its gradient in
        ``theta = [log l_1..l_m, log l_g, log noise]``."""
        m = S.shape[1]
        ls, lg, tau = np.exp(theta[:m]), np.exp(theta[m]), np.exp(theta[m + 1])
        Z = S / ls
        K = np.exp(-0.5 * self._sq_dists(Z, Z) - Dg / lg)
        A = K.copy()
        A[np.diag_indices_from(A)] += tau
        n, d = Y.shape
        try:
            c = cho_factor(A, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            return 1e25, np.zeros_like(theta)
        alpha = cho_solve(c, Y, check_finite=False)
        fit = float((Y * alpha).sum())
        if not fit > 0:
            return 1e25, np.zeros_like(theta)
        lml = -0.5 * n * d * np.log(fit / (n * d)) - d * float(np.log(np.diag(c[0])).sum())
        W, info = dpotri(c[0], lower=1)  # A^-1 from the Cholesky factor (lower triangle)
        if info != 0:
            return 1e25, np.zeros_like(theta)
        W = np.tril(W) + np.tril(W, -1).T
        M = (0.5 * n * d / fit) * (alpha @ alpha.T) - 0.5 * d * W  # dL/dA
        MK = M * K
        grad = np.empty_like(theta)
        # sum_ab MK_ab (z_ai - z_bi)^2 = 2 sum_a r_a z_ai^2 - 2 (Z^T MK Z)_ii, r = row sums of MK (symmetric)
        r = MK.sum(axis=1)
        grad[:m] = 2.0 * (r @ Z**2) - 2.0 * np.einsum("ai,ai->i", Z, MK @ Z)
        grad[m] = float((MK * Dg).sum()) / lg
        grad[m + 1] = tau * float(np.trace(M))
        return -lml, -grad

    def _learn(self, S: np.ndarray, Dg: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, float, float, float]:
        m = S.shape[1]
        bounds = [_LOG_BOUNDS["length"]] * m + [_LOG_BOUNDS["signature"], _LOG_BOUNDS["noise"]]
        # one start: slow features at a few standard deviations, the signature's scale of the order of
        # 100 median distances and little noise, where the optima on the gardens suite lie (docs/gardens-suite.md)
        theta0 = np.r_[np.full(m, np.log(3.0 * max(1.0, np.sqrt(m / 4)))), np.log(100.0), np.log(1e-4)]
        with one_blas_thread():  # ~100 factorisations of an 800x800 matrix: threads thrash on a busy machine
            best = minimize(self._neg_lml, theta0, args=(S, Dg, Y), jac=True, method="L-BFGS-B", bounds=bounds,
                            options={"maxiter": 200})
        th = best.x
        return np.exp(th[:m]), float(np.exp(th[m])), float(np.exp(th[m + 1])), float(-best.fun)

    # ------------------------------------------------------------ fit / predict
    def fit(self, features: Any, xy: Any, *, hyperparameters_from: "SignatureGPReadout | None" = None
            ) -> "SignatureGPReadout":
        """Fits on features (N, >= n_outputs + n_signature) and positions (N, 2).

        ``hyperparameters_from``: a fitted readout of the same shape whose
        kernel hyperparameters (``length_scale_``, ``signature_scale_``,
        ``noise_``) are kept instead of learned: only the posterior is
        fitted, one Cholesky factorisation instead of an optimisation (as
        scikit-learn's ``GaussianProcessRegressor(optimizer=None)``). For
        repeated fits on resamples of one run, such as random splits.
        """
        S, G = self._split(features)
        fixed = None
        if hyperparameters_from is not None:
            if not isinstance(hyperparameters_from, SignatureGPReadout) or not hasattr(hyperparameters_from, "dual_"):
                raise TypeError("hyperparameters_from must be a fitted SignatureGPReadout")
            if (hyperparameters_from.n_outputs, hyperparameters_from.n_signature) != (self.n_outputs,
                                                                                      self.n_signature):
                raise ValueError(f"hyperparameters_from reads {hyperparameters_from.n_outputs} slow features and "
                                 f"{hyperparameters_from.n_signature} signature values; this readout "
                                 f"{self.n_outputs} and {self.n_signature}")
            fixed = (np.array(hyperparameters_from.length_scale_, float),
                     float(hyperparameters_from.signature_scale_), float(hyperparameters_from.noise_))
        elif self.length_scale is not None:
            fixed = (np.array(self.length_scale, float), float(self.signature_scale), float(self.noise))
        return self._fit_prepared(S, self._distances(G, as_matrix(xy, "xy")), fixed=fixed)

    @classmethod
    def fit_nested(cls, features: Any, xy: Any, n_outputs: int, n_signature: int,
                   **params: Any) -> tuple["SignatureGPReadout", "SignatureGPReadout"]:
        """Fits the combination (``n_outputs`` slow features with the
        signature) and the signature alone on the same features, computing
        the signatures' distances once: ``(combination, signature alone)``."""
        both, alone = cls(n_outputs, n_signature, **params), cls(0, n_signature, **params)
        S, G = both._split(features)
        prepared = both._distances(G, as_matrix(xy, "xy"))
        return both._fit_prepared(S, prepared), alone._fit_prepared(S[:, :0], prepared)

    def _distances(self, G: np.ndarray, Y: np.ndarray) -> dict[str, Any]:
        """What every fit on ``G`` shares: the evenly spaced samples the
        hyperparameters are learned on (``fit``) and the L1 distances between
        their signatures, the samples kept when the run is not longer than
        ``max_train`` (``keep``, with all their distances ``D``), the distance
        unit, and (filled by the first thinned fit, reused by a nested one)
        the inducing samples of a longer run."""
        check_same_length(G, Y, "features", "xy")
        if len(G) < 3:
            raise ValueError(f"a GP readout needs at least 3 training samples, got {len(G)}")
        G = G.astype(np.float64)
        even = evenly_spaced(len(G), self.max_train)
        fit = even[evenly_spaced(len(even), self.max_fit)]
        sub = G[evenly_spaced(len(G), 300)]
        dg = self._l1(sub, sub)[np.triu_indices(len(sub), 1)]
        unit = float(np.median(dg)) if dg.size else 0.0
        thinned = len(even) < len(G)
        D = None if thinned else self._l1(G, G)
        Dfit = self._l1(G[fit], G[fit]) if thinned else D[np.ix_(fit, fit)]
        return {"G": G, "Y": Y, "fit": fit, "Dfit": Dfit, "keep": None if thinned else even, "D": D,
                "even": even, "inducing": None, "unit": unit if unit > 0 else 1.0}

    def _fit_prepared(self, S: np.ndarray, prep: dict[str, Any],
                      fixed: tuple[np.ndarray, float, float] | None = None) -> "SignatureGPReadout":
        G, Y, fit_idx = prep["G"], prep["Y"], prep["fit"]
        self.distance_unit_ = prep["unit"]
        self.mean_ = S.mean(axis=0)
        sd = S.std(axis=0)
        self.scale_ = np.where(sd > 0, sd, 1.0)
        Ss = (S - self.mean_) / self.scale_
        y_mean, y_sd = Y.mean(axis=0), Y.std(axis=0)
        y_sd = np.where(y_sd > 0, y_sd, 1.0)
        Yf = (Y[fit_idx] - y_mean) / y_sd
        Dg = prep["Dfit"] / self.distance_unit_
        if fixed is None:
            ls, lg, tau, lml = self._learn(Ss[fit_idx], Dg, Yf)
        else:
            ls, lg, tau = fixed
            lml = float(-self._neg_lml(np.r_[np.log(ls), np.log(lg), np.log(tau)], Ss[fit_idx], Dg, Yf)[0])
        self.length_scale_, self.signature_scale_, self.noise_, self.log_marginal_likelihood_ = ls, lg, tau, lml
        self.y_mean_ = Y.mean(axis=0)
        Z = Ss / ls
        if prep["keep"] is None:
            return self._fit_dtc(Z, G, Y - self.y_mean_, max(tau, 1e-10), prep)
        keep = prep["keep"]
        self.inducing_ = keep
        self.X_, self.G_ = Z[keep], G[keep].astype(np.float32)
        K = np.exp(-0.5 * self._sq_dists(self.X_, self.X_) - prep["D"] / (self.distance_unit_ * lg))
        K[np.diag_indices_from(K)] += max(tau, 1e-10)
        self.dual_ = cho_solve(cho_factor(K, overwrite_a=True, check_finite=False), Y - self.y_mean_,
                               check_finite=False)
        # K dual = (K + tau I) dual - tau dual = Y - mean - tau dual: the posterior mean at the training
        # samples without a second pass over their signature distances (when every sample was kept)
        self.training_predictions_ = Y - max(tau, 1e-10) * self.dual_
        return self

    def _inducing(self, Z: np.ndarray, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``max_train`` inducing samples chosen farthest-first in this
        readout's kernel (each next one the sample least covered, by its
        largest kernel value, by those chosen so far; the first the run's
        first), and every sample's signature distance to them (N, m)
        float32: a covering of the run without the near-duplicates that
        evenly spaced samples of a dense run (or an image beside its
        corrupted copy) hold. The choice reads the signatures' L1 distance
        on every ``q // 128``-th value (scaled up): a row of distances per
        chosen sample over all N is memory-bound, and the covering needs no
        exact distances; the table is then computed exactly, in blocks."""
        n, m = len(G), min(self.max_train, len(G))
        width = self.distance_unit_ * self.signature_scale_
        stride = max(1, G.shape[1] // 128)
        Gs = np.ascontiguousarray(G[:, ::stride])
        scale = G.shape[1] / Gs.shape[1]
        idx = np.empty(m, np.intp)
        cover = np.full(n, -np.inf)
        i = 0
        for j in range(m):
            idx[j] = i
            d1 = cdist(Gs, Gs[i : i + 1], "cityblock")[:, 0] * scale
            np.maximum(cover, -0.5 * ((Z - Z[i]) ** 2).sum(axis=1) - d1 / width, out=cover)  # log kernel
            i = int(np.argmin(cover))
        return idx, self._l1(G, G[idx], dtype=np.float32)

    def _fit_dtc(self, Z: np.ndarray, G: np.ndarray, Yc: np.ndarray, tau: float,
                 prep: dict[str, Any]) -> "SignatureGPReadout":
        """The fit of a run longer than ``max_train``: the DTC posterior
        (:func:`sfanav.localization.sparse_gp.dtc_weights`) with ``max_train``
        inducing samples and every sample as data. The inducing samples are
        chosen farthest-first (:meth:`_inducing`) when the (N, max_train)
        float32 distance table fits ``_DISTANCE_CACHE_BYTES``, else evenly
        spaced with the distances computed per block (and no training
        predictions). A nested fit on the same samples reuses the first
        fit's choice."""
        width = self.distance_unit_ * self.signature_scale_
        if prep["inducing"] is None:
            if len(G) * min(self.max_train, len(G)) * 4 <= _DISTANCE_CACHE_BYTES:
                prep["inducing"] = self._inducing(Z, G)
            else:
                prep["inducing"] = (prep["even"], None)
        idx, Dnm = prep["inducing"]
        self.inducing_ = idx
        self.X_, self.G_ = Z[idx], G[idx].astype(np.float32)
        Gk = G[idx]
        Dmm = Dnm[idx].astype(np.float64) if Dnm is not None else self._l1(Gk, Gk)
        Kmm = np.exp(-0.5 * self._sq_dists(self.X_, self.X_) - Dmm / width)
        chunk = 1024

        def rows(sl: slice) -> np.ndarray:
            d1 = Dnm[sl] if Dnm is not None else self._l1(G[sl], Gk)
            return np.exp(-0.5 * self._sq_dists(Z[sl], self.X_) - d1 / width)

        self.dual_ = dtc_weights(Kmm, rows, Yc, tau, chunk)
        self.training_predictions_ = None
        if Dnm is not None:
            self.training_predictions_ = np.concatenate(
                [rows(slice(s, s + chunk)) @ self.dual_ for s in range(0, len(Z), chunk)]) + self.y_mean_
        return self

    def predict(self, features: Any, chunk: int = 1024) -> np.ndarray:
        """Positions (N, 2) of features (N, >= n_outputs + n_signature)."""
        if not hasattr(self, "dual_"):
            raise NotFittedError("this SignatureGPReadout is not fitted; call fit first")
        S, G = self._split(features)
        Q = (S - self.mean_) / self.scale_ / self.length_scale_
        Gt = self.G_.astype(np.float64)
        out = np.empty((len(Q), self.dual_.shape[1]))
        for s in range(0, len(Q), chunk):
            K = np.exp(-0.5 * self._sq_dists(Q[s : s + chunk], self.X_)
                       - self._l1(G[s : s + chunk].astype(np.float64), Gt) / (self.distance_unit_ * self.signature_scale_))
            out[s : s + chunk] = K @ self.dual_ + self.y_mean_
        return out

    # ------------------------------------------------------------ state
    def get_state(self) -> dict[str, Any]:
        if not hasattr(self, "dual_"):
            raise NotFittedError("this SignatureGPReadout is not fitted; call fit first")
        return {"params": {"n_outputs": self.n_outputs, "n_signature": self.n_signature, "max_fit": self.max_fit,
                           "max_train": self.max_train},
                "mean": self.mean_, "scale": self.scale_, "X": self.X_, "G": self.G_, "dual": self.dual_,
                "y_mean": self.y_mean_, "length_scale": self.length_scale_,
                "signature_scale": float(self.signature_scale_), "distance_unit": float(self.distance_unit_),
                "noise": float(self.noise_)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "SignatureGPReadout":
        r = cls(**state["params"])
        r.mean_, r.scale_ = np.asarray(state["mean"], float), np.asarray(state["scale"], float)
        r.X_, r.G_ = np.asarray(state["X"], float), np.asarray(state["G"], np.float32)
        r.dual_, r.y_mean_ = np.asarray(state["dual"], float), np.asarray(state["y_mean"], float)
        r.length_scale_ = np.asarray(state["length_scale"], float)
        r.signature_scale_, r.distance_unit_ = float(state["signature_scale"]), float(state["distance_unit"])
        r.noise_, r.log_marginal_likelihood_ = float(state["noise"]), None
        r.training_predictions_ = r.inducing_ = None
        m, q = r.n_outputs, r.n_signature
        if (r.X_.shape[1:] != (m,) or r.G_.shape != (len(r.X_), q) or r.dual_.ndim != 2
                or len(r.dual_) != len(r.X_) or r.mean_.shape != (m,) or r.scale_.shape != (m,)
                or r.length_scale_.shape != (m,) or r.y_mean_.shape != (r.dual_.shape[1],)):
            raise ValueError("invalid SignatureGPReadout state: inconsistent array shapes")
        if not (np.all(r.scale_ > 0) and np.all(r.length_scale_ > 0) and r.signature_scale_ > 0
                and r.distance_unit_ > 0 and r.noise_ >= 0):
            raise ValueError("invalid SignatureGPReadout state: scales must be positive")
        return r
