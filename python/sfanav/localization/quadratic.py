"""The thesis's readout (3.5): least-squares regression from the quadratically
expanded ``n`` slowest SFA outputs to metric (x, y), with an optional ridge
penalty (:class:`QuadraticRegression`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import (
    NotFittedError,
    as_matrix,
    check_int,
    check_nonneg_float,
    check_same_length,
)
from ..sfa.node import expand, expanded_dim
from .error_metrics import euclidean_errors
from .extrapolation import MARGIN, count_extrapolated, training_bounds, warn_extrapolated


def fit_weights(E: np.ndarray, y: np.ndarray, ridge: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Least squares ``y ~ E @ coef + intercept`` (intercept not penalised)."""
    mu_e, mu_y = E.mean(axis=0), y.mean(axis=0)
    Ec, yc = E - mu_e, y - mu_y
    if ridge == 0.0:
        coef, _, rank, _ = np.linalg.lstsq(Ec, yc, rcond=None)
    else:
        G = Ec.T @ Ec
        G[np.diag_indices_from(G)] += ridge
        coef = np.linalg.solve(G, Ec.T @ yc)
        rank = E.shape[1]
    return coef, mu_y - mu_e @ coef, int(rank)


class QuadraticRegression:
    """Polynomial (default quadratic) regression from the ``n_outputs`` slowest
    SFA outputs to metric coordinates (thesis 3.5).

    The first ``n_outputs`` columns of the features are expanded with
    :func:`sfanav.expand` (all monomials of degree 1..``degree``), then a
    linear least-squares fit with intercept maps them to the targets.

    Parameters
    ----------
    n_outputs : int or None, default 8
        Number of slowest outputs used (the thesis's best n was 8 of 2..12).
        None: all columns.
    ridge : float, default 0.0
        L2 penalty on the coefficients of the centred expanded features (the
        intercept is not penalised). 0 is ordinary least squares (minimum-norm
        solution if rank deficient).
    degree : int, default 2
        Degree of the polynomial expansion.

    Attributes
    ----------
    coef_ : ndarray of shape (n_expanded, n_targets)
    intercept_ : ndarray of shape (n_targets,)
    n_outputs_ : int
        Feature columns used.
    n_features_in_ : int
        Feature columns seen in :meth:`fit` (>= ``n_outputs_``).
    rank_ : int
        Rank of the centred design matrix.
    target_bounds_ : ndarray of shape (2, n_targets)
        Bounding box of the training targets (minimum, maximum per axis).
    n_extrapolated_ : int
        Estimates :meth:`predict` returned farther than
        ``extrapolation_margin`` times the box's diagonal outside it, since
        fit (the first such call warns with
        :class:`~sfanav.localization.extrapolation.ExtrapolationWarning`).

    Class attribute ``extrapolation_margin`` (default 0.5) sets that margin.
    """

    extrapolation_margin: float = MARGIN

    def __init__(self, n_outputs: int | None = 8, ridge: float = 0.0, degree: int = 2) -> None:
        self.n_outputs = n_outputs
        self.ridge = ridge
        self.degree = degree

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {"n_outputs": self.n_outputs, "ridge": self.ridge, "degree": self.degree}

    def set_params(self, **params: Any) -> "QuadraticRegression":
        for k, v in params.items():
            if k not in self.get_params():
                raise ValueError(f"unknown parameter {k!r} for QuadraticRegression")
            setattr(self, k, v)
        return self

    def __repr__(self) -> str:
        return f"QuadraticRegression(n_outputs={self.n_outputs!r}, ridge={self.ridge!r}, degree={self.degree!r})"

    def _design(self, features: Any, n: int, name: str = "features") -> np.ndarray:
        F = as_matrix(features, name)
        if F.shape[1] < n:
            raise ValueError(f"{name} has {F.shape[1]} columns, but the regression uses the first {n}")
        return expand(np.ascontiguousarray(F[:, :n]), self.degree)

    def fit(self, features: Any, xy: Any) -> "QuadraticRegression":
        """Fits on slow features (N, m), slowest first, and targets (N, d),
        usually positions (N, 2) in metres. Returns ``self``."""
        F = as_matrix(features, "features")
        Y = as_matrix(xy, "xy")
        check_same_length(F, Y, "features", "xy")
        n = F.shape[1] if self.n_outputs is None else check_int(self.n_outputs, "n_outputs")
        degree = check_int(self.degree, "degree")
        ridge = check_nonneg_float(self.ridge, "ridge")
        if n > F.shape[1]:
            raise ValueError(f"n_outputs={n}, but features have only {F.shape[1]} columns")
        if len(F) < 2:
            raise ValueError(f"the regression needs at least 2 samples, got {len(F)}")
        E = expand(np.ascontiguousarray(F[:, :n]), degree)
        self.coef_, self.intercept_, self.rank_ = fit_weights(E, Y, ridge)
        self.n_outputs_ = n
        self.n_features_in_ = F.shape[1]
        self.n_targets_ = Y.shape[1]
        self.target_bounds_ = training_bounds(Y)
        self.n_extrapolated_ = 0
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise NotFittedError("this QuadraticRegression is not fitted yet; call fit first")

    def predict(self, features: Any) -> np.ndarray:
        """Estimated targets (N, d) from features (N, m >= n_outputs_)."""
        self._check_fitted()
        P = self._design(features, self.n_outputs_) @ self.coef_ + self.intercept_
        bounds = getattr(self, "target_bounds_", None)
        if bounds is not None:
            n = count_extrapolated(P, bounds, self.extrapolation_margin)
            if n:
                if not getattr(self, "n_extrapolated_", 0):
                    warn_extrapolated(n, len(P), bounds, self.extrapolation_margin, "QuadraticRegression")
                self.n_extrapolated_ = getattr(self, "n_extrapolated_", 0) + n
        return P

    def score(self, features: Any, xy: Any) -> float:
        """Mean Euclidean distance (MED, metres) of the estimates from ``xy``.
        Lower is better (unlike scikit-learn's ``score``, which is higher-is-better R^2)."""
        return float(euclidean_errors(self.predict(features), xy).mean())

    # ---------------------------------------------------------- persistence
    def get_state(self) -> dict[str, Any]:
        self._check_fitted()
        return {
            "params": {"n_outputs": self.n_outputs_, "ridge": float(self.ridge), "degree": int(self.degree)},
            "coef": self.coef_,
            "intercept": self.intercept_,
            "rank": self.rank_,
            "n_features_in": self.n_features_in_,
            **({"target_bounds": self.target_bounds_} if hasattr(self, "target_bounds_") else {}),
        }

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "QuadraticRegression":
        try:
            reg = cls(**state["params"])
            reg.coef_ = np.asarray(state["coef"], dtype=np.float64)
            reg.intercept_ = np.asarray(state["intercept"], dtype=np.float64)
            reg.rank_ = int(state["rank"])
            reg.n_outputs_ = int(state["params"]["n_outputs"])
            reg.n_features_in_ = int(state["n_features_in"])
            if "target_bounds" in state:  # absent in models saved before the extrapolation check
                reg.target_bounds_ = np.asarray(state["target_bounds"], dtype=np.float64)
                reg.n_extrapolated_ = 0
        except (KeyError, TypeError) as exc:
            raise ValueError(f"invalid QuadraticRegression state: {exc}") from None
        bounds = getattr(reg, "target_bounds_", None)
        if bounds is not None and bounds.shape != (2, reg.intercept_.shape[-1]):
            raise ValueError(f"invalid QuadraticRegression state: target_bounds has shape {bounds.shape}")
        want = expanded_dim(reg.n_outputs_, reg.degree)
        if reg.coef_.ndim != 2 or reg.coef_.shape[0] != want or reg.intercept_.shape != (reg.coef_.shape[1],):
            raise ValueError(
                f"invalid QuadraticRegression state: coefficients of shape {reg.coef_.shape} do not fit "
                f"{reg.n_outputs_} outputs at degree {reg.degree} ({want} expanded features)"
            )
        reg.n_targets_ = reg.coef_.shape[1]
        return reg
