"""Readouts beyond the thesis's quadratic regression: from slow features to
metric positions where the slowest outputs are not smooth functions of
position.

* :class:`KNNReadout`: k nearest training samples in the standardised
  feature space, positions averaged with inverse-distance weights;
* :class:`KernelRidgeReadout`: Gaussian-kernel ridge regression (Saunders,
  Gammerman and Vovk 1998);
* :class:`GPReadout`: a Gaussian process with one length scale per feature
  (ARD), fitted by maximum marginal likelihood (scikit-learn).

All have ``fit(features, xy)`` and ``predict(features)`` on features
(N, m >= n_outputs), of which the first ``n_outputs`` columns are used.
A readout is described by a spec dict (:func:`make_readout`,
:func:`describe_spec`) and saved as plain state (:func:`readout_state`)."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from .._checks import NotFittedError, as_matrix, check_same_length
from .._sampling import evenly_spaced
from .._threads import one_blas_thread
from .quadratic import QuadraticRegression
from .signature_knn import SignatureKNNReadout
from .signature_readout import SignatureGPReadout
from .sparse_gp import dtc_weights

try:  # loaded here, before any threadpool_limits: a BLAS library loaded inside one escapes the limit
    from scipy.linalg import cho_factor, cho_solve
except ImportError:  # pragma: no cover - scipy is a dependency
    cho_factor = cho_solve = None


def _cols(F: Any, n: int | None, name: str = "features") -> np.ndarray:
    X = as_matrix(F, name)
    if n is not None:
        if X.shape[1] < n:
            raise ValueError(f"{name} have {X.shape[1]} columns, fewer than n_outputs={n}")
        X = X[:, :n]
    return X


class _Standardised:
    n_outputs: int | None

    def _fit_scale(self, X: np.ndarray) -> np.ndarray:
        self.mean_ = X.mean(axis=0)
        sd = X.std(axis=0)
        self.scale_ = np.where(sd > 0, sd, 1.0)
        return (X - self.mean_) / self.scale_

    def _check_scale(self) -> None:
        n = self.n_outputs
        if self.mean_.ndim != 1 or (n is not None and self.mean_.shape != (n,)):
            raise ValueError(f"invalid {type(self).__name__} state: a feature mean of shape {self.mean_.shape} "
                             f"for n_outputs={n}")
        if self.scale_.shape != self.mean_.shape or not np.all(self.scale_ > 0):
            raise ValueError(f"invalid {type(self).__name__} state: feature scales must be positive and "
                             "match the feature mean")

    def _scaled(self, F: Any) -> np.ndarray:
        if not hasattr(self, "mean_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted; call fit first")
        return (_cols(F, self.n_outputs) - self.mean_) / self.scale_


class _KernelMachine(_Standardised):
    """A fitted kernel expansion ``k(q, X) @ dual + y_mean`` on standardised
    features: the shared prediction and model-file state of
    :class:`KernelRidgeReadout` and :class:`GPReadout`."""

    X_: np.ndarray
    dual_: np.ndarray
    y_mean_: np.ndarray

    def _kernel(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:  # pragma: no cover - overridden
        raise NotImplementedError

    def _query(self, Q: np.ndarray) -> np.ndarray:
        """Standardised queries in the coordinates of ``X_``."""
        return Q

    def predict(self, features: Any, chunk: int = 2048) -> np.ndarray:
        if not hasattr(self, "dual_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted; call fit first")
        Q = self._query(self._scaled(features))
        out = np.empty((len(Q), self.dual_.shape[1]))
        for s in range(0, len(Q), chunk):
            out[s : s + chunk] = self._kernel(Q[s : s + chunk], self.X_) @ self.dual_ + self.y_mean_
        return out

    def _arrays(self) -> dict[str, Any]:
        if not hasattr(self, "dual_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted; call fit first")
        return {"mean": self.mean_, "scale": self.scale_, "X": self.X_, "dual": self.dual_, "y_mean": self.y_mean_}

    def _load_arrays(self, state: dict[str, Any]) -> None:
        self.mean_, self.scale_ = np.asarray(state["mean"], float), np.asarray(state["scale"], float)
        self.X_, self.dual_ = np.asarray(state["X"], float), np.asarray(state["dual"], float)
        self.y_mean_ = np.asarray(state["y_mean"], float)
        if (self.X_.ndim != 2 or self.dual_.ndim != 2 or len(self.X_) != len(self.dual_)
                or self.mean_.shape != (self.X_.shape[1],) or self.y_mean_.shape != (self.dual_.shape[1],)):
            raise ValueError(f"invalid {type(self).__name__} state: inconsistent array shapes")
        self._check_scale()


class KNNReadout(_Standardised):
    """k-nearest-neighbour readout: the mean position of the ``k`` training
    samples nearest in the standardised feature space, weighted by inverse
    distance (``weights="distance"``) or equally (``"uniform"``).

    Memory grows with the training run (one feature vector and position per
    sample: ``n_outputs + 2`` numbers), unlike the regressions."""

    def __init__(self, n_outputs: int | None = 8, k: int = 5, weights: str = "distance") -> None:
        if weights not in ("distance", "uniform"):
            raise ValueError(f"weights must be 'distance' or 'uniform', got {weights!r}")
        if int(k) < 1:
            raise ValueError(f"k must be at least 1, got {k}")
        self.n_outputs, self.k, self.weights = n_outputs, int(k), weights

    def __repr__(self) -> str:
        return f"KNNReadout(n_outputs={self.n_outputs}, k={self.k}, weights={self.weights!r})"

    def fit(self, features: Any, xy: Any) -> "KNNReadout":
        X = _cols(features, self.n_outputs)
        Y = as_matrix(xy, "xy")
        check_same_length(X, Y, "features", "xy")
        self.X_ = self._fit_scale(X)
        self.y_ = Y
        return self

    def predict(self, features: Any, chunk: int = 2048) -> np.ndarray:
        Q = self._scaled(features)
        k = min(self.k, len(self.X_))
        out = np.empty((len(Q), self.y_.shape[1]))
        sq = (self.X_**2).sum(axis=1)
        for s in range(0, len(Q), chunk):
            q = Q[s : s + chunk]
            d2 = np.maximum((q**2).sum(axis=1)[:, None] + sq[None, :] - 2.0 * q @ self.X_.T, 0.0)
            idx = np.argpartition(d2, k - 1, axis=1)[:, :k] if k < len(self.X_) else np.tile(np.arange(k), (len(q), 1))
            dk = np.sqrt(np.take_along_axis(d2, idx, axis=1))
            if self.weights == "distance":
                w = 1.0 / np.maximum(dk, 1e-9)
            else:
                w = np.ones_like(dk)
            w /= w.sum(axis=1, keepdims=True)
            out[s : s + chunk] = np.einsum("qk,qkd->qd", w, self.y_[idx])
        return out

    def get_state(self) -> dict[str, Any]:
        if not hasattr(self, "X_"):
            raise NotFittedError("this KNNReadout is not fitted; call fit first")
        return {"params": {"n_outputs": self.n_outputs, "k": self.k, "weights": self.weights},
                "mean": self.mean_, "scale": self.scale_, "X": self.X_, "y": self.y_}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "KNNReadout":
        r = cls(**state["params"])
        r.mean_, r.scale_ = np.asarray(state["mean"], float), np.asarray(state["scale"], float)
        r.X_, r.y_ = np.asarray(state["X"], float), np.asarray(state["y"], float)
        if (r.X_.ndim != 2 or r.y_.ndim != 2 or len(r.X_) != len(r.y_) or len(r.X_) == 0
                or r.mean_.shape != (r.X_.shape[1],)):
            raise ValueError("invalid KNNReadout state: inconsistent array shapes")
        r._check_scale()
        return r


class KernelRidgeReadout(_KernelMachine):
    """Kernel ridge regression with the Gaussian kernel ``exp(-gamma |a -
    b|^2 / n)`` on the standardised features (``gamma`` relative to the
    number of features ``n``), ridge ``alpha``; the intercept is the
    training mean. The model keeps at most ``max_train`` evenly spaced
    samples (the solve is cubic in their number); a longer run's weights are
    the DTC's, every sample informing them
    (:func:`sfanav.localization.sparse_gp.dtc_weights`)."""

    def __init__(self, n_outputs: int | None = 8, gamma: float = 1.0, alpha: float = 1e-2,
                 max_train: int = 3000) -> None:
        if not gamma > 0 or not alpha > 0:
            raise ValueError(f"gamma and alpha must be positive, got {gamma}, {alpha}")
        self.n_outputs, self.gamma, self.alpha, self.max_train = n_outputs, float(gamma), float(alpha), int(max_train)

    def __repr__(self) -> str:
        return f"KernelRidgeReadout(n_outputs={self.n_outputs}, gamma={self.gamma:g}, alpha={self.alpha:g})"

    def _kernel(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        d2 = (A**2).sum(axis=1)[:, None] + (B**2).sum(axis=1)[None, :] - 2.0 * A @ B.T
        return np.exp(-self.gamma / A.shape[1] * np.maximum(d2, 0.0))

    def fit(self, features: Any, xy: Any) -> "KernelRidgeReadout":
        X = _cols(features, self.n_outputs)
        Y = as_matrix(xy, "xy")
        check_same_length(X, Y, "features", "xy")
        if len(X) > self.max_train:  # the kept samples as inducing points, every sample as data
            keep = evenly_spaced(len(X), self.max_train)
            Xa = self._fit_scale(X)
            self.X_, self.y_mean_ = Xa[keep], Y.mean(axis=0)
            self.dual_ = dtc_weights(self._kernel(self.X_, self.X_), lambda sl: self._kernel(Xa[sl], self.X_),
                                     Y - self.y_mean_, self.alpha)
            return self
        Xs = self._fit_scale(X)
        self.X_ = Xs
        self.y_mean_ = Y.mean(axis=0)
        K = self._kernel(Xs, Xs)
        K[np.diag_indices_from(K)] += self.alpha
        try:  # K + alpha I is symmetric positive definite: Cholesky, ~2x faster than LU
            if cho_factor is None:
                raise ImportError
            self.dual_ = cho_solve(cho_factor(K, overwrite_a=True, check_finite=False), Y - self.y_mean_,
                                   check_finite=False)
        except (ImportError, np.linalg.LinAlgError):
            K = self._kernel(Xs, Xs)
            K[np.diag_indices_from(K)] += self.alpha
            self.dual_ = np.linalg.solve(K, Y - self.y_mean_)
        return self

    def get_state(self) -> dict[str, Any]:
        return {"params": {"n_outputs": self.n_outputs, "gamma": self.gamma, "alpha": self.alpha,
                           "max_train": self.max_train}, **self._arrays()}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "KernelRidgeReadout":
        r = cls(**state["params"])
        r._load_arrays(state)
        return r


def readout_state(spec: dict[str, Any], readout: Any) -> dict[str, Any]:
    """A fitted readout as a model-file state: ``{"spec": spec, "state": ...}``
    (arrays inside; no pickle). Read back with :func:`readout_from_state`."""
    return {"spec": dict(spec), "state": readout.get_state()}


def readout_from_state(state: dict[str, Any]) -> Any:
    """The fitted readout a :func:`readout_state` describes."""
    try:
        kind = state["spec"]["kind"]
        cls = {"quadratic": QuadraticRegression, "knn": KNNReadout, "kernel": KernelRidgeReadout,
               "gp": GPReadout, "gp-signature": SignatureGPReadout, "knn-signature": SignatureKNNReadout}[kind]
        return cls.from_state(state["state"])
    except (KeyError, TypeError) as exc:
        raise ValueError(f"invalid readout state: {exc}") from None


def make_readout(spec: dict[str, Any]) -> Any:
    """A readout from a spec: ``{"kind": "quadratic", "n_outputs", "ridge"}``,
    ``{"kind": "knn", "n_outputs", "k", "weights"}`` or ``{"kind": "kernel",
    "n_outputs", "gamma", "alpha"}`` or ``{"kind": "gp", "n_outputs"}`` (plus
    ``length_scale`` and ``noise`` to fix its hyperparameters) or
    ``{"kind": "gp-signature", "n_outputs", "n_signature"}`` (slow features
    and an appearance signature,
    :class:`sfanav.localization.SignatureGPReadout`) or ``{"kind":
    "knn-signature", "n_signature", "k"}`` (the nearest training views by
    the signature alone, :class:`sfanav.localization.SignatureKNNReadout`)."""
    s = dict(spec)
    kind = s.pop("kind", None)
    if kind == "quadratic":
        return QuadraticRegression(n_outputs=s.pop("n_outputs", 8), ridge=s.pop("ridge", 0.0), degree=s.pop("degree", 2))
    if kind == "knn":
        return KNNReadout(**s)
    if kind == "kernel":
        return KernelRidgeReadout(**s)
    if kind == "gp":
        return GPReadout(**s)
    if kind == "gp-signature":
        return SignatureGPReadout(**s)
    if kind == "knn-signature":
        return SignatureKNNReadout(**s)
    raise ValueError(f"unknown readout kind {kind!r}; use 'quadratic', 'knn', 'kernel', 'gp', 'gp-signature' or "
                     "'knn-signature'")



_KEY_ORDER = ("n_outputs", "n_signature", "k", "weights", "gamma", "alpha", "ridge", "degree", "noise", "length_scale",
              "max_train")


def describe_spec(spec: dict[str, Any]) -> str:
    """A spec in words, e.g. ``kernel(n_outputs=12, gamma=0.5, alpha=0.001)``."""
    s = dict(spec)
    kind = s.pop("kind")
    keys = sorted(s, key=lambda k: (_KEY_ORDER.index(k) if k in _KEY_ORDER else len(_KEY_ORDER), k))
    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:g}"
        if isinstance(v, (list, tuple, np.ndarray)):
            return "[" + " ".join(f"{float(x):.2g}" for x in v) + "]"
        return str(v)

    return kind + "(" + ", ".join(f"{k}={fmt(s[k])}" for k in keys) + ")"


class GPReadout(_KernelMachine):
    """Gaussian-process regression (the posterior mean) with an ARD squared
    exponential kernel ``exp(-sum_i (a_i - b_i)^2 / (2 l_i^2))`` on the
    standardised features plus white noise (Rasmussen and Williams 2006,
    ch. 2 and 5): one length scale ``l_i`` per slow feature, so features
    that do not code position get long scales and drop out.

    The hyperparameters (length scales, signal and noise variance; shared by
    x and y, each standardised) maximise the log marginal likelihood of the
    training run (type-II maximum likelihood, scikit-learn's optimiser) on at
    most ``max_fit`` evenly spaced samples; no cross-validation is needed.
    Given ``length_scale`` and ``noise`` (noise / signal variance) they are
    fixed instead. The model keeps at most ``max_train`` evenly spaced
    samples; a longer run's posterior mean is the DTC's with them as
    inducing points and every sample as data
    (:func:`sfanav.localization.sparse_gp.dtc_weights`).

    Fitted attributes: ``length_scale_`` (n_outputs,), ``noise_`` (noise /
    signal variance), ``log_marginal_likelihood_`` (None if fixed)."""

    def __init__(self, n_outputs: int | None = 12, length_scale: Sequence[float] | None = None,
                 noise: float | None = None, max_fit: int = 1000, max_train: int = 3000) -> None:
        if (length_scale is None) != (noise is None):
            raise ValueError("give both length_scale and noise (fixed hyperparameters) or neither (learned)")
        if length_scale is not None:
            ls = np.asarray(length_scale, float)
            if ls.ndim != 1 or not np.all(np.isfinite(ls)) or np.any(ls <= 0):
                raise ValueError(f"length_scale must be positive finite numbers, got {length_scale!r}")
            if not (np.isfinite(noise) and noise > 0):  # type: ignore[arg-type]
                raise ValueError(f"noise must be positive, got {noise}")
        if int(max_fit) < 2 or int(max_train) < 2:
            raise ValueError(f"max_fit and max_train must be at least 2, got {max_fit}, {max_train}")
        self.n_outputs = n_outputs
        self.length_scale = None if length_scale is None else [float(v) for v in length_scale]
        self.noise = None if noise is None else float(noise)
        self.max_fit, self.max_train = int(max_fit), int(max_train)

    def __repr__(self) -> str:
        return f"GPReadout(n_outputs={self.n_outputs})"

    def _learn(self, Xs: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, float, float]:
        import warnings

        from sklearn.exceptions import ConvergenceWarning
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

        d = Xs.shape[1]
        kernel = (ConstantKernel(1.0, (1e-3, 1e3)) * RBF(np.ones(d), (1e-2, 1e3))
                  + WhiteKernel(1e-2, (1e-8, 1e1)))
        keep = evenly_spaced(len(Xs), self.max_fit)
        with warnings.catch_warnings(), one_blas_thread():  # many factorisations: threads thrash when busy
            warnings.simplefilter("ignore", ConvergenceWarning)  # a length scale at its bound: feature unused
            gp = GaussianProcessRegressor(kernel, normalize_y=True, random_state=0).fit(Xs[keep], Y[keep])
        k = gp.kernel_
        signal, ls, noise = float(k.k1.k1.constant_value), np.atleast_1d(k.k1.k2.length_scale).astype(float), \
            float(k.k2.noise_level)
        return ls, noise / signal, float(gp.log_marginal_likelihood_value_)

    def _kernel(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        d2 = (A**2).sum(axis=1)[:, None] + (B**2).sum(axis=1)[None, :] - 2.0 * A @ B.T
        return np.exp(-0.5 * np.maximum(d2, 0.0))

    def fit(self, features: Any, xy: Any) -> "GPReadout":
        X = _cols(features, self.n_outputs)
        Y = as_matrix(xy, "xy")
        check_same_length(X, Y, "features", "xy")
        if len(X) < 3:
            raise ValueError(f"a GP readout needs at least 3 training samples, got {len(X)}")
        Xs = self._fit_scale(X)
        if self.length_scale is None:
            ls, noise, lml = self._learn(Xs, Y)
        else:
            ls, noise, lml = np.asarray(self.length_scale, float), float(self.noise), None  # type: ignore[arg-type]
            if len(ls) != X.shape[1]:
                raise ValueError(f"length_scale has {len(ls)} entries for {X.shape[1]} features")
        self.length_scale_, self.noise_, self.log_marginal_likelihood_ = ls, noise, lml
        keep = evenly_spaced(len(Xs), self.max_train)
        A, Yk = Xs[keep] / ls, Y[keep]
        if len(keep) < len(Xs):  # the kept samples as inducing points, every sample as data
            self.y_mean_ = Y.mean(axis=0)
            Z = Xs / ls
            self.dual_ = dtc_weights(self._kernel(A, A), lambda sl: self._kernel(Z[sl], A), Y - self.y_mean_,
                                     max(noise, 1e-10))
            self.X_ = A
            return self
        self.y_mean_ = Yk.mean(axis=0)
        K = self._kernel(A, A)
        K[np.diag_indices_from(K)] += max(noise, 1e-10)
        try:
            self.dual_ = cho_solve(cho_factor(K, overwrite_a=True, check_finite=False), Yk - self.y_mean_,
                                   check_finite=False)
        except np.linalg.LinAlgError:
            K = self._kernel(A, A)
            K[np.diag_indices_from(K)] += max(noise, 1e-10)
            self.dual_ = np.linalg.lstsq(K, Yk - self.y_mean_, rcond=None)[0]
        self.X_ = A
        return self

    def _query(self, Q: np.ndarray) -> np.ndarray:
        return Q / self.length_scale_

    def fixed_spec(self) -> dict[str, Any]:
        """The spec of this readout with its learned hyperparameters fixed
        (refitting it only solves for the posterior mean)."""
        if not hasattr(self, "length_scale_"):
            raise NotFittedError("this GPReadout is not fitted; call fit first")
        return {"kind": "gp", "n_outputs": self.n_outputs, "length_scale": [float(v) for v in self.length_scale_],
                "noise": float(self.noise_)}

    def get_state(self) -> dict[str, Any]:
        arrays = self._arrays()
        return {"params": {"n_outputs": self.n_outputs, "max_fit": self.max_fit, "max_train": self.max_train},
                **arrays, "length_scale": self.length_scale_, "noise": float(self.noise_)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "GPReadout":
        r = cls(**state["params"])
        r._load_arrays(state)
        r.length_scale_, r.noise_ = np.asarray(state["length_scale"], float), float(state["noise"])
        r.log_marginal_likelihood_ = None
        if r.length_scale_.shape != r.mean_.shape or not np.all(r.length_scale_ > 0):
            raise ValueError("invalid GPReadout state: inconsistent array shapes")
        return r
