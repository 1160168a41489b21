"""Online updates of a trained :class:`~sfanav.Localizer`: a new run added to
the map (network and readout) without retraining from scratch.

An update re-solves the network's top stage (the slow features) from its
stored statistics plus the new run's (:mod:`sfanav.sfa.updates`, exact with
the stages below frozen) and then refits the readout on the slow features
of the old and the new runs. Re-solving the top stage changes the old
views' slow features, so the localizer keeps a **readout memory**
(:class:`ReadoutMemory`): for an evenly spaced, bounded subset of its
training views (default at most :data:`MAX_VIEWS`), their inputs to the
re-solved stage (the frozen stages' outputs, under each pooled rotation),
their appearance signatures if the readout reads them, and their
positions. The new slow features of those views are recomputed from it
exactly (the frozen stages give the same inputs as in training).

* :func:`remember` gives a fitted localizer its memory (from its training
  run); :func:`~sfanav.localization.fit_localizer` does it with
  ``readout_memory=N``.
* :class:`LocalizerUpdater` adds runs (``partial_fit(images, xy)``) under an
  :class:`~sfanav.sfa.updates.UpdatePolicy`; ``localizer_`` is the result.
* :func:`readout_memory_bytes` / :func:`drop_readout_memory`: what the memory
  and the network statistics cost in the model file, and a copy without
  them (no longer updatable).

A localizer with a readout memory saves its network with the training
statistics (what the network update needs). Runs need positions: ground
truth, or for a run with odometry only the positions
:func:`sfanav.odometry.map_joining.join_run` learns in the map's frame.
docs/updates.md has the derivation, the tests and the measurements.

Examples
--------
>>> loc = fit_localizer(net, X_a, xy_a, readout="quadratic", readout_memory=3000)  # doctest: +SKIP
>>> new = LocalizerUpdater(loc).partial_fit(X_b, xy_b).localizer_                  # doctest: +SKIP
"""

from __future__ import annotations

import copy
import sys
from typing import Any

import numpy as np

from .. import _core
from .._checks import NotFittedError, as_matrix, check_int, check_same_length
from .._sampling import evenly_spaced
from ..data.corruptions import CAMERA, CorruptionModel
from ..sfa.modelfile import state_from_bytes
from ..sfa.updates import NetworkUpdater, UpdatePolicy, statistics_bytes
from .localizer import Localizer, pooling_step
from .readouts import describe_spec

__all__ = ["MAX_VIEWS", "ReadoutMemory", "remember", "top_stage_inputs", "top_stage_features",
           "top_stage_training_inputs", "top_stage_degree", "LocalizerUpdater", "readout_memory_bytes",
           "drop_readout_memory", "updatable_memory", "runs_share_places"]

MAX_VIEWS = 3000
"""Default bound on the views a readout memory keeps."""


