"""One SFA node and its statistics (thesis chapter 3).

* :class:`SFA`: Slow Feature Analysis with an optional polynomial expansion,
  scikit-learn style (``fit``, ``partial_fit``, ``transform``,
  ``n_components``); several sequences are separated by passing a list.
* :class:`Statistics`: the covariance and derivative-covariance accumulator
  (f64, centred, mergeable with :meth:`Statistics.merge`).
* :func:`expand`, :func:`expanded_dim`: the monomial expansion;
  :func:`beta_values` turns delta values into beta values.

The numerics run in the Rust core (``sfanav._core``)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from .. import _core
from .._checks import NotFittedError, as_float_2d, check_positive_int
from .modelfile import dumps, register_loader, save_model, state_from_bytes


def beta_values(delta: np.ndarray) -> np.ndarray:
    """``beta = sqrt(Delta) / (2 pi)`` (thesis section 7.2.1): the number of
    oscillations per time step of a sine wave with that Delta value."""
    delta = np.asarray(delta, dtype=np.float64)
    return np.sqrt(np.clip(delta, 0.0, None)) / (2.0 * np.pi)


def _sequences(X: Any) -> list[np.ndarray]:
    """One array -> one sequence; a list/tuple of arrays -> separate sequences."""
    if isinstance(X, (list, tuple)) and len(X) > 0 and all(
        isinstance(x, np.ndarray) and x.ndim == 2 for x in X
    ):
        seqs = [as_float_2d(x, f"X[{i}]") for i, x in enumerate(X)]
        widths = {s.shape[1] for s in seqs}
        if len(widths) != 1:
            raise ValueError(f"all sequences must have the same number of features, got {sorted(widths)}")
        return seqs
    return [as_float_2d(X, "X")]


class SFA:
    """Slow Feature Analysis (Wiskott and Sejnowski 2002; thesis section 3.2).

    Finds functions of the input whose outputs vary as slowly as possible
    over time (smallest mean squared time derivative, Delta) under zero mean,
    unit variance and decorrelation.

    Parameters
    ----------
    n_components : int
        Number of slow features to extract (slowest first).
    degree : int, default 1
        Degree of the polynomial expansion applied before SFA (1 = linear
        SFA, 2 = quadratic SFA, ...). See :func:`sfanav.expand` for the order
        of the monomials.
    reduce_to : int or None, default None
        If given, the thesis's network node (section 3.4.2): linear SFA to
        ``reduce_to`` dimensions, then the expansion of those signals to
        ``degree``, then SFA to ``n_components``. Training then takes two
        passes over the data.
    tol : float, default 1e-10
        Relative tolerance: directions of the input covariance with variance
        at most ``tol`` times the largest are dropped (and counted in
        ``rank_deficit_``) instead of being divided by. If fewer than
        ``n_components`` directions remain, fitting raises ValueError.
    precision : {"double", "mixed"}, default "double"
        "mixed" forms the outer products of each cache-sized block of rows
        in float32 and sums them in float64: faster statistics (docs/benchmarks.md),
        relative error about 1e-6 instead of 1e-15, and ``tol`` is raised to
        at least 1e-6. For image-derived data; keep "double" otherwise.

    Attributes
    ----------
    delta_values_ : ndarray of shape (n_components,)
        Delta value of each output on the training data, ascending: the mean
        squared difference of consecutive outputs (unit time step).
    beta_values_ : ndarray of shape (n_components,)
        ``sqrt(delta_values_) / (2 pi)``.
    n_features_in_ : int
        Number of input features seen in training.
    n_components_ : int
        Number of outputs.
    rank_deficit_ : int
        Number of covariance directions dropped by the final SFA step.
    rank_deficits_ : list of int
        The same for every stage (reduction stage first).

    Notes
    -----
    Time runs along axis 0. The covariance is the population covariance
    (divided by the number of samples), so training outputs have exactly
    zero mean and unit variance with ``np.std(..., ddof=0)``; Delta is the
    mean over derivative pairs. Consecutive calls to :meth:`partial_fit`
    continue one sequence unless ``new_sequence=True``; :meth:`fit` with a
    list of arrays treats each as its own sequence (no derivative between
    them). Float32 and float64 inputs are read in place (no copy, any
    strides); arithmetic is float64; outputs have the input's dtype. Heavy
    work runs in Rust, in parallel, with the GIL released.

    Examples
    --------
    >>> import numpy as np, sfanav
    >>> t = np.linspace(0, 2 * np.pi, 5000)
    >>> X = np.c_[np.sin(t) + np.cos(11 * t) ** 2, np.cos(11 * t)]
    >>> y = sfanav.SFA(1, degree=2).fit_transform(X)
    >>> abs(np.corrcoef(y[:, 0], np.sin(t))[0, 1]) > 0.99
    True
    """

    def __init__(
        self,
        n_components: int = 2,
        degree: int = 1,
        reduce_to: int | None = None,
        tol: float = _core.DEFAULT_TOL,
        precision: str = "double",
    ) -> None:
        self.n_components = n_components
        self.degree = degree
        self.reduce_to = reduce_to
        self.tol = tol
        self.precision = precision
        self._node: _core.SfaNode | None = None

    # ------------------------------------------------------------ params
    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {
            "n_components": self.n_components,
            "degree": self.degree,
            "reduce_to": self.reduce_to,
            "tol": self.tol,
            "precision": self.precision,
        }

    def set_params(self, **params: Any) -> "SFA":
        for k, v in params.items():
            if k not in self.get_params():
                raise ValueError(f"unknown parameter {k!r} for SFA")
            setattr(self, k, v)
        self._node = None
        return self

    def __repr__(self) -> str:
        args = ", ".join(
            f"{k}={v!r}"
            for k, v in self.get_params().items()
            if v != {"degree": 1, "reduce_to": None, "tol": _core.DEFAULT_TOL, "precision": "double"}.get(k, object())
        )
        return f"SFA({args})"

    def _new_node(self) -> _core.SfaNode:
        n = check_positive_int(self.n_components, "n_components")
        d = check_positive_int(self.degree, "degree")
        k = check_positive_int(self.reduce_to, "reduce_to", allow_none=True)
        if isinstance(self.tol, (bool, np.bool_)) or not isinstance(self.tol, (int, float, np.floating)):
            raise TypeError(f"tol must be a float, got {type(self.tol).__name__}")
        if self.precision not in ("double", "mixed"):
            raise ValueError(f"precision must be 'double' or 'mixed', got {self.precision!r}")
        return _core.SfaNode(n, degree=d, reduce_to=k, tol=float(self.tol), mixed_precision=self.precision == "mixed")

    # ------------------------------------------------------------ training
    def fit(self, X: np.ndarray | Sequence[np.ndarray], y: None = None) -> "SFA":
        """Fits on one time series ``X`` of shape (n_samples, n_features), or
        on a list of such arrays, each its own sequence. Returns ``self``."""
        seqs = _sequences(X)
        if sum(len(s) for s in seqs) < 2:
            raise ValueError("SFA needs at least 2 samples to fit")
        node = self._new_node()
        for stage in range(node.n_stages):
            for s in seqs:
                node.partial_fit(s, new_sequence=True)
            if stage + 1 < node.n_stages:
                node.finish_stage()
        node.ensure_solved()
        self._node = node
        return self

    def partial_fit(self, X: np.ndarray, y: None = None, *, new_sequence: bool = False) -> "SFA":
        """Feeds one chunk of a time series (streaming training).

        Consecutive chunks continue one sequence (the derivative between the
        last sample of one chunk and the first of the next is used) unless
        ``new_sequence=True``. With ``reduce_to`` set the model trains in two
        passes: feed every chunk, call :meth:`finish_stage`, feed every chunk
        again. The model is solved lazily when a fitted attribute or
        :meth:`transform` is used. After :meth:`fit`, ``partial_fit`` adds
        data to the final stage only (a reduction stage stays as fitted).
        """
        X = as_float_2d(X, "X")
        if self._node is None:
            self._node = self._new_node()
        self._node.partial_fit(X, new_sequence=bool(new_sequence))
        return self

    def finish_stage(self) -> "SFA":
        """Ends a training pass of a two-stage model (``reduce_to`` set): solves
        the reduction stage so the next pass of :meth:`partial_fit` trains the
        final stage."""
        if self._node is None:
            raise NotFittedError("no training data was given to this SFA")
        self._node.finish_stage()
        return self

    @property
    def n_passes_(self) -> int:
        """Number of passes over the data the model needs (1, or 2 with ``reduce_to``)."""
        return self._fitted_node(solve=False).n_stages

    # ------------------------------------------------------------ inference
    def _fitted_node(self, solve: bool = True) -> _core.SfaNode:
        if self._node is None:
            raise NotFittedError(
                "this SFA instance is not fitted yet; call fit or partial_fit first"
            )
        if solve and not self._node.is_solved:
            if self._node.training_stage + 1 < self._node.n_stages:
                raise NotFittedError(
                    "the reduction stage is still in training: call finish_stage() after the "
                    "first full pass of partial_fit, then feed the data again"
                )
            self._node.ensure_solved()
        return self._node

    def transform(self, X: np.ndarray) -> np.ndarray:
        """Slow features of ``X``: (n_samples, n_features) -> (n_samples,
        n_components), same dtype as ``X`` (float32 or float64)."""
        node = self._fitted_node()
        X = as_float_2d(X, "X")
        if X.shape[1] != node.n_features:
            raise ValueError(
                f"X has {X.shape[1]} features, but this SFA was fitted with {node.n_features}"
            )
        return node.transform(X)

    def fit_transform(self, X: np.ndarray | Sequence[np.ndarray], y: None = None) -> np.ndarray:
        """Fits and returns the slow features of the training data (for a list
        of sequences, concatenated in order)."""
        self.fit(X)
        seqs = _sequences(X)
        return np.concatenate([self.transform(s) for s in seqs]) if len(seqs) > 1 else self.transform(seqs[0])

    # ------------------------------------------------------------ attributes
    @property
    def delta_values_(self) -> np.ndarray:
        return self._fitted_node().delta_values

    @property
    def beta_values_(self) -> np.ndarray:
        return beta_values(self.delta_values_)

    @property
    def n_features_in_(self) -> int:
        n = self._fitted_node(solve=False).n_features
        if n is None:
            raise NotFittedError("this SFA instance has seen no data")
        return n

    @property
    def n_components_(self) -> int:
        return self._fitted_node().stage_outputs[-1]

    @property
    def rank_deficits_(self) -> list[int]:
        return list(self._fitted_node().rank_deficits)

    @property
    def rank_deficit_(self) -> int:
        return self.rank_deficits_[-1]

    @property
    def statistics_(self) -> "Statistics":
        """Training statistics of the (last) stage in training."""
        st = self._fitted_node(solve=False).statistics()
        if st is None:
            raise NotFittedError("this model was saved without its training statistics")
        return Statistics._wrap(st)

    # ------------------------------------------------------------ persistence
    def _state(self, include_statistics: bool) -> dict[str, Any]:
        return {
            "params": {k: v for k, v in self.get_params().items()},
            "node": None if self._node is None else self._node.get_state(include_statistics),
        }

    def save(self, path: str | os.PathLike, *, include_statistics: bool = True) -> None:
        """Saves the model to ``path`` (see :mod:`sfanav.sfa.modelfile`; no pickle).

        With ``include_statistics`` (default) the training statistics are
        stored too, so :meth:`partial_fit` can continue after loading.
        """
        save_model(path, "SFA", self._state(include_statistics))

    def to_bytes(self, *, include_statistics: bool = True) -> bytes:
        """The model as the bytes of its model file (no pickle)."""
        return dumps("SFA", self._state(include_statistics))

    @classmethod
    def from_bytes(cls, data: bytes) -> "SFA":
        """A model from :meth:`to_bytes`. Raises ValueError for bytes that are
        not an unaltered SFA model, TypeError for another type."""
        return cls.from_state(state_from_bytes(data, "SFA"))

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        return (SFA.from_bytes, (self.to_bytes(),))

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "SFA":
        try:
            params = state["params"]
            model = cls(**params)
            node_state = state["node"]
        except (KeyError, TypeError) as exc:
            raise ValueError(f"invalid SFA model state: {exc}") from None
        if node_state is not None:
            model._node = _core.SfaNode.from_state(node_state)
        return model


register_loader("SFA", SFA.from_state)


def expand(X: np.ndarray, degree: int) -> np.ndarray:
    """All monomials of degree 1..``degree`` of the features of ``X``.

    ``X`` (n_samples, D) -> (n_samples, C(D + degree, degree) - 1), same
    dtype. Order: by degree; within a degree, index tuples ``i <= j <= ...``
    in lexicographic order, e.g. for D = 3, degree 2:
    ``x0, x1, x2, x0x0, x0x1, x0x2, x1x1, x1x2, x2x2`` (MDP's order).
    """
    X = as_float_2d(X, "X")
    d = check_positive_int(degree, "degree")
    return _core.expand(X, d)


def expanded_dim(n_features: int, degree: int) -> int:
    """Output width of :func:`expand`: ``C(n_features + degree, degree) - 1``."""
    return _core.expanded_dim(check_positive_int(n_features, "n_features"), check_positive_int(degree, "degree"))


class Statistics:
    """Streaming, mergeable SFA statistics: mean, covariance and derivative
    covariance of a time series, accumulated in float64.

    ``update(X)`` feeds consecutive samples of a sequence (chunks continue the
    sequence unless ``new_sequence=True``); ``add_samples`` and
    ``add_pairs`` take weighted samples and weighted derivative pairs
    directly; ``merge`` combines accumulators exactly (parallel or
    distributed training, e.g. one per dask chunk).
    """

    def __init__(self, n_features: int) -> None:
        self._acc = _core.Statistics(check_positive_int(n_features, "n_features"))

    @classmethod
    def _wrap(cls, acc: _core.Statistics) -> "Statistics":
        obj = cls.__new__(cls)
        obj._acc = acc
        return obj

    @classmethod
    def from_core(cls, acc: _core.Statistics) -> "Statistics":
        """Wraps statistics the Rust core made (e.g. a partition's, in
        :mod:`sfanav.sfa.distributed`); no copy."""
        if not isinstance(acc, _core.Statistics):
            raise TypeError(f"expected sfanav._core.Statistics, got {type(acc).__name__}")
        return cls._wrap(acc)

    def update(self, X: np.ndarray, *, new_sequence: bool = False) -> "Statistics":
        self._acc.update(as_float_2d(X, "X", min_samples=0), new_sequence=bool(new_sequence))
        return self

    def add_samples(self, X: np.ndarray, weights: np.ndarray | None = None) -> "Statistics":
        X = as_float_2d(X, "X", min_samples=0)
        self._acc.add_samples(X, None if weights is None else _weights(weights, len(X)))
        return self

    def add_pairs(self, A: np.ndarray, B: np.ndarray, weights: np.ndarray | None = None) -> "Statistics":
        """Adds derivative pairs ``B[i] - A[i]`` with optional weights."""
        A = as_float_2d(A, "A", min_samples=0)
        B = as_float_2d(B, "B", min_samples=0)
        if A.dtype != B.dtype:
            A, B = A.astype(np.float64, copy=False), B.astype(np.float64, copy=False)
        self._acc.add_pairs(A, B, None if weights is None else _weights(weights, len(A)))
        return self

    def break_sequence(self) -> "Statistics":
        self._acc.break_sequence()
        return self

    def merge(self, other: "Statistics", *, continuing: bool = False) -> "Statistics":
        """Adds ``other``'s statistics. With ``continuing=True`` ``other`` is the
        continuation of this sequence (the pair across the boundary is added)."""
        if not isinstance(other, Statistics):
            raise TypeError(f"can only merge Statistics, got {type(other).__name__}")
        (self._acc.merge_continuing if continuing else self._acc.merge)(other._acc)
        return self

    def copy(self) -> "Statistics":
        return Statistics._wrap(self._acc.copy())

    def mean(self) -> np.ndarray:
        return self._acc.mean()

    def covariance(self) -> np.ndarray:
        return self._acc.covariance()

    def derivative_covariance(self) -> np.ndarray:
        return self._acc.derivative_covariance()

    @property
    def n_features(self) -> int:
        return self._acc.dim

    @property
    def n_samples(self) -> int:
        return self._acc.n_samples

    @property
    def n_pairs(self) -> int:
        return self._acc.n_pairs

    @property
    def weight_sum(self) -> float:
        return self._acc.weight_sum

    @property
    def pair_weight_sum(self) -> float:
        return self._acc.pair_weight_sum

    def __repr__(self) -> str:
        return f"Statistics(n_features={self.n_features}, n_samples={self.n_samples}, n_pairs={self.n_pairs})"

    def get_state(self) -> dict[str, Any]:
        return self._acc.get_state()

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "Statistics":
        return cls._wrap(_core.Statistics.from_state(state))

    def to_bytes(self) -> bytes:
        """The statistics as the bytes of an sfanav model (checksummed, no
        pickle): for shipping accumulators between processes, e.g. to merge
        the partial statistics of several workers.

        Examples
        --------
        >>> a = Statistics(3).update(np.random.default_rng(0).normal(size=(50, 3)))
        >>> Statistics.from_bytes(a.to_bytes()).n_samples
        50
        """
        return dumps("Statistics", self.get_state())

    @classmethod
    def from_bytes(cls, data: bytes) -> "Statistics":
        """Statistics from :meth:`to_bytes`. Raises ValueError for bytes that
        are not unaltered statistics, TypeError for another type."""
        return cls.from_state(state_from_bytes(data, "Statistics"))

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        # pickle (e.g. Dask shipping an accumulator) goes through the checked bytes
        return (Statistics.from_bytes, (self.to_bytes(),))


def _weights(w: Any, n: int) -> np.ndarray:
    w = np.ascontiguousarray(w, dtype=np.float64)
    if w.ndim != 1 or len(w) != n:
        raise ValueError(f"weights must be 1-D of length {n}, got shape {w.shape}")
    return w
