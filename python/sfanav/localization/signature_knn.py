"""A readout by appearance alone: the position of the training views whose
signatures are nearest to the query's.

:class:`SignatureKNNReadout` stores the appearance signature (the last
``n_signature`` columns of a feature row, e.g. the rotation-invariant
Fourier signature of the photometrically normalised panorama) of each
training view with its position, and answers a query with the
inverse-distance weighted mean position of the ``k`` views nearest in L1
distance. It is place recognition over stored views, as the classic peers
do, on the product's normalised signature; it reads no slow feature.

The sfanav default does not use it on one run: there the Gaussian process of
slow features and signature (:class:`SignatureGPReadout`) interpolates
between the places of the run. When the training set is several recordings
of the same places in different light or seasons, a query in a light no
recording showed may find the slow features less invariant than the stored
views' signatures are close; leave-one-recording-out cross-validation
(:func:`sfanav.localization.select_auto_readout` with ``groups``) then
chooses between the two (docs/localization.md, "Several recordings").
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import NotFittedError, as_matrix, check_int, check_same_length
from .._sampling import evenly_spaced
from .signature_distance import l1_distances


class SignatureKNNReadout:
    """k nearest training views by the L1 distance of their signatures.

    Parameters
    ----------
    n_signature : int
        Length of the signature: the last ``n_signature`` columns of the
        features (the columns before it are ignored).
    k : int, default 1
        Views averaged per query (inverse-distance weights; an exact match
        takes its view's position).
    max_train : int, default 10000
        Views kept at most (evenly spaced over the run beyond that): each
        costs ``4 * n_signature`` bytes in the model and its distance at
        every query.

    Fitted attributes: ``G_`` (m, n_signature) float32 signatures of the
    kept views, ``y_`` (m, 2) their positions (m), ``views_`` (m,) their
    indices among the samples given to :meth:`fit` (None after loading).

    Examples
    --------
    >>> import numpy as np
    >>> xy = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    >>> G = np.array([[0.0, 1.0], [1.0, 1.0], [2.0, 1.0]])
    >>> r = SignatureKNNReadout(n_signature=2).fit(G, xy)
    >>> r.predict(np.array([[1.1, 1.0]])).tolist()
    [[1.0, 0.0]]
    """

    def __init__(self, n_signature: int = 1, k: int = 1, max_train: int = 10000, n_outputs: int = 0) -> None:
        self.n_signature = check_int(n_signature, "n_signature", minimum=1)
        self.k = check_int(k, "k", minimum=1)
        self.max_train = check_int(max_train, "max_train", minimum=1)
        if check_int(n_outputs, "n_outputs", minimum=0) != 0:
            raise ValueError(f"a SignatureKNNReadout reads no slow features: n_outputs must be 0, got {n_outputs}")
        self.n_outputs = 0

    def __repr__(self) -> str:
        return f"SignatureKNNReadout(n_signature={self.n_signature}, k={self.k}, max_train={self.max_train})"

    def _signature(self, features: Any, name: str = "features") -> np.ndarray:
        X = as_matrix(features, name)
        if X.shape[1] < self.n_signature:
            raise ValueError(f"{name} have {X.shape[1]} columns; this readout reads a signature of "
                             f"{self.n_signature} values")
        return X[:, X.shape[1] - self.n_signature :]

    def fit(self, features: Any, xy: Any, *, views: Any = None) -> "SignatureKNNReadout":
        """Stores the signatures of features (N, >= n_signature) with their
        positions (N, 2).

        ``views``: indices of the samples to store (default all), e.g. the
        originals of a run fitted together with corrupted copies of its
        images: a copy's signature beside the clean one of the same place
        only gives a clean query a second, worse candidate (measured in
        docs/localization.md). At most ``max_train`` of them are kept,
        evenly spaced.

        Raises ValueError for mismatched or non-finite inputs and for
        ``views`` outside ``range(N)`` or empty."""
        G = self._signature(features)
        Y = as_matrix(xy, "xy", n_cols=2)
        check_same_length(G, Y, "features", "xy")
        idx = np.arange(len(G)) if views is None else np.asarray(views)
        if idx.ndim != 1 or idx.size == 0 or idx.dtype.kind not in "iu":
            raise ValueError(f"views must be a non-empty 1-D array of sample indices, got shape {idx.shape}, "
                             f"dtype {idx.dtype}")
        if idx.min() < 0 or idx.max() >= len(G):
            raise ValueError(f"views must index the {len(G)} samples, got indices {idx.min()}..{idx.max()}")
        if len(idx) > self.max_train:
            idx = idx[evenly_spaced(len(idx), self.max_train)]
        self.views_ = idx.astype(np.int64)
        self.G_ = np.ascontiguousarray(G[idx], dtype=np.float32)
        self.y_ = np.array(Y[idx], dtype=np.float64)
        return self

    def predict(self, features: Any, chunk: int = 256) -> np.ndarray:
        """Positions (N, 2) of features (N, >= n_signature): the
        inverse-distance weighted mean of the ``k`` nearest views'."""
        if not hasattr(self, "G_"):
            raise NotFittedError("this SignatureKNNReadout is not fitted; call fit first")
        G = self._signature(features)
        k = min(self.k, len(self.G_))
        out = np.empty((len(G), 2))
        Gt = self.G_.astype(np.float64)
        for s in range(0, len(G), chunk):
            D = l1_distances(G[s : s + chunk].astype(np.float64), Gt)
            idx = np.argpartition(D, k - 1, axis=1)[:, :k] if k < len(Gt) else np.tile(np.arange(k), (len(D), 1))
            w = 1.0 / np.maximum(np.take_along_axis(D, idx, axis=1), 1e-12)
            w /= w.sum(axis=1, keepdims=True)
            out[s : s + chunk] = np.einsum("qk,qkd->qd", w, self.y_[idx])
        return out

    def get_state(self) -> dict[str, Any]:
        if not hasattr(self, "G_"):
            raise NotFittedError("this SignatureKNNReadout is not fitted; call fit first")
        return {"params": {"n_signature": self.n_signature, "k": self.k, "max_train": self.max_train},
                "G": self.G_, "y": self.y_}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "SignatureKNNReadout":
        r = cls(**state["params"])
        r.G_, r.y_ = np.asarray(state["G"], np.float32), np.asarray(state["y"], float)
        r.views_ = None
        if r.G_.ndim != 2 or r.G_.shape[1] != r.n_signature or r.y_.shape != (len(r.G_), 2) or len(r.G_) == 0:
            raise ValueError("invalid SignatureKNNReadout state: inconsistent array shapes")
        if not (np.all(np.isfinite(r.G_)) and np.all(np.isfinite(r.y_))):
            raise ValueError("invalid SignatureKNNReadout state: non-finite values")
        return r
