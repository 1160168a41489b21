"""Feature sources for the closed loop: what the robot's cameras give at a
pose. :class:`ImageFeatures` (render + trained network),
:class:`MetricFeatures` (render + localizer: positions in the learned metric
space), :class:`CoordinateFeatures` (any function of the pose, e.g. SFA on
coordinates from :func:`fit_coordinate_sfa`, thesis 7.2.2) and
:class:`RunGraphFeatures` (the ideal slow features of an exploration run, a
reference for what SFA can at best learn)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .geodesic import run_positions, thin_run


class ImageFeatures:
    """Slow features of camera poses: renders each pose with ``renderer``
    and ``camera`` and transforms the images with a trained ``network``.

    ``rows``: an :class:`sfanav.ImageRows` applied to the rendered images
    before the network (e.g. a fitted Localizer's ``rows``: the sfanav
    default's horizon band).

    ``features(poses (k, 3)) -> (k, n_outputs)``; ``images`` counts the
    images processed."""

    def __init__(self, network: Any, renderer: Any, camera: Any, *, lighting: Any = None, rows: Any = None) -> None:
        self.network, self.renderer, self.camera, self.lighting = network, renderer, camera, lighting
        self.rows = None if rows is None or getattr(rows, "identity", False) else rows
        self.images = 0

    def render(self, poses: Any) -> np.ndarray:
        """The camera's images (k, H, W[, C]) at ``poses`` (k, 3); counted in ``images``."""
        P = np.atleast_2d(np.asarray(poses, float))
        imgs = np.stack([self.renderer.render(self.camera, p, 0.0, self.lighting) for p in P])
        self.images += len(P)
        return imgs

    def __call__(self, poses: Any) -> np.ndarray:
        imgs = self.render(poses)
        if self.rows is not None:
            imgs = self.rows(imgs)
        return np.asarray(self.network.transform(imgs), float)


class CoordinateFeatures:
    """Slow features computed from positions (thesis 7.2.2: SFA learned on
    the coordinates of a trajectory): ``features(poses) = model(x, y)``.

    ``model`` is a callable on (k, 2) positions (see :func:`fit_coordinate_sfa`)."""

    def __init__(self, model: Callable[[np.ndarray], np.ndarray]) -> None:
        self.model = model
        self.images = 0

    def __call__(self, poses: Any) -> np.ndarray:
        P = np.atleast_2d(np.asarray(poses, float))
        self.images += len(P)
        return np.asarray(self.model(P[:, :2]), float)


class MetricFeatures(ImageFeatures):
    """Positions in a learned metric space as navigation features: each
    camera pose is rendered and localized by a fitted
    :class:`sfanav.Localizer` (image rows, network, readout), so
    ``features(poses (k, 3)) -> (k, 2)`` estimated x, y in metres.

    With ``n_outputs=2`` the thesis's cost becomes the Euclidean distance
    between the estimated positions of the robot's cameras and of the
    target's image (images -> slow features -> metric space ->
    navigation); with :class:`GeodesicField` the exploration run's
    geodesic distance. ``images`` counts the images processed."""

    def __init__(self, localizer: Any, renderer: Any, camera: Any, *, lighting: Any = None) -> None:
        if not getattr(localizer, "is_fitted_", False):
            raise ValueError("MetricFeatures needs a fitted sfanav.Localizer")
        super().__init__(localizer.trained_network(), renderer, camera, lighting=lighting)
        self.localizer = localizer

    def __call__(self, poses: Any) -> np.ndarray:
        return np.asarray(self.localizer.predict(self.render(poses)), float)


class RunGraphFeatures:
    """The slowest features of an exploration run with no limit on the
    function class: a reference for what SFA can at best learn from the run
    (beyond the thesis; docs/navigation.md).

    SFA minimises the mean squared change of unit-variance, decorrelated
    outputs along the run. Over *all* functions of position, with the
    transitions of a random exploration standing in by a graph joining the
    run's places (nodes: one per ``thin`` m cell the run visited, weighted
    by its number of frames ``c``; edges: places at most ``radius`` m
    apart, weight ``exp(-d^2 / 2 sigma^2)``), this is the generalized
    eigenproblem ``L f = lambda C f`` of the graph Laplacian ``L`` (Laplacian
    eigenmaps; Sprekeler 2011 relates SFA's slowest functions of a random
    walk to them). Its smallest non-trivial solutions are exactly zero-mean,
    unit-variance and decorrelated over the run's frames, ordered by
    slowness; in an open rectangle they are the half-cosine modes of x and
    y (the thesis's ideal x / y codes, flat at the borders), and they flow
    around obstacles the run kept clear of, since no edge crosses them.

    Parameters
    ----------
    positions : array (N, 2)
        The run's positions (m), in time order.
    n_components : int
        Number of features.
    radius, sigma, thin : float
        Edge radius, edge width and node cell size (m).

    Attributes
    ----------
    centres_ : (n, 2) node positions; ``values_`` : (n, n_components)
    features of the nodes; ``run_features_`` : (N, n_components) features of
    the run's frames (their nodes'); ``delta_values_`` : mean squared change
    of ``run_features_`` between consecutive frames (SFA's Delta, ascending
    up to the graph's approximation); ``beta_values_`` = sqrt(Delta) / 2 pi;
    ``n_dropped_`` : nodes outside the graph's largest connected part (they
    take the values of their nearest node in it).

    ``features(poses (k, >= 2)) -> (k, n_components)``: the mean of the 8
    nearest nodes' values weighted by inverse distance (a
    :class:`CoordinateFeatures`-style callable for :class:`Navigator`).
    """

    def __init__(self, positions: Any, n_components: int = 8, *, radius: float = 0.5, sigma: float = 0.25,
                 thin: float = 0.1) -> None:
        from scipy.sparse import coo_matrix, diags
        from scipy.sparse.csgraph import connected_components
        from scipy.sparse.linalg import eigsh
        from scipy.spatial import cKDTree

        P = run_positions(positions)
        if isinstance(n_components, bool) or int(n_components) != n_components or int(n_components) < 1:
            raise ValueError(f"n_components must be a positive integer, got {n_components!r}")
        for name, v in (("radius", radius), ("sigma", sigma), ("thin", thin)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of metres, got {v}")
        k = int(n_components)
        centres, node = thin_run(P, float(thin))
        counts = np.bincount(node, minlength=len(centres)).astype(float)
        tree = cKDTree(centres)
        pairs = tree.query_pairs(float(radius), output_type="ndarray")
        n = len(centres)
        d = np.hypot(*(centres[pairs[:, 0]] - centres[pairs[:, 1]]).T)
        w = np.exp(-(d * d) / (2.0 * float(sigma) ** 2))
        W = coo_matrix((np.r_[w, w], (np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]])),
                       shape=(n, n)).tocsr()
        _, label = connected_components(W, directed=False)
        main = np.flatnonzero(label == np.bincount(label).argmax())
        if len(main) < k + 2:
            raise ValueError(f"the run's graph has too few connected places ({len(main)}) for "
                             f"{k} features: a longer run or a larger radius")
        Wm = W[main][:, main]
        L = diags(np.asarray(Wm.sum(axis=1)).ravel()) - Wm
        M = diags(counts[main])
        shift = -1e-8 * float(L.diagonal().max() / counts[main].min())
        vals, vecs = eigsh(L.tocsc(), k=k + 1, M=M.tocsc(), sigma=shift, which="LM")
        order = np.argsort(vals)
        vecs = vecs[:, order[1:]]  # drop the constant
        V = np.empty((n, k))
        V[main] = vecs
        self.n_dropped_ = int(n - len(main))
        if self.n_dropped_:
            other = np.setdiff1d(np.arange(n), main)
            V[other] = vecs[cKDTree(centres[main]).query(centres[other])[1]]
        frames = V[node]
        mu, sd = frames.mean(axis=0), frames.std(axis=0)
        V = (V - mu) / sd
        sign = np.sign(V[np.abs(V).argmax(axis=0), np.arange(k)])
        V *= np.where(sign == 0, 1.0, sign)
        self.centres_, self.values_, self.tree_ = centres, V, tree
        self.run_features_ = V[node]
        self.delta_values_ = np.mean(np.diff(self.run_features_, axis=0) ** 2, axis=0)
        self.beta_values_ = np.sqrt(self.delta_values_) / (2 * np.pi)
        self.n_components = k

    def __call__(self, poses: Any) -> np.ndarray:
        P = np.asarray(poses, dtype=float)
        if P.ndim != 2 or P.shape[1] < 2:
            raise ValueError(f"poses must be (k, >= 2), got shape {P.shape}")
        m = min(8, len(self.centres_))
        d, i = self.tree_.query(P[:, :2], k=m)
        d, i = np.asarray(d).reshape(len(P), m), np.asarray(i).reshape(len(P), m)
        wt = 1.0 / (d + 0.05)
        return np.einsum("km,kmc->kc", wt, self.values_[i]) / wt.sum(axis=1, keepdims=True)


