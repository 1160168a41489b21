"""``LandmarkLocalizer``: position from the views of several markers (thesis
5.4).

One hierarchical SFA network per marker is trained on that marker's views
(:class:`~sfanav.landmarks.views.ViewExtractor`) as one time series, without
simulated rotation: the views are aligned already. Each marker gets its own
readout of its slowest outputs (the single-landmark localization of the
thesis, on the frames where the marker was found), and one readout reads
them all *stacked*: for every marker its ``n_outputs`` slowest outputs, set
to zero where the marker was not found, and a flag that is 1 where it was.
Networks, readouts and the extractor's settings are saved as one model file
(:mod:`sfanav.sfa.modelfile`: versioned, checksummed, no pickle).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import NotFittedError, as_matrix, check_int, check_n_outputs, check_nonneg_float, check_same_length
from ..localization.error_metrics import localization_metrics
from ..localization.readouts import describe_spec, make_readout, readout_from_state, readout_state
from ..sfa.modelfile import read_model, register_loader, save_model
from ..sfa.config import preset_config
from ..sfa.network import Network, Rotation
from .views import MarkerViews, ViewExtractor

NETWORK_PRESET = "landmark-120"
"""The network preset trained per marker (thesis 5.4.1)."""
N_OUTPUTS = 8
"""Slowest outputs each marker contributes (thesis 5.4.1: the first eight)."""
MIN_VIEWS = 10
"""Fewest views of a marker its network is trained on."""


class LandmarkLocalizer:
    """Absolute position from omnidirectional images through the views of
    several landmarks (thesis 5.4).

    Parameters
    ----------
    extractor : ViewExtractor
        Which markers, and how their views are cut (size, margin, ...).
    network : str or dict, default ``"landmark-120"``
        The network each marker gets: a preset name or a config dict (the
        preset TOML's format); its input must be ``extractor.size`` square
        with the extractor's channels.
    n_outputs : int, default 8
        Slowest outputs of each marker's network that its own readout and the
        stack read.
    readout : "quadratic" or dict, default "quadratic"
        The readouts: the thesis's quadratic regression (with ``ridge``), or
        a readout spec of :func:`sfanav.localization.make_readout` (e.g.
        ``{"kind": "gp"}``), used for every marker and for the stack.
    ridge : float, default 0.0
        L2 penalty of the quadratic regressions.

    Attributes
    ----------
    networks_ : dict int -> Network
        The fitted network of each marker.
    marker_readouts_ : dict int -> readout
        Each marker's own readout (its ``n_outputs`` outputs -> x, y),
        fitted on the training images where it was found.
    regression_ : readout
        The readout of the stacked features -> x, y (metres).
    readout_spec_ : dict
        The stacked readout's spec.
    detection_rates_ : dict int -> float
        Fraction of the training images each marker was found in.
    train_metrics_ : dict
        :func:`sfanav.localization.localization_metrics` of the stacked
        readout on the training images.
    training_positions_ : ndarray (N, 2)
        The training positions, metres.
    info : dict
        Free JSON metadata saved with the model (``sfanav train`` stores the
        image size and training settings here).

    Examples
    --------
    >>> loc = LandmarkLocalizer(ViewExtractor([136, 144]))
    >>> loc.fit(train_images, train_xy)        # omnidirectional images      # doctest: +SKIP
    >>> loc.predict(test_images)               # (N, 2) metres               # doctest: +SKIP
    >>> loc.save("landmarks.sfa"); loc = sfanav.load("landmarks.sfa")       # doctest: +SKIP
    """

    def __init__(self, extractor: ViewExtractor, network: str | dict[str, Any] = NETWORK_PRESET, *,
                 n_outputs: int = N_OUTPUTS, readout: str | dict[str, Any] = "quadratic", ridge: float = 0.0) -> None:
        if not isinstance(extractor, ViewExtractor):
            raise TypeError(f"extractor must be a sfanav.landmarks.ViewExtractor, got {type(extractor).__name__}")
        if not isinstance(network, (str, dict)):
            raise TypeError(f"network must be a preset name or a config dict, got {type(network).__name__}")
        self.extractor = extractor
        self.network = network
        self.n_outputs = n_outputs
        self.readout = readout
        self.ridge = ridge
        self.info: dict[str, Any] = {}

    def __repr__(self) -> str:
        state = f"fitted: {describe_spec(self.readout_spec_)}" if self.is_fitted_ else "not fitted"
        return (f"<sfanav.LandmarkLocalizer markers={list(self.extractor.ids)}, n_outputs={self.n_outputs}, "
                f"{state}>")

    @property
    def ids(self) -> tuple[int, ...]:
        """The markers, in the order of the stack."""
        return self.extractor.ids

    @property
    def is_fitted_(self) -> bool:
        return hasattr(self, "regression_")

    @property
    def n_features_(self) -> int:
        """Columns of the stacked features: ``(n_outputs + 1)`` per marker."""
        return len(self.ids) * (check_int(self.n_outputs, "n_outputs") + 1)

    def _check_fitted(self) -> None:
        if not self.is_fitted_:
            raise NotFittedError("this LandmarkLocalizer is not fitted yet; call fit first")

    def new_network(self) -> Network:
        """A new, unfitted network for one marker's views (what :meth:`fit`
        trains per marker). ValueError if the network's input is not the
        views' size and channels or it has fewer than ``n_outputs`` outputs."""
        cfg = preset_config(self.network) if isinstance(self.network, str) else self.network
        net = Network(cfg)
        h, w, c = net.input_shape
        s = self.extractor.size
        if (h, w, c) != (s, s, self.extractor.channels):
            raise ValueError(f"the network takes {w}x{h}x{c} images, but the views are {s}x{s}x"
                             f"{self.extractor.channels}: use a network for the view size (or ViewExtractor(size=...))")
        check_n_outputs(self.n_outputs, net.n_outputs_)
        return net

    def _spec(self, n_columns: int) -> dict[str, Any]:
        ro = self.readout
        if isinstance(ro, dict):
            spec = dict(ro)
        elif ro == "quadratic":
            spec = {"kind": "quadratic", "ridge": check_nonneg_float(self.ridge, "ridge"), "degree": 2}
        else:
            raise ValueError(f"readout must be 'quadratic' or a readout spec dict, got {ro!r}")
        spec["n_outputs"] = n_columns
        return spec

    # ------------------------------------------------------------ training
    def fit(self, images: Any, xy: Any, *, progress: bool = False) -> "LandmarkLocalizer":
        """Extracts the marker views of ``images`` (omnidirectional, (N, H,
        W[, 3]) uint8 in temporal order, or an iterable of such batches) and
        fits on them and the positions ``xy`` (N, 2) metres. Returns ``self``.
        ValueError as :meth:`fit_views`."""
        t0 = time.perf_counter()
        views = self.extractor.transform(images, progress=progress)
        self.info["extract_seconds"] = round(time.perf_counter() - t0, 2)
        return self.fit_views(views, xy, progress=progress)

    def fit_views(self, views: MarkerViews, xy: Any, *, progress: bool = False) -> "LandmarkLocalizer":
        """Fits on extracted views (:meth:`ViewExtractor.transform`) and the
        positions ``xy`` (N, 2) metres: each marker's network on its views
        (in order, as one time series), its own readout on them, and the
        stacked readout on every image. Returns ``self``.

        Raises
        ------
        ValueError
            If the views are of other markers, or a marker was found in fewer
            than :data:`MIN_VIEWS` images (naming it and how often it was found).
        """
        self._check_views(views)
        Y = as_matrix(xy, "xy", n_cols=2)
        check_same_length(views.found, Y, "views", "xy")
        n = check_int(self.n_outputs, "n_outputs")
        counts = views.found.sum(axis=0)
        for mid, c in zip(self.ids, counts):
            if c < MIN_VIEWS:
                raise ValueError(f"marker {mid} was found in {int(c)} of {len(views)} training images; its network "
                                 f"needs at least {MIN_VIEWS} views (is it in the scene, and the dictionary "
                                 f"{self.extractor.dictionary}?)")
        t0 = time.perf_counter()
        self.networks_: dict[int, Network] = {}
        self.marker_readouts_: dict[int, Any] = {}
        for mid in self.ids:
            v, idx = views.of(mid)
            net = self.new_network()
            net.fit(v, Rotation(step=self.extractor.size, window=1.0), progress=progress)
            self.networks_[mid] = net
            F = net.transform(v)[:, :n]
            self.marker_readouts_[mid] = make_readout(self._spec(n)).fit(F, Y[idx])
        fit_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        S = self.stack(views)
        self.readout_spec_ = self._spec(S.shape[1])
        self.regression_ = make_readout(self.readout_spec_).fit(S, Y)
        self.detection_rates_ = {mid: float(r) for mid, r in zip(self.ids, views.detection_rate())}
        self.training_positions_ = np.array(Y, dtype=np.float64)
        self.train_metrics_ = localization_metrics(self.regression_.predict(S), Y)
        self.info.update({"n_train_images": int(len(Y)), "fit_seconds": round(fit_s, 2),
                          "readout_seconds": round(time.perf_counter() - t1, 2),
                          "readout": describe_spec(self.readout_spec_),
                          "detection_rates": {str(k): v for k, v in self.detection_rates_.items()}})
        return self

    def _check_views(self, views: Any) -> None:
        if not isinstance(views, MarkerViews):
            raise TypeError(f"views must be sfanav.landmarks.MarkerViews, got {type(views).__name__}")
        if tuple(views.ids) != self.ids:
            raise ValueError(f"views are of markers {list(views.ids)}, this localizer reads {list(self.ids)}")

    # ------------------------------------------------------------ features
    def marker_features(self, views: MarkerViews, marker_id: int) -> tuple[np.ndarray, np.ndarray]:
        """One marker's slowest ``n_outputs`` outputs where it was found,
        (n, n_outputs), and the indices of those images (n,)."""
        self._check_views(views)
        net = self._network(marker_id)
        v, idx = views.of(marker_id)
        n = check_int(self.n_outputs, "n_outputs")
        F = net.transform(v)[:, :n] if len(idx) else np.zeros((0, n))
        return F, idx

    def _network(self, marker_id: int) -> Network:
        if not hasattr(self, "networks_"):
            raise NotFittedError("this LandmarkLocalizer is not fitted yet; call fit first")
        if int(marker_id) not in self.networks_:
            raise ValueError(f"marker {marker_id} is not one of this localizer's markers {list(self.ids)}")
        return self.networks_[int(marker_id)]

    def stack(self, views: MarkerViews) -> np.ndarray:
        """The stacked features (N, (n_outputs + 1) k): for each marker in
        :attr:`ids` order its ``n_outputs`` slowest outputs (zeros where it
        was not found) followed by its flag (1 found, 0 missing)."""
        self._check_views(views)
        n = check_int(self.n_outputs, "n_outputs")
        out = np.zeros((len(views), (n + 1) * len(self.ids)))
        for j, mid in enumerate(self.ids):
            F, idx = self.marker_features(views, mid)
            out[idx, j * (n + 1): j * (n + 1) + n] = F
            out[idx, j * (n + 1) + n] = 1.0
        return out

    # ------------------------------------------------------------ inference
    def predict(self, images: Any, *, progress: bool = False) -> np.ndarray:
        """Positions (N, 2) in metres of omnidirectional images (N, H, W[, 3])
        uint8 (or an iterable of batches). An image in which no marker was
        found gets the stacked readout's answer for "nothing seen"."""
        self._check_fitted()
        return self.predict_views(self.extractor.transform(images, progress=progress))

    def predict_views(self, views: MarkerViews) -> np.ndarray:
        """Positions (N, 2) in metres from extracted views (stacked readout)."""
        self._check_fitted()
        return self.regression_.predict(self.stack(views))

    def predict_marker(self, views: MarkerViews, marker_id: int) -> tuple[np.ndarray, np.ndarray]:
        """One marker's own estimates (n, 2) metres where it was found, and
        the indices of those images (n,)."""
        self._check_fitted()
        F, idx = self.marker_features(views, marker_id)
        if not len(idx):
            return np.zeros((0, 2)), idx
        return self.marker_readouts_[int(marker_id)].predict(F), idx

    def score(self, images: Any, xy: Any) -> float:
        """Mean Euclidean distance (MED, metres) of the estimates for
        ``images`` from ``xy`` (N, 2). Lower is better."""
        from ..localization.error_metrics import med

        return med(self.predict(images), xy)

    # ------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike) -> Path:
        """Saves extractor settings, networks and readouts as one model file
        (kind ``"LandmarkLocalizer"``, pickle-free); read back with
        :func:`sfanav.load`."""
        self._check_fitted()
        nets = {}
        with tempfile.TemporaryDirectory(prefix="sfanav-") as tmp:
            for mid, net in self.networks_.items():
                p = Path(tmp) / f"{mid}.sfa"
                net.save(p)  # the network's own save() defines its state
                nets[str(mid)] = read_model(p)[1]
        state = {
            "extractor": self.extractor.to_dict(),
            "network_param": self.network,
            "params": {"n_outputs": int(self.n_outputs), "ridge": float(self.ridge),
                       "readout": self.readout if isinstance(self.readout, str) else dict(self.readout)},
            "networks": nets,
            "marker_readouts": {str(mid): readout_state(self._spec(int(self.n_outputs)), r)
                                for mid, r in self.marker_readouts_.items()},
            "readout": readout_state(self.readout_spec_, self.regression_),
            "detection_rates": {str(k): float(v) for k, v in self.detection_rates_.items()},
            "train_metrics": dict(self.train_metrics_),
            "training_positions": self.training_positions_,
            "info": dict(self.info or {}),
        }
        return save_model(path, "LandmarkLocalizer", state)

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "LandmarkLocalizer":
        """Rebuilds a localizer from a model file's state; ValueError if the
        state is malformed or its parts do not fit each other."""
        try:
            ex = ViewExtractor.from_dict(state["extractor"])
            params = dict(state["params"])
            net_param = state["network_param"]
            if not isinstance(net_param, (str, dict)):
                raise ValueError(f"the network parameter must be a preset name or a config, got {net_param!r}")
            loc = cls(ex, net_param, n_outputs=check_int(params["n_outputs"], "n_outputs"),
                      readout=params["readout"], ridge=check_nonneg_float(params["ridge"], "ridge"))
            nets = state["networks"]
            if set(nets) != {str(m) for m in ex.ids} or set(state["marker_readouts"]) != set(nets):
                raise ValueError(f"networks for markers {sorted(nets)}, the extractor reads {list(ex.ids)}")
            loc.networks_ = {m: Network.from_state(nets[str(m)]) for m in ex.ids}
            for m, net in loc.networks_.items():
                h, w, c = net.input_shape
                if not net.is_fitted_ or (h, w, c) != (ex.size, ex.size, ex.channels) or net.n_outputs_ < loc.n_outputs:
                    raise ValueError(f"the network of marker {m} does not fit the views ({w}x{h}x{c}, "
                                     f"{net.n_outputs_} outputs)")
            loc.marker_readouts_ = {m: readout_from_state(state["marker_readouts"][str(m)]) for m in ex.ids}
            loc.regression_ = readout_from_state(state["readout"])
            loc.readout_spec_ = dict(state["readout"]["spec"])
            loc.detection_rates_ = {int(k): float(v) for k, v in state["detection_rates"].items()}
            loc.train_metrics_ = dict(state.get("train_metrics") or {})
            loc.training_positions_ = as_matrix(state["training_positions"], "training_positions", n_cols=2)
            loc.info = dict(state.get("info") or {})
        except (KeyError, TypeError) as exc:
            raise ValueError(f"invalid LandmarkLocalizer model state: {exc}") from None
        # one probe: every readout must take its features and give one finite position
        try:
            probes = [loc.regression_.predict(np.zeros((1, loc.n_features_)))]
            probes += [r.predict(np.zeros((1, loc.n_outputs))) for r in loc.marker_readouts_.values()]
        except ValueError as exc:
            raise ValueError(f"invalid LandmarkLocalizer model state: a readout does not fit its features ({exc})") from None
        if any(p.shape != (1, 2) or not np.isfinite(p).all() for p in probes):
            raise ValueError("invalid LandmarkLocalizer model state: a readout gives no finite (x, y) position")
        return loc


register_loader("LandmarkLocalizer", LandmarkLocalizer.from_state)