class ReadoutMemory:
    """What a localizer's readout needs of its old training views to be
    refitted after the network's top stage is re-solved.

    Parameters
    ----------
    inputs : array (n, K, k)
        Each view's input to the re-solved stage (the frozen stages'
        outputs, float64) under the K rotations its features are pooled
        over (K = 1 without pooling).
    positions : array (n, 2)
        The positions (metres) the readout was fitted to.
    signatures : array (n, q) or None
        The views' appearance signatures, if the readout reads them.
    augmented : tuple (inputs, signatures) or None
        The same of the views' corrupted copies, if the readout was fitted
        on such copies as well (``readout_augmentation``).
    max_views : int, default :data:`MAX_VIEWS`
        The bound: :meth:`extended` keeps an evenly spaced subset.
    n_seen : int or None
        Views the memory was drawn from (default n).
    images : array (n, H, W[, C]) or None
        The views' images as the localizer takes them (8-bit panoramas):
        what re-solving every layer (``UpdatePolicy(resolve="all")``) trains
        on. About H x W x C bytes a view (42 kB at 350x40 RGB).
    runs : array (n,) int or None
        The run each view came from, in the order the runs were added
        (default all 0).

    ``nbytes`` is what it adds to the model file (its arrays). ValueError
    for arrays that disagree in length or shape.
    """

    def __init__(self, inputs: Any, positions: Any, signatures: Any = None, augmented: Any = None, *,
                 max_views: int = MAX_VIEWS, n_seen: int | None = None, images: Any = None,
                 runs: Any = None) -> None:
        Z = np.asarray(inputs, dtype=np.float64)
        if Z.ndim != 3 or not np.isfinite(Z).all():
            raise ValueError(f"readout memory inputs must be a finite (n, K, k) array, got shape {Z.shape}")
        Y = as_matrix(positions, "readout memory positions", n_cols=2)
        check_same_length(Z, Y, "readout memory inputs", "positions")
        G = None if signatures is None else as_matrix(signatures, "readout memory signatures")
        if G is not None:
            check_same_length(Z, G, "readout memory inputs", "signatures")
        A = None
        if augmented is not None:
            Za = np.asarray(augmented[0], dtype=np.float64)
            Ga = None if augmented[1] is None else as_matrix(augmented[1], "augmented signatures")
            if Za.shape != Z.shape or (Ga is None) != (G is None) or (Ga is not None and Ga.shape != G.shape):
                raise ValueError("the augmented copies in a readout memory must have the shapes of the views")
            A = (Za, Ga)
        self.inputs, self.positions, self.signatures, self.augmented = Z, Y, G, A
        self.images = None if images is None else np.asarray(images)
        if self.images is not None and (self.images.ndim not in (3, 4) or len(self.images) != len(Z)):
            raise ValueError(f"readout memory images must be (n, H, W[, C]) with n = {len(Z)}, got shape "
                             f"{self.images.shape}")
        R = np.zeros(len(Z), np.int64) if runs is None else np.asarray(runs)
        if R.shape != (len(Z),) or (len(R) and (R.dtype.kind not in "iu" or R.min() < 0)):
            raise ValueError(f"readout memory runs must be {len(Z)} integers >= 0")
        self.runs = R.astype(np.int64)
        self.max_views = check_int(max_views, "max_views")
        self.n_seen = len(Z) if n_seen is None else check_int(n_seen, "n_seen", minimum=0)

    def __len__(self) -> int:
        return len(self.inputs)

    def __repr__(self) -> str:
        return (f"<ReadoutMemory {len(self)} views of {self.n_seen} (max {self.max_views}), "
                f"{self.nbytes} bytes>")

    @property
    def nbytes(self) -> int:
        arrays = [self.inputs, self.positions, self.signatures, self.images,
                  self.runs if self.runs.any() else None]  # as saved: run labels only past the first run
        if self.augmented is not None:
            arrays += list(self.augmented)
        return int(sum(a.nbytes for a in arrays if a is not None))

    def subset(self, idx: Any) -> "ReadoutMemory":
        """The views ``idx`` (same bound, same ``n_seen``)."""
        idx = np.asarray(idx)
        aug = None if self.augmented is None else (
            self.augmented[0][idx], None if self.augmented[1] is None else self.augmented[1][idx])
        return ReadoutMemory(self.inputs[idx], self.positions[idx],
                             None if self.signatures is None else self.signatures[idx], aug,
                             max_views=self.max_views, n_seen=self.n_seen,
                             images=None if self.images is None else self.images[idx], runs=self.runs[idx])

    def extended(self, other: "ReadoutMemory") -> "ReadoutMemory":
        """This memory followed by ``other``'s views, thinned to an evenly
        spaced subset of at most ``max_views``; ``n_seen`` adds up."""
        if other.inputs.shape[1:] != self.inputs.shape[1:] or (other.signatures is None) != (self.signatures is None) \
                or (other.augmented is None) != (self.augmented is None) or (other.images is None) != (
                    self.images is None) or (self.images is not None and other.images.shape[1:] != self.images.shape[1:]):
            raise ValueError("the views to add do not match the readout memory (stage inputs, signatures, copies, "
                             "images)")

        def cat(a: Any, b: Any) -> Any:
            return None if a is None else np.concatenate([a, b])

        aug = None
        if self.augmented is not None:
            aug = (cat(self.augmented[0], other.augmented[0]), cat(self.augmented[1], other.augmented[1]))
        first = int(self.runs.max()) + 1 if len(self.runs) else 0  # the added views' runs follow
        both = ReadoutMemory(cat(self.inputs, other.inputs), cat(self.positions, other.positions),
                             cat(self.signatures, other.signatures), aug, max_views=self.max_views,
                             n_seen=self.n_seen + other.n_seen, images=cat(self.images, other.images),
                             runs=np.concatenate([self.runs, first + other.runs]))
        return both.subset(evenly_spaced(len(both), self.max_views))

    def get_state(self) -> dict[str, Any]:
        """The memory as a model-file state (arrays; no pickle)."""
        out: dict[str, Any] = {"inputs": self.inputs, "positions": self.positions, "max_views": self.max_views,
                               "n_seen": self.n_seen}
        if self.signatures is not None:
            out["signatures"] = self.signatures
        if self.augmented is not None:
            out["augmented_inputs"] = self.augmented[0]
            if self.augmented[1] is not None:
                out["augmented_signatures"] = self.augmented[1]
        if self.images is not None:
            out["images"] = self.images
        if self.runs.any():
            out["runs"] = self.runs
        return out

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "ReadoutMemory":
        try:
            aug = None
            if "augmented_inputs" in state:
                aug = (state["augmented_inputs"], state.get("augmented_signatures"))
            return cls(state["inputs"], state["positions"], state.get("signatures"), aug,
                       max_views=state["max_views"], n_seen=state["n_seen"], images=state.get("images"),
                       runs=state.get("runs"))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"invalid readout memory state: {exc}") from None