def fit_coordinate_sfa(
    positions: Any,
    area: Sequence[float],
    *,
    n_components: int = 8,
    expansion: str = "rbf",
    spacing: float = 1.5,
    degree: int = 7,
) -> Callable[[np.ndarray], np.ndarray]:
    """SFA learned on the coordinates of a trajectory (thesis 7.2.2).

    The positions (N, 2) along the trajectory (in time order) are expanded
    nonlinearly and linear SFA extracts the ``n_components`` slowest
    features; the returned callable maps positions (k, 2) to them. Its
    attribute ``sfa`` is the fitted :class:`sfanav.SFA` (``beta_values_``
    for the 1/beta weights).

    ``expansion="rbf"`` (default): Gaussian bumps of width ``spacing`` on a
    grid of ``spacing`` m over the area, a function space flexible enough
    for the local distortions that velocity regions cause (a 1.5 m grid
    over 18 x 22 m: 195 functions). ``"poly"``: all monomials up to
    ``degree`` of the coordinates scaled to [-1, 1] (smooth, global; it
    cannot concentrate variance in a small region).
    """
    from ..sfa.node import SFA, expand

    P = np.asarray(positions, float).reshape(-1, 2)
    w, h = float(area[0]), float(area[1])
    if expansion == "rbf":
        sp = float(spacing)
        if not sp > 0:
            raise ValueError(f"spacing must be positive, got {spacing}")
        cx = np.arange(-w / 2, w / 2 + 1e-9, sp)
        cy = np.arange(-h / 2, h / 2 + 1e-9, sp)
        C = np.array([(x, y) for x in cx for y in cy])

        def feat(X: np.ndarray) -> np.ndarray:
            d2 = ((X[:, None, :] - C[None, :, :]) ** 2).sum(-1)
            return np.exp(-d2 / (2 * sp * sp))
    elif expansion == "poly":
        scale = np.array([w / 2, h / 2])

        def feat(X: np.ndarray) -> np.ndarray:
            return expand(X / scale, int(degree))
    else:
        raise ValueError(f"expansion must be 'rbf' or 'poly', got {expansion!r}")
    sfa = SFA(int(n_components)).fit(feat(P))

    def model(X: np.ndarray) -> np.ndarray:
        return sfa.transform(feat(np.asarray(X, float).reshape(-1, 2)))

    model.sfa = sfa  # type: ignore[attr-defined]
    return model
