"""Online updates of a trained :class:`~sfanav.Network`: add a new run to the
map without retraining from scratch.

A network saved with its training statistics
(``Network.save(path, include_statistics=True)``) keeps, for every node
and stage, the exact sums its solution came from (:class:`Statistics`:
mean, covariance and derivative covariance, mergeable). An update streams
the new run through the frozen stages below the ones it re-solves, adds the
run's statistics to the stored ones (the run is its own recording: no
derivative pair joins it to the old data) and solves again.

* :class:`UpdatePolicy` says what is re-solved and when.
* :class:`NetworkUpdater` applies it: ``partial_fit(run)`` per run,
  ``solve()`` on demand, ``network_`` the current network.
* :func:`statistics_bytes` is what keeping the statistics costs in the
  model file; :func:`drop_statistics` a copy without them (which can no
  longer be updated).

``resolve="top"`` re-solves the final stage of the top layer (the slow
features themselves) with every stage below it frozen. It is exact:
updating with run A and then run B gives the same statistics and the same
outputs (to rounding) as training that stage on A and B together. Stages
whose input would change cannot be updated exactly from stored second
moments (an expanded stage would need the old data's higher moments), so
they stay as trained; docs/updates.md has the derivation and the
measurements.

Examples
--------
>>> net = sfanav.Network.from_preset("thesis-5.1").fit(run_a)        # doctest: +SKIP
>>> up = NetworkUpdater(net, UpdatePolicy(resolve="top"))            # doctest: +SKIP
>>> up.partial_fit(run_b).network_.transform(test_images)            # doctest: +SKIP
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _core
from .._checks import NotFittedError, as_image_batch, check_int
from .modelfile import state_from_bytes

__all__ = ["RESOLVE", "UpdatePolicy", "NetworkUpdater", "statistics_bytes", "drop_statistics"]

RESOLVE = ("top", "all")
"""What an update can re-solve: ``"top"``, the final stage of the top layer
(exact from the stored statistics); ``"all"``, every layer, trained again
on the images a localizer's readout memory keeps and the new runs
(:class:`sfanav.localization.updates.LocalizerUpdater` only)."""

SCALE_RATIO = 50.0  # a run whose pixel scale differs this much from training is refused (0..255 against 0..1)


@dataclass(frozen=True)
class UpdatePolicy:
    """What an update re-solves and when.

    Parameters
    ----------
    resolve : {"top", "all"}, default "top"
        The stages re-solved. ``"top"``: the final stage of the top layer,
        from the stored statistics plus the new runs'; every stage below it
        stays as trained (exact, see :mod:`sfanav.sfa.updates`). ``"all"``:
        every layer, trained again on the remembered images and the new
        runs (a localizer whose readout memory keeps its images; the cost
        of a retrain on them).
    every : int or None, default None
        None: solve after every :meth:`NetworkUpdater.partial_fit` (and on
        :meth:`NetworkUpdater.solve`). N: solve once at least N images have
        been added since the last solve (and on ``solve()``); runs in
        between only accumulate statistics.

    Raises ValueError for an unknown ``resolve`` or an ``every`` < 1.

    Examples
    --------
    >>> UpdatePolicy(every=500)
    UpdatePolicy(resolve='top', every=500)
    """

    resolve: str = "top"
    every: int | None = None

    def __post_init__(self) -> None:
        if self.resolve not in RESOLVE:
            raise ValueError(f"resolve must be one of {', '.join(RESOLVE)}, got {self.resolve!r}")
        if self.every is not None:
            check_int(self.every, "every")

    def due(self, n_pending: int) -> bool:
        """Whether ``n_pending`` images added since the last solve call for
        one now (after every run without ``every``)."""
        return self.every is None or n_pending >= self.every


def _network_state(network: Any) -> dict[str, Any]:
    """The network's model-file state with every statistic (a deep copy)."""
    return state_from_bytes(network.to_bytes(include_statistics=True), "Network")


def statistics_bytes(network: Any) -> int:
    """Bytes the training statistics add to ``network``'s model file (the
    file with them minus the file without them).

    Examples
    --------
    >>> statistics_bytes(trained_network)  # doctest: +SKIP
    1843200
    """
    _check_network(network)
    return len(network.to_bytes(include_statistics=True)) - len(network.to_bytes(include_statistics=False))


def drop_statistics(network: Any) -> Any:
    """A copy of ``network`` without its training statistics (a smaller
    model file that can no longer be updated)."""
    _check_network(network)
    from .network import Network

    return Network.from_bytes(network.to_bytes(include_statistics=False))