# ---------------------------------------------------------------- the split at the re-solved stage
def _split_network(network: Any) -> tuple[Any, Any]:
    """``(below, top)``: a core network whose output is the input of the
    top layer's final stage (that stage replaced by an identity), and the
    final stage alone as a core node. ValueError if the top layer has other
    than one node with a reduction stage."""
    state = state_from_bytes(network.to_bytes(include_statistics=False), "Network")
    nodes = state["nodes"]
    if len(nodes[-1]) != 1 or len(nodes[-1][0]["stages"]) != 2:
        raise ValueError("a readout memory needs a network whose top layer is one node with a reduction stage "
                         "(the thesis's and the sfanav default's networks)")
    top = nodes[-1][0]
    k = int(top["stages"][0]["solution"]["n_out"])
    spec = copy.deepcopy(network.config_)
    spec["layers"][-1] = dict(spec["layers"][-1], n_out=k, degree=1)
    identity = {"degree": 1, "input_dim": k, "n_out": k, "stats": None,
                "solution": {"delta": np.zeros(k), "dropped": np.zeros(0), "mean": np.zeros(k), "n_out": k,
                             "projection": np.eye(k).ravel(), "rank": k}}
    below_top = dict(copy.deepcopy(top), n_components=k, degree=1)
    below_top["stages"][1] = identity
    below = _core.Network.from_states(spec, nodes[:-1] + [[below_top]], len(nodes))
    final = {"n_components": top["n_components"], "degree": top["degree"], "reduce_to": None, "tol": top["tol"],
             "mixed_precision": top["mixed_precision"], "n_features": k, "training_stage": 0,
             "stages": [top["stages"][1]]}
    return below, _core.SfaNode.from_state(final)


def _below_top(localizer: Localizer, images: Any) -> tuple[Any, np.ndarray, Any]:
    """(trained network, the images as its input, the network below its top stage)."""
    net = localizer.trained_network()
    below, _ = _split_network(net)
    return net, np.ascontiguousarray(localizer.network_input(np.asarray(images))), below


def top_stage_inputs(localizer: Localizer, images: Any) -> np.ndarray:
    """The inputs of the network's top stage for images (N, H, W[, C]) as the
    localizer sees them (photometric normalisation, rows, the K pooled
    rotations): (N, K, k) float64, K = 1 without rotation pooling (the
    window at rotation 0, as :meth:`Localizer.features`)."""
    net, a, below = _below_top(localizer, images)
    K = localizer.rotation_pooling_
    if K == 1:
        v = net.input_shape[1]
        if a.shape[2] < v:
            raise ValueError(f"images of {a.shape[2]} px are narrower than the network input ({v} px)")
        Z = below.transform(np.ascontiguousarray(a[:, :, :v]))
        return np.asarray(Z, dtype=np.float64)[:, None, :]
    return np.asarray(below.transform_rotations(a, pooling_step(net, a.shape[2], K)), dtype=np.float64)


def top_stage_features(network: Any, inputs: Any) -> np.ndarray:
    """The slow features of views from their top-stage inputs (N, K, k):
    the network's final stage applied to each rotation, averaged over the K
    rotations: (N, n_outputs). Equals :meth:`Localizer.features` of the
    images the inputs came from (to rounding)."""
    Z = np.asarray(inputs, dtype=np.float64)
    _, top = _split_network(network)
    n, K, k = Z.shape
    Y = np.asarray(top.transform(np.ascontiguousarray(Z.reshape(n * K, k))))
    return Y.reshape(n, K, -1).mean(axis=1)


def top_stage_training_inputs(localizer: Localizer, images: Any) -> np.ndarray:
    """The inputs of the network's top stage for images (N, H, W[, C]) as
    the localizer sees them, under the simulated rotations the network was
    trained with (``step_`` px over the whole panorama): (N, V, k) float64,
    V = ceil(W / step), view v the panorama rolled left by v * step px.
    Flattened to (N * V, k), image after image, this is the sequence whose
    statistics the top stage was solved from (derivative pairs between
    consecutive views and from an image's last view to the next image's
    first). ValueError for a network that records no training rotation."""
    net, a, below = _below_top(localizer, images)
    step = net.step_
    if step is None:
        raise ValueError("this localizer's network records no training rotation (step)")
    return np.asarray(below.transform_rotations(a, int(step)), dtype=np.float64)


def top_stage_degree(network: Any) -> int:
    """The polynomial degree the network's top stage expands its inputs
    with before solving (``sfanav._core.expand(inputs, degree)``): what
    its statistics are sums over."""
    _, top = _split_network(network)
    return int(top.get_state(with_statistics=False)["stages"][0]["degree"])


def _memory_of(localizer: Localizer, images: Any, xy: Any, augmentation: CorruptionModel | None, seed: int,
               max_views: int, keep_images: bool = False) -> ReadoutMemory:
    """A readout memory of the evenly spaced views of a run (all kept, then
    thinned by the caller)."""
    a = np.asarray(images)
    Y = as_matrix(xy, "xy", n_cols=2)
    check_same_length(a, Y, "images", "xy")
    idx = evenly_spaced(len(a), max_views)
    a, Y = a[idx], Y[idx]
    sig = localizer.n_signature_ > 0
    aug = None
    if augmentation is not None:
        altered = augmentation.apply(a, seed=seed + 1)  # the draw fit_localizer makes for readout_augmentation
        aug = (top_stage_inputs(localizer, altered), localizer.signatures(altered) if sig else None)
    return ReadoutMemory(top_stage_inputs(localizer, a), Y, localizer.signatures(a) if sig else None, aug,
                         max_views=max_views, n_seen=len(np.asarray(images)), images=a if keep_images else None)


