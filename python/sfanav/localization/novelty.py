"""How far an image's slow features lie from those of the training run: the
novelty of a query, the evidence that its estimate is an extrapolation.

A readout fitted on one exploration run answers every image with a
position, also where the robot never drove in training; there its
estimates can be metres off and still move smoothly, so that a filter
cannot tell them from good ones. The slow features show it: on ground the
training covered an image's nearest training image (in the standardised
slowest features) is about as near as training images are to each other,
off it several times farther (docs/odometry.md, "Fusion off the training
run's ground").

:class:`NoveltyReference` keeps the training features (standardised per
column) and their typical nearest-neighbour distance; :meth:`score` is a
query's distance to its nearest training feature in units of that
distance (about 1 on covered ground). :func:`sfanav.odometry.fuse` scales
the filter's measurement noise by it.

Example
-------
>>> rng = np.random.default_rng(0)
>>> ref = NoveltyReference().fit(rng.normal(size=(500, 4)))
>>> near, far = ref.score(np.vstack([rng.normal(size=(1, 4)), 6 + np.zeros((1, 4))]))
>>> bool(near < 2.5 < far)
True
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._checks import as_matrix

MAX_REFERENCE = 20000
"""At most this many training features are kept (evenly spaced in the run):
the score's cost and the model file's size stay bounded (8 features x
20000 x 8 bytes = 1.3 MB)."""


class NoveltyReference:
    """Training features and their nearest-neighbour scale (see the module
    docstring).

    Attributes (after :meth:`fit`)
    ------------------------------
    reference_ : ndarray (M, m)
        The training features, divided by ``scale_`` (M <= :data:`MAX_REFERENCE`).
    scale_ : ndarray (m,)
        Their standard deviation per column (1 for a constant column).
    unit_ : float
        The median distance of a training feature to its nearest other one
        (standardised units; > 0).
    """

    def fit(self, features: Any) -> "NoveltyReference":
        """Fits on the training features (N, m), N >= 2, finite. Returns self.
        Raises ValueError for fewer than two rows or non-finite values."""
        F = as_matrix(features, "features")
        if len(F) < 2:
            raise ValueError(f"a novelty reference needs at least 2 training features, got {len(F)}")
        if len(F) > MAX_REFERENCE:
            F = F[np.linspace(0, len(F) - 1, MAX_REFERENCE).round().astype(int)]
        s = F.std(axis=0)
        self.scale_ = np.where(s > 0, s, 1.0)
        self.reference_ = F / self.scale_
        self._tree = cKDTree(self.reference_)
        d = self._tree.query(self.reference_, k=2)[0][:, 1]
        pos = d[d > 0]
        self.unit_ = float(np.median(pos)) if len(pos) else 1.0
        return self

    def score(self, features: Any) -> np.ndarray:
        """Novelty (N,) of features (N, m): the distance to the nearest
        training feature in units of :attr:`unit_` (about 1 on covered
        ground, 0 on a training image). Raises ValueError for a column count
        other than the training's or non-finite values."""
        if not hasattr(self, "reference_"):
            raise ValueError("this NoveltyReference is not fitted: call fit(features) first")
        F = as_matrix(features, "features", min_rows=0)
        if F.shape[1] != self.reference_.shape[1]:
            raise ValueError(f"features have {F.shape[1]} columns, the reference {self.reference_.shape[1]}")
        if len(F) == 0:
            return np.zeros(0)
        return self._tree.query(F / self.scale_, k=1)[0] / self.unit_

    def get_state(self) -> dict[str, Any]:
        return {"reference": self.reference_, "scale": self.scale_, "unit": float(self.unit_)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "NoveltyReference":
        """Rebuilds from :meth:`get_state`; ValueError for inconsistent arrays."""
        ref = as_matrix(state["reference"], "novelty reference")
        scale = np.asarray(state["scale"], dtype=np.float64).reshape(-1)
        unit = float(state["unit"])
        if len(ref) < 2 or scale.shape != (ref.shape[1],) or not (np.isfinite(scale).all() and (scale > 0).all()):
            raise ValueError(f"invalid novelty reference: {ref.shape} features, scale {scale.shape}")
        if not (np.isfinite(unit) and unit > 0):
            raise ValueError(f"invalid novelty reference: unit {unit!r}")
        out = cls()
        out.reference_, out.scale_, out.unit_ = ref, scale, unit
        out._tree = cKDTree(ref)
        return out