def _check_network(network: Any) -> None:
    from .network import Network

    if not isinstance(network, Network):
        raise TypeError(f"network must be a sfanav.Network, got {type(network).__name__}")
    if not network.is_fitted_:
        raise NotFittedError("this network is not fitted; fit it before updating it")


def _top_stage(state: dict[str, Any]) -> int:
    """Index of the final stage of the top layer's nodes; ValueError when
    their statistics were not kept."""
    stages = {len(node["stages"]) for node in state["nodes"][-1]}
    if len(stages) != 1:  # pragma: no cover - the core builds every node of a layer alike
        raise ValueError("the top layer's nodes have different numbers of stages")
    k = stages.pop() - 1
    if any(node["stages"][k]["stats"] is None for node in state["nodes"][-1]):
        raise ValueError("this network was saved without its training statistics, so it cannot be updated: "
                         "train it again and save it with include_statistics=True")
    return k


class NetworkUpdater:
    """Adds runs to a fitted :class:`~sfanav.Network` under an
    :class:`UpdatePolicy` (scikit-learn's ``partial_fit``).

    Parameters
    ----------
    network : sfanav.Network
        Fitted, with its training statistics (saved with
        ``include_statistics=True``). Not modified: updates make new
        networks.
    policy : UpdatePolicy, default ``UpdatePolicy()``
    batch_size : int, default 16
        Images streamed through the frozen layers at a time.

    Attributes
    ----------
    network_ : sfanav.Network
        The network as of the last solve (with its statistics).
    n_images_ : int
        Images added by :meth:`partial_fit` so far.
    n_pending_ : int
        Images added since the last solve.
    n_solves_ : int
        Solves so far.
    n_pairs_ : int
        Derivative pairs added by :meth:`add_pairs` so far.

    Raises TypeError for a network that is not a Network, NotFittedError
    for an unfitted one, ValueError for one saved without statistics.
    """

    def __init__(self, network: Any, policy: UpdatePolicy | None = None, *, batch_size: int = 16) -> None:
        _check_network(network)
        policy = UpdatePolicy() if policy is None else policy
        if not isinstance(policy, UpdatePolicy):
            raise TypeError(f"policy must be an UpdatePolicy, got {type(policy).__name__}")
        if policy.resolve != "top":
            raise ValueError(f"a network alone re-solves its top stage only (resolve='top'); resolve="
                             f"{policy.resolve!r} needs the old images: update a localizer whose readout memory "
                             "keeps them (LocalizerUpdater, remember(..., keep_images=True))")
        self.policy = policy
        self.batch_size = check_int(batch_size, "batch_size")
        self._state = _network_state(network)
        self._stage = _top_stage(self._state)
        self._layer = len(self._state["nodes"]) - 1
        if network.period_ is None or network.step_ is None:
            raise ValueError("this network does not record its training rotation (step and panorama width), "
                             "so a run cannot be added consistently")
        self._period, self._step = int(network.period_), int(network.step_)
        self._input_shape = network.input_shape
        self._scale = getattr(network, "input_scale_", None)
        self._tw = float(getattr(network, "transition_weight_", None) or 1.0)
        self.network_ = network
        self.n_images_ = 0
        self.n_pending_ = 0
        self.n_solves_ = 0
        self.n_pairs_ = 0
        self._core = self._training_core()

    # ------------------------------------------------------------ checks
    def check_run(self, images: Any) -> np.ndarray:
        """The run as an image batch (N, H, W[, C]) if it matches the
        network (height, channels, panorama width, pixel scale); else
        ValueError (TypeError for a non-array) naming what differs."""
        a = as_image_batch(images, "run")
        if len(a) == 0:
            raise ValueError("the run has no images")
        h, _, c = self._input_shape
        ac = 1 if a.ndim == 3 else a.shape[3]
        if a.shape[1] != h or ac != c or a.shape[2] != self._period:
            raise ValueError(f"the run's images are {a.shape[2]}x{a.shape[1]} with {ac} channel(s), but the model "
                             f"was trained on {self._period}x{h} panoramas with {c} channel(s)")
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise ValueError("the run's images contain NaN or infinity")
        now = float(max(a.max(), -float(a.min())))
        if self._scale and now > 0 and max(now / self._scale, self._scale / now) > SCALE_RATIO:
            raise ValueError(f"the run's pixel values go up to {now:.3g}, the model's training images' to "
                             f"{self._scale:.3g}: scale the run as in training")
        return a

    # ------------------------------------------------------------ updating
    def _training_core(self) -> Any:
        """A core network with every layer below the top trained and the top
        layer's final stage in training, holding the stored statistics."""
        state = self._state
        return _core.Network.from_states(self.network_.config_, copy.deepcopy(state["nodes"]), self._layer)

    def _trainer(self) -> Any:
        return _core.LayerTrainer(self._core, self._layer, self._stage, self._step, self._period,
                                  transition_weight=self._tw, lag_products=False)

    def partial_fit(self, images: Any) -> "NetworkUpdater":
        """Adds one run (N, H, W[, C], the training panoramas' size, channels
        and scale) as its own recording, and solves if the policy says so.
        Returns ``self``. ValueError for a run that does not match (the
        network is then unchanged)."""
        a = self.check_run(images)
        tr = self._trainer()
        core = self._core
        for s in range(0, len(a), self.batch_size):
            tr.feed(core, np.ascontiguousarray(a[s : s + self.batch_size]))
        # The trainer's pass is not ended here: the node keeps the sums and the next run starts a new trainer,
        # so no derivative pair joins two runs.
        self.n_images_ += len(a)
        self.n_pending_ += len(a)
        if self.policy.due(self.n_pending_):
            self.solve()
        return self

    def solve(self) -> Any:
        """Re-solves the policy's stages from every statistic added so far
        and returns the new network (also ``network_``)."""
        from .network import Network

        core = _core.Network.from_states(self.network_.config_, self._core.node_states(True), self._layer)
        tr = _core.LayerTrainer(core, self._layer, self._stage, self._step, self._period,
                                transition_weight=self._tw, lag_products=False)
        # the sums are already in the nodes: an empty merge only tells the trainer the pass saw images
        empty = [_core.Statistics(node["stages"][self._stage]["stats"]["dim"])
                 for node in self._state["nodes"][self._layer]]
        tr.merge_statistics(core, empty, max(1, self.n_images_))
        if not tr.end_pass(core):  # pragma: no cover - the final stage ends the layer
            raise RuntimeError("the top layer did not finish training")
        state = dict(self._state)
        state["nodes"] = core.node_states(True)
        state["trained"] = core.n_trained
        self.network_ = Network.from_state(state)
        self.n_pending_ = 0
        self.n_solves_ += 1
        return self.network_

    @property
    def transition_weight(self) -> float:
        """The weight of the derivative pair between consecutive images in
        the network's training (``Network.fit(transition_weight=)``)."""
        return self._tw

    def add_pairs(self, a: Any, b: Any, weights: Any = None) -> "NetworkUpdater":
        """Adds derivative pairs between views given by their inputs to the
        updated stage: ``a``, ``b`` (M, k) float (the frozen stages' outputs
        of two views each, e.g. a readout memory's stored inputs and a new
        run's), ``weights`` (M,) >= 0 (default 1). Each pair adds
        ``w (e(b) - e(a)) (e(b) - e(a))^T`` to the stage's derivative
        statistics, ``e`` its expansion, and nothing to its sample moments:
        a slowness constraint between views that no sequence joins (the same
        place in two recordings: what place-major training gives). The next
        solve uses them. Only for networks whose top layer is one node.
        Returns ``self``. ValueError for shapes that do not match the stage
        or bad weights (nothing added then)."""
        states = self._core.node_states(True)
        top = states[self._layer]
        if len(top) != 1:
            raise ValueError(f"pairs of stage inputs need a top layer of one node, this one has {len(top)}")
        stage = top[0]["stages"][self._stage]
        A = np.ascontiguousarray(np.asarray(a, dtype=np.float64))
        B = np.ascontiguousarray(np.asarray(b, dtype=np.float64))
        k = int(stage["input_dim"])
        if A.ndim != 2 or A.shape != B.shape or A.shape[1] != k:
            raise ValueError(f"a and b must both be (M, {k}) stage inputs, got {A.shape} and {B.shape}")
        if not (np.isfinite(A).all() and np.isfinite(B).all()):
            raise ValueError("the stage inputs contain NaN or infinity")
        w = np.ones(len(A)) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
        if len(w) != len(A) or not np.all(np.isfinite(w) & (w >= 0)):
            raise ValueError(f"weights must be {len(A)} finite numbers >= 0")
        if len(A) == 0:
            return self
        degree = int(stage["degree"])
        stats = _core.Statistics.from_state(stage["stats"])
        stats.add_pairs(np.asarray(_core.expand(A, degree)), np.asarray(_core.expand(B, degree)), w)
        stage["stats"] = stats.get_state()
        self._core = _core.Network.from_states(self.network_.config_, states, self._layer)
        self.n_pairs_ += len(A)
        return self

    def top_statistics(self) -> list[Any]:
        """The statistics of the stage being updated, one per top-layer node
        (:class:`~sfanav.sfa.node.Statistics`, copies)."""
        from .node import Statistics

        out = []
        for node in self._core.node_states(True)[self._layer]:
            out.append(Statistics.from_state(node["stages"][self._stage]["stats"]))
        return out