def remember(localizer: Localizer, images: Any, xy: Any, *, max_views: int = MAX_VIEWS,
             augmentation: CorruptionModel | None = None, seed: int = 0, keep_images: bool = False) -> Localizer:
    """Gives a fitted localizer the readout memory of its training run:
    ``images`` (N, H, W[, C]) as given to ``fit`` and the positions ``xy``
    (N, 2) its readout was fitted to; at most ``max_views`` evenly spaced
    views are kept. ``augmentation``: the corruption model of the readout's
    ``readout_augmentation`` (with the same ``seed``), if it was fitted on
    corrupted copies. ``keep_images``: keep the views' images too, for
    updates that re-solve every layer (``UpdatePolicy(resolve="all")``).
    Sets and returns ``localizer`` (``readout_memory_``); it is saved with
    the model file, together with the network's training statistics.

    NotFittedError for an unfitted localizer, ValueError for one without a
    network or whose network cannot be split at its top stage.
    """
    if not isinstance(localizer, Localizer):
        raise TypeError(f"localizer must be a sfanav.Localizer, got {type(localizer).__name__}")
    if not localizer.is_fitted_:
        raise NotFittedError("this Localizer is not fitted; fit it before giving it a readout memory")
    if augmentation is not None and not isinstance(augmentation, CorruptionModel):
        raise TypeError(f"augmentation must be a CorruptionModel or None, got {type(augmentation).__name__}")
    localizer.readout_memory_ = _memory_of(localizer, images, xy, augmentation, seed,
                                           check_int(max_views, "max_views"), keep_images=bool(keep_images))
    return localizer


def readout_memory_bytes(localizer: Localizer) -> dict[str, int]:
    """What keeping a localizer updatable costs in its model file (bytes):
    ``{"readout_memory": ..., "network_statistics": ...}``."""
    mem = getattr(localizer, "readout_memory_", None)
    net = localizer.trained_network()
    return {"readout_memory": 0 if mem is None else mem.nbytes,
            "network_statistics": statistics_bytes(net) if mem is not None else 0}


def drop_readout_memory(localizer: Localizer) -> Localizer:
    """``localizer`` without its readout memory (its model file then keeps
    no network statistics either: smaller, no longer updatable). Returns
    it."""
    localizer.readout_memory_ = None
    return localizer


def updatable_memory(localizer: Any, why: str) -> "ReadoutMemory":
    """The readout memory of a fitted, updatable :class:`Localizer`.
    TypeError for another object, NotFittedError for an unfitted one,
    ValueError naming ``why`` the memory is needed when it has none."""
    if not isinstance(localizer, Localizer):
        raise TypeError(f"localizer must be a sfanav.Localizer, got {type(localizer).__name__}")
    if not localizer.is_fitted_:
        raise NotFittedError("this Localizer is not fitted; fit it before updating it or joining a run to it")
    mem = getattr(localizer, "readout_memory_", None)
    if mem is None:
        raise ValueError(f"this localizer keeps no readout memory (its map's views), so {why}: train it with "
                         "readout_memory (sfanav train --updatable)")
    return mem


PAIR_MAX_TURN_DEG = 15.0
"""The largest heading difference (degrees) of a cross-run pair under ``resolve="all"``
(:class:`LocalizerUpdater` ``pair_max_turn_deg``)."""


class LocalizerUpdater:
    """Adds runs to a fitted :class:`~sfanav.Localizer` (scikit-learn's
    ``partial_fit``): the network's top stage re-solved from its statistics
    plus the runs' (:class:`~sfanav.sfa.updates.NetworkUpdater`), then the
    readout refitted, same kind and settings, on the readout memory's views
    (slow features recomputed from their stored stage inputs) and the new
    runs' views.

    Parameters
    ----------
    localizer : Localizer
        Fitted, with a network holding its training statistics and a
        readout memory (:func:`remember`, ``fit_localizer(...,
        readout_memory=N)``, or a model file saved from such a localizer).
        Not modified: updates make new localizers.
    policy : UpdatePolicy, default ``UpdatePolicy()``
        When to solve (``every``); ``resolve="top"``.
    augmentation : CorruptionModel or None
        Needed when the readout memory holds corrupted copies (a readout
        fitted with ``readout_augmentation``): the new runs get copies drawn
        from it as well (``seed``).
    seed : int, default 0
    cross_pairs : bool, default False
        Join each new view to the map's view nearest to it (within
        ``pair_radius``) by a derivative pair of their inputs to the
        re-solved stage (:func:`cross_run_pairs`,
        :meth:`~sfanav.sfa.updates.NetworkUpdater.add_pairs`): the pair
        place-major training forms between a place's views in two
        recordings, which makes the slow features invariant to what differs
        between the runs (light, season). Weight: the network's transition
        weight per pair, spread over the K pooled rotations. False: each run
        joins only as its own sequence. Off by default: on the seasons
        scene fed season by season the pairs made the updated map worse
        at most steps (docs/updates-measured.md): with the lower layers
        frozen on the first recording the top stage cannot become
        invariant to the season without losing position.
    pair_radius : float or None, default None
        Metres; None: twice the median spacing of the map's views.
    pair_max_turn_deg : float or None, default 15
        Under ``resolve="all"``, a cross-run pair is kept only if its two
        panoramas face the same way to within this many degrees (their
        column shift by :func:`sfanav.loopclosure.align`): every layer's
        nodes see parts of the panorama, and a pair of views of one place
        at different headings tells each node that two different directions
        are the same (on ``6.2.1-changes-online``, where the second run
        crosses the first's lanes at right angles, the pairs made the
        every-layer update 2.2x the retrain's error; with this test 1.0x,
        docs/updates-measured.md). None: every pair.
    kernel : {"auto", "keep", "learn"}, default "auto"
        A Gaussian-process readout's kernel hyperparameters (length scales,
        noise): ``"keep"`` fits the posterior on all views with the fitted
        kernel (one Cholesky factorisation: the update's cost stays a small
        fraction of a retrain); ``"learn"`` learns them again by maximum
        likelihood, as training does (most of a retrain's readout cost);
        ``"auto"`` learns them when the map has seen at least twice the
        images the kernel was learned on (``info["readout_kernel_images"]``),
        and keeps them otherwise, so relearning happens at geometrically
        spaced sizes and its cost per added image stays bounded. Other
        readouts are refitted as trained in every case. Measured in
        docs/updates-measured.md.
    readout : {"auto", "keep"}, default "auto"
        ``"keep"``: the readout is refitted as the model fitted it (its kind
        and settings). ``"auto"``: when the model's readout was chosen
        automatically (``readout="auto"``, the default) and the map holds
        two or more runs of the same places (:func:`runs_share_places`: at
        least half of every run's views near another run's; a run that
        explores new ground does not count), the readout is chosen again, as training
        on several recordings chooses it (leave-one-run-out cross-validation
        over the runs, ``fit_localizer(groups=)``), at every solve that
        learns the kernel again (``kernel``): its kind can change, e.g. to
        the nearest views by the appearance signature, which training on
        several recordings in different light chooses (docs/updates-measured.md).
        Elsewhere (a readout given by kind, one run) as ``"keep"``.

    Attributes
    ----------
    localizer_ : Localizer
        The localizer as of the last solve, with the grown readout memory.
    n_images_, n_pending_, n_solves_, n_pairs_ : int
        Images added, added since the last solve, solves, cross-run pairs
        added.

    Raises TypeError / NotFittedError / ValueError for a localizer that
    cannot be updated (no memory, no statistics), naming what is missing.
    """

    def __init__(self, localizer: Localizer, policy: UpdatePolicy | None = None, *,
                 augmentation: CorruptionModel | None = None, seed: int = 0, kernel: str = "auto",
                 cross_pairs: bool = False, pair_radius: float | None = None,
                 pair_max_turn_deg: float | None = PAIR_MAX_TURN_DEG, readout: str = "auto") -> None:
        mem = updatable_memory(localizer, "its readout cannot be refitted after an update")
        if kernel not in KERNEL:
            raise ValueError(f"kernel must be one of {', '.join(KERNEL)}, got {kernel!r}")
        if readout not in READOUT:
            raise ValueError(f"readout must be one of {', '.join(READOUT)}, got {readout!r}")
        self.kernel = kernel
        self.readout = readout
        self.cross_pairs = bool(cross_pairs)
        if pair_radius is not None and not (np.isfinite(pair_radius) and pair_radius > 0):
            raise ValueError(f"pair_radius must be a positive number of metres or None, got {pair_radius!r}")
        self.pair_radius = pair_radius
        if pair_max_turn_deg is not None and not (np.isfinite(pair_max_turn_deg) and 0 <= pair_max_turn_deg <= 180):
            raise ValueError(f"pair_max_turn_deg must be a number of degrees in [0, 180] or None, got "
                             f"{pair_max_turn_deg!r}")
        self.pair_max_turn_deg = pair_max_turn_deg
        if mem.augmented is not None and augmentation is None:
            raise ValueError("this localizer's readout was fitted on corrupted copies as well: pass the corruption "
                             "model (augmentation=) so that the new runs get copies too")
        if augmentation is not None and not isinstance(augmentation, CorruptionModel):
            raise TypeError(f"augmentation must be a CorruptionModel or None, got {type(augmentation).__name__}")
        self.policy = UpdatePolicy() if policy is None else policy
        if not isinstance(self.policy, UpdatePolicy):
            raise TypeError(f"policy must be an UpdatePolicy, got {type(self.policy).__name__}")
        if self.policy.resolve == "all" and mem.images is None:
            raise ValueError("re-solving every layer (resolve='all') trains on the old views' images, and this "
                             "localizer's readout memory keeps none: remember(..., keep_images=True)")
        # the network solves when this updater says so (its top-stage statistics; unused under resolve="all")
        self._net = NetworkUpdater(localizer.trained_network(), UpdatePolicy("top", every=sys.maxsize))
        self.augmentation = augmentation if mem.augmented is not None else None
        self.seed = check_int(seed, "seed", minimum=0)
        self.localizer_ = localizer
        self._pending: ReadoutMemory | None = None
        self.n_images_ = self.n_pending_ = self.n_solves_ = self.n_pairs_ = 0
        self._pairs_at_solve = 0

    def partial_fit(self, images: Any, xy: Any = None) -> "LocalizerUpdater":
        """Adds one run: images (N, H, W[, C]) as the localizer takes them
        and their positions ``xy`` (N, 2) metres in the map's frame; solves
        if the policy says so. Returns ``self``. ValueError for a run that
        does not match the model or comes without positions (nothing is
        changed then)."""
        loc = self.localizer_
        if xy is None:
            raise ValueError("this run has no positions: give its ground-truth positions, or, for a run with odometry "
                             "only, the positions sfanav.odometry.map_joining.join_run learns in the map's frame")
        a = np.asarray(images)
        Y = as_matrix(xy, "xy", n_cols=2)
        check_same_length(a, Y, "images", "xy")
        net_images = self._net.check_run(loc.network_input(a))
        mem = loc.readout_memory_
        new = _memory_of(loc, a, Y, self.augmentation, self.seed, max_views=len(a),
                         keep_images=mem.images is not None)
        new.max_views = mem.max_views
        # resolve="all" trains every layer again on the images at solve time (with its own cross-run pairs):
        # the top-stage statistics below would be computed for nothing
        top = self.policy.resolve == "top"
        if top and self.cross_pairs:
            seen = mem if self._pending is None else _concat(mem, self._pending)
            i_old, j_new = cross_run_pairs(seen.positions, new.positions, self.pair_radius)
            K = new.inputs.shape[1]
            w = np.full(len(i_old) * K, self._net.transition_weight / K)
            k = new.inputs.shape[2]
            self._net.add_pairs(seen.inputs[i_old].reshape(-1, k), new.inputs[j_new].reshape(-1, k), w)
            self.n_pairs_ += len(i_old)
        if top:
            self._net.partial_fit(net_images)
        self._pending = new if self._pending is None else _concat(self._pending, new)
        self.n_images_ += len(a)
        self.n_pending_ += len(a)
        if self.policy.due(self.n_pending_):
            self.solve()
        return self

    def solve(self) -> Localizer:
        """Re-solves the network's top stage and refits the readout on the
        memory's and the pending runs' views; returns the new localizer
        (also ``localizer_``)."""
        old = self.localizer_
        mem = old.readout_memory_
        views = mem if self._pending is None else _concat(mem, self._pending)
        if self.policy.resolve == "all":
            return self._solve_all(old, views)
        net = self._net.solve()
        F = top_stage_features(net, views.inputs)
        aug = None
        if views.augmented is not None:
            aug = (top_stage_features(net, views.augmented[0]), views.augmented[1])
        # the fitted readout's kind and settings, the fitted pooling; chosen again by runs when the kernel is learned
        n_seen = views.n_seen
        learned_on = int((old.info or {}).get("readout_kernel_images", mem.n_seen))
        learn = self.kernel == "learn" or (self.kernel == "auto" and n_seen >= 2 * learned_on)
        reselect = learn and self._reselects(old, views)
        new = old.sibling(network=net, readout="auto" if reselect else
                          readout_spec_for_update(old, "learn" if learn else "keep"),
                          n_outputs=old.n_outputs_ or None, rotation_pooling=old.rotation_pooling_)
        new.fit_features(F, views.positions, signatures=views.signatures, augmented=aug,
                         groups=views.runs if reselect else None)
        # the parameters as the user gave them
        new.readout, new.n_outputs, new.rotation_pooling = old.readout, old.n_outputs, old.rotation_pooling
        new.info = dict(old.info or {})
        n_added = 0 if self._pending is None else self._pending.n_seen
        new.info["n_train_images"] = int(new.info.get("n_train_images", mem.n_seen)) + n_added
        new.info["updates"] = list(new.info.get("updates", [])) + [{"n_images": int(n_added),
                                                                     "readout_views": int(len(views)),
                                                                     "kernel": "learned" if learn else "kept",
                                                                     "readout": _readout_note(new, reselect),
                                                                     "cross_pairs": int(self.n_pairs_
                                                                                        - self._pairs_at_solve)}]
        self._pairs_at_solve = self.n_pairs_
        new.info["readout_kernel_images"] = int(n_seen if learn else learned_on)
        new.readout_memory_ = mem if self._pending is None else mem.extended(self._pending)
        self.localizer_ = new
        self._pending = None
        self.n_pending_ = 0
        self.n_solves_ += 1
        return new

    def _solve_all(self, old: Localizer, views: ReadoutMemory) -> Localizer:
        """``resolve="all"``: the localizer trained again, every layer, on the
        remembered and the pending views' images as one sequence run after run,
        the runs joined by derivative pairs between each view and the nearest
        view of an earlier run (:func:`cross_run_pairs`, at every layer and
        simulated rotation: what place-major training gives a place seen in two
        runs), with the training recipe the model file records (rotation,
        invariance partners, readout augmentation, readout kind; an automatic
        readout chosen again over the runs, ``readout="auto"``)."""
        from ..sfa.network import Network, Rotation
        from .training import fit_localizer

        info = dict(old.info or {})
        net0 = old.trained_network()
        rot = info.get("rotation") or {}
        rotation = Rotation(int(rot.get("step", net0.step_ or 5)), float(rot.get("window", 1.0)))
        invariance = None
        if info.get("invariance"):
            if info["invariance"] != CAMERA.describe():
                raise ValueError("this localizer's network was trained with invariance partners of a corruption model "
                                 "this sfanav does not know, so it cannot be trained again as it was")
            invariance = CAMERA
        R, P = views.runs, views.positions
        a_idx: list[np.ndarray] = []
        b_idx: list[np.ndarray] = []
        for r in np.unique(R)[1:]:
            earlier, this = np.flatnonzero(R < r), np.flatnonzero(R == r)
            i, j = cross_run_pairs(P[earlier], P[this], self.pair_radius)
            a_idx.append(earlier[i])
            b_idx.append(this[j])
        pa = np.concatenate(a_idx) if a_idx else np.zeros(0, np.int64)
        pb = np.concatenate(b_idx) if b_idx else np.zeros(0, np.int64)
        n_found = len(pa)
        if len(pa) and self.pair_max_turn_deg is not None:
            from ..loopclosure.closures import align

            W = views.images.shape[2]
            shift = align(views.images, pa, pb)
            keep = np.minimum(shift, W - shift) * (360.0 / W) <= self.pair_max_turn_deg
            pa, pb = pa[keep], pb[keep]
        reselect = self._reselects(old, views)
        fit = {"transition_weight": self._net.transition_weight}
        if len(pa):
            fit["pairs"] = (pa, pb, np.full(len(pa), self._net.transition_weight))
        new = fit_localizer(Network(net0.config), views.images, P, rotation=rotation,
                            readout="auto" if reselect else readout_spec_for_update(old, "learn"),
                            n_outputs=old.n_outputs_ or None, rows=old.rows,
                            rotation_pooling=old.rotation_pooling_, signature=old.signature, photometric=old.photometric,
                            lowpass=old.lowpass,
                            readout_augmentation=self.augmentation, invariance=invariance,
                            invariance_weight=float(info.get("invariance_weight", 1.0)), network_fit=fit,
                            progress=False, seed=self.seed, **({"groups": views.runs} if reselect else {}))
        memory = _memory_of(new, views.images, P, self.augmentation, self.seed, max_views=len(P), keep_images=True)
        memory.runs, memory.max_views, memory.n_seen = views.runs.copy(), views.max_views, views.n_seen
        n_added = 0 if self._pending is None else self._pending.n_seen
        new.info = {**info, **{k: v for k, v in new.info.items() if k not in ("n_train_images",)}}
        new.info["n_train_images"] = int(info.get("n_train_images", old.readout_memory_.n_seen)) + n_added
        new.info["updates"] = list(info.get("updates", [])) + [{"n_images": int(n_added), "readout_views": int(len(P)),
                                                                "resolve": "all", "cross_run_pairs": int(len(pa)),
                                                                "cross_run_pairs_turned": int(n_found - len(pa)),
                                                                "readout": _readout_note(new, reselect)}]
        new.info["readout_kernel_images"] = int(views.n_seen)
        new.readout_memory_ = memory.subset(evenly_spaced(len(memory), memory.max_views))
        new.readout, new.n_outputs, new.rotation_pooling = old.readout, old.n_outputs, old.rotation_pooling
        self.localizer_ = new
        self._pending = None
        self.n_pending_ = 0
        self.n_solves_ += 1
        return new

    def _reselects(self, old: Localizer, views: ReadoutMemory) -> bool:
        """Whether this solve chooses the readout again by runs (``readout="auto"``): an automatic
        readout, and runs of the same places (:func:`runs_share_places`)."""
        return (self.readout == "auto" and isinstance(old.readout, str) and old.readout == "auto"
                and runs_share_places(views.positions, views.runs, self.pair_radius))


def _readout_note(localizer: Localizer, reselected: bool) -> str:
    """What an update's record says of the readout: its kind, and the rule when it was chosen again."""
    kind = describe_spec(localizer.readout_spec_)
    sel = getattr(localizer, "selection_", None)
    if reselected and sel is not None:
        return f"chosen again by runs: {kind} ({sel.rule})"
    return f"refitted: {kind}"


SAME_PLACES_FRACTION = 0.5
"""The share of each run's views that must lie near another run's views for
an update to treat the runs as recordings of the same places and choose
the readout again over them (:func:`runs_share_places`)."""


def runs_share_places(xy: Any, runs: Any, radius: float | None = None, *,
                      fraction: float = SAME_PLACES_FRACTION) -> bool:
    """Whether views at ``xy`` (N, 2) metres from ``runs`` (N,) are two or
    more recordings of the same places: every run has at least ``fraction``
    of its views within ``radius`` metres of another run's (None: twice the
    median distance from a view to the nearest other view of its own run).
    Leave-one-run-out cross-validation, which chooses a readout over
    recordings, scores a run that explores new ground as an extrapolation
    and would choose for the wrong reason: on such runs an update keeps
    the readout's kind (docs/updates-measured.md).

    >>> import numpy as np
    >>> loop = np.c_[np.cos(np.linspace(0, 6, 50)), np.sin(np.linspace(0, 6, 50))]
    >>> runs_share_places(np.r_[loop, loop + 0.01], np.repeat([0, 1], 50))
    True
    >>> runs_share_places(np.r_[loop, loop + 5.0], np.repeat([0, 1], 50))
    False
    """
    P = as_matrix(xy, "xy", n_cols=2)
    R = np.asarray(runs)
    if R.shape != (len(P),):
        raise ValueError(f"runs must hold one label per view ({len(P)}), got shape {R.shape}")
    from scipy.spatial import cKDTree

    labels = np.unique(R)
    if len(labels) < 2:
        return False
    if radius is None:  # the runs' own spacing (pooled views of two runs may coincide)
        gaps = np.concatenate([cKDTree(P[R == r]).query(P[R == r], k=2)[0][:, 1] for r in labels
                               if np.count_nonzero(R == r) >= 2] or [np.zeros(0)])
        spacing = float(np.median(gaps)) if gaps.size else 0.0
        radius = 2.0 * spacing if spacing > 0 else 1e-9
    for r in labels:
        others, this = np.flatnonzero(R != r), np.flatnonzero(R == r)
        _, j = cross_run_pairs(P[others], P[this], radius)
        if len(j) < fraction * len(this):
            return False
    return True


def cross_run_pairs(old_xy: Any, new_xy: Any, radius: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For each new view, the old view nearest to it: ``(i_old, j_new)``
    int64 (P,), only pairs closer than ``radius`` metres (None: twice the
    median distance from an old view to its nearest other old view).
    ``old_xy`` (N, 2), ``new_xy`` (M, 2), metres in one frame.

    Examples
    --------
    >>> import numpy as np
    >>> cross_run_pairs(np.c_[np.arange(5.0), np.zeros(5)], [[1.1, 0.2], [9.0, 0.0]])
    (array([1]), array([0]))
    """
    from scipy.spatial import cKDTree

    P = as_matrix(old_xy, "old positions", n_cols=2)
    Q = as_matrix(new_xy, "new positions", n_cols=2)
    if len(P) == 0 or len(Q) == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e.copy()
    tree = cKDTree(P)
    if radius is None:
        if len(P) < 2:
            raise ValueError("one old view: give pair_radius")
        spacing = float(np.median(tree.query(P, k=2)[0][:, 1]))
        radius = 2.0 * spacing if spacing > 0 else 1e-9
    d, i = tree.query(Q, k=1)
    keep = np.flatnonzero(d < radius)
    return i[keep].astype(np.int64), keep.astype(np.int64)


READOUT = ("auto", "keep")
"""What an update does with the readout's kind (:class:`LocalizerUpdater` ``readout``)."""

KERNEL = ("auto", "keep", "learn")
"""What an update does with a Gaussian-process readout's kernel."""

_GP_HYPERPARAMETERS = {"gp": ("length_scale", "noise"), "gp-signature": ("length_scale", "signature_scale", "noise")}


def readout_spec_for_update(localizer: Localizer, kernel: str = "keep") -> dict[str, Any]:
    """The readout spec an update refits ``localizer``'s readout with: its
    fitted spec, and for a Gaussian-process readout (``gp``,
    ``gp-signature``) its fitted kernel hyperparameters fixed (``kernel=
    "keep"``) or left to be learned (``"learn"``)."""
    spec = dict(localizer.readout_spec_)
    names = _GP_HYPERPARAMETERS.get(spec.get("kind"), ())
    for name in names:
        spec.pop(name, None)
    if names and kernel == "keep":
        reg = localizer.regression_
        spec.update({name: ([float(v) for v in np.ravel(getattr(reg, name + "_"))] if name == "length_scale"
                            else float(getattr(reg, name + "_"))) for name in names})
    return spec


def _concat(a: ReadoutMemory, b: ReadoutMemory) -> ReadoutMemory:
    """Every view of ``a`` then ``b`` (no thinning; ``a``'s bound)."""
    wide = a.subset(np.arange(len(a)))
    wide.max_views = sys.maxsize
    out = wide.extended(b)
    out.max_views = a.max_views
    return out
