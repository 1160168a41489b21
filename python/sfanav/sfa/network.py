"""The hierarchical receptive-field SFA network (thesis sections 3.3-3.4, 5.1).

Layers of SFA nodes on regular grids turn a panoramic image into a few slow
features that encode the robot's position and not its orientation, learned
from one exploration run with simulated rotation. The numerics run in Rust
(``sfanav._core.Network``); this module handles configs, presets, image
streaming, progress and persistence.
"""

from __future__ import annotations

import copy
import os
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from importlib import resources
from math import comb
from pathlib import Path
from typing import Any

import numpy as np

from .. import _core
from .._checks import (
    NotFittedError,
    as_image_batch,
    check_int,
    check_nonneg_float,
    check_positive_float,
    is_single_image,
)
from .._progress import progress_bar
from .config import (
    PRESETS,
    preset_config,
    read_config_file,
    resolve_config,
    spec_to_json,
)
from ..loopclosure.partners import closure_partners
from .feedback import check_partners
from .modelfile import dumps, register_loader, save_model, state_from_bytes
from .pairs import check_pairs

DEFAULT_CACHE_LIMIT = 1e9  # bytes of cached lower-layer fields under cache="auto"


@dataclass(frozen=True)
class Rotation:
    """Simulated rotation (thesis 3.4.1): every training panorama is shown as
    its lateral circular shifts by ``step`` pixels, seen through a window of
    ``window`` x the panorama width (1.0: the whole image, rolled)."""

    step: int = 5
    window: float = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.step, bool) or not isinstance(self.step, (int, np.integer)) or self.step < 1:
            raise ValueError(f"Rotation.step must be a positive integer (pixels), got {self.step!r}")
        if not (isinstance(self.window, (int, float)) and 0.0 < self.window <= 1.0):
            raise ValueError(f"Rotation.window must be in (0, 1], got {self.window!r}")


def _image_array(images: Any, what: str) -> np.ndarray:
    """Training images that ``what`` indexes: an array, or an ``.npy`` path
    (memory-mapped). TypeError for anything else (an iterable is read once
    per pass and cannot be indexed)."""
    if isinstance(images, (str, os.PathLike)):
        images = np.load(Path(images), mmap_mode="r", allow_pickle=False)
    if not isinstance(images, np.ndarray):
        raise TypeError(f"{what} need the images as an array (N, H, W[, C]) or an .npy path")
    return images


def _check_transition_weight(w: Any) -> float:
    if isinstance(w, bool) or not isinstance(w, (int, float, np.integer, np.floating)):
        raise TypeError(f"transition_weight must be a number, got {type(w).__name__}")
    w = float(w)
    if not (np.isfinite(w) and w >= 0.0):
        raise ValueError(f"transition_weight must be a finite number >= 0, got {w!r}")
    return w


def _batches_of(images: Any, batch_size: int) -> Callable[[], Iterable[np.ndarray]]:
    """A function that returns a fresh iterator of image batches (N, H, W[, C])
    each time it is called (training needs several passes)."""
    if isinstance(images, (str, os.PathLike)):
        path = Path(images)
        if not path.exists():
            raise FileNotFoundError(f"no image data at {path}")
        if path.suffix != ".npy":
            raise ValueError(f"{path}: give an .npy array of images (N, H, W[, C]) or an array")
        images = np.load(path, mmap_mode="r", allow_pickle=False)
    if isinstance(images, np.ndarray):
        if images.ndim not in (3, 4):
            raise ValueError(f"images must have shape (N, H, W) or (N, H, W, C), got {images.shape}")
        arr = images
        return lambda: (arr[i : i + batch_size] for i in range(0, len(arr), batch_size))
    if callable(images):
        factory = images

        def from_factory() -> Iterable[np.ndarray]:
            return _rebatch(factory(), batch_size)

        return from_factory
    if isinstance(images, Sequence):
        seq = images
        return lambda: _rebatch(iter(seq), batch_size)
    if isinstance(images, Iterable):
        raise TypeError(
            "training reads the images several times (two passes per layer): pass an array, "
            "a list, an .npy path, or a function that returns a fresh iterable, not a one-shot "
            "iterator or generator"
        )
    raise TypeError(f"cannot read images from {type(images).__name__}")


def _rebatch(it: Iterable[Any], batch_size: int) -> Iterable[np.ndarray]:
    buf: list[np.ndarray] = []
    for item in it:
        a = np.asarray(item)
        if a.ndim in (2, 3) and (a.ndim == 2 or a.shape[-1] in (1, 3)):
            buf.append(a)  # one image
        elif a.ndim in (3, 4):
            if buf:
                yield np.stack(buf)
                buf = []
            yield a  # already a batch
            continue
        else:
            raise ValueError(f"an image must be (H, W) or (H, W, C), got shape {a.shape}")
        if len(buf) == batch_size:
            yield np.stack(buf)
            buf = []
    if buf:
        yield np.stack(buf)


class _PassBars:
    """A tqdm bar per training pass, driven by the core's progress reports
    (``_core.Network.fit``)."""

    def __init__(self) -> None:
        self.bar: Any = None
        self.done = 0

    def __call__(self, event: str, layer: int, n_layers: int, pass_: int, n_passes: int, done: int,
                 total: int | None, cached: bool) -> None:
        if event == "start":
            self.close()
            desc = f"layer {layer + 1}/{n_layers} pass {pass_ + 1}/{n_passes}" + (" (cached)" if cached else "")
            self.bar, self.done = progress_bar(True, total, desc), 0
        elif self.bar is not None:
            self.bar.update(done - self.done)
            self.done = done
            if event == "finish":
                self.close()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


# --------------------------------------------------------------------- Network


class Network:
    """Hierarchical SFA network over panoramic images.

    Parameters
    ----------
    config : dict, or path to a TOML/JSON file
        Layer grids and node settings, in the format of the preset files
        (``sfanav/sfa/presets/*.toml``; see :meth:`from_preset`).

    Attributes
    ----------
    config_ : dict
        The resolved spec (explicit RF sizes and reductions).
    delta_values_ : ndarray of shape (n_outputs,)
        Delta values of the top node after :meth:`fit`.

    Examples
    --------
    >>> net = sfanav.Network.from_preset("thesis-5.1")
    >>> net.fit(train_images, rotation=sfanav.Rotation(step=5))   # doctest: +SKIP
    >>> codes = net.transform(test_images)  # (N, 8)               # doctest: +SKIP
    """

    def __init__(self, config: dict[str, Any] | str | os.PathLike) -> None:
        if isinstance(config, (str, os.PathLike)):
            config = read_config_file(config)
        self.config = copy.deepcopy(config)
        self.config_ = resolve_config(self.config)
        self._net = _core.Network(self.config_)

    @classmethod
    def from_preset(cls, name: str, **overrides: Any) -> "Network":
        """A network of the thesis's tables: ``"thesis-5.1"`` (350x40 RGB),
        ``"thesis-5.2"`` (600x60 RGB), ``"thesis-5.3"`` (409x40 gray); or
        ``"sfanav-default"``, the sfanav default (Table 5.1's geometry with
        20 / 24 / 24 outputs in layers 1-3 and 12 top outputs, mixed
        precision; why: docs/gardens.md).

        Overrides: ``weight_sharing``, ``max_expanded``, ``tol``, ``precision``
        (network settings), ``degree`` and ``reduce_to`` (applied to every layer), and
        ``out`` (the top node's number of outputs)."""
        config = preset_config(name)
        for key, value in overrides.items():
            if key in ("weight_sharing", "max_expanded", "tol", "precision"):
                config.setdefault("network", {})[key] = value
            elif key in ("degree", "reduce_to"):
                for layer in config["layers"]:
                    layer[key] = value
            elif key == "out":
                config["layers"][-1]["out"] = value
            else:
                raise ValueError(
                    f"unknown override {key!r}; use weight_sharing, max_expanded, tol, precision, degree, "
                    "reduce_to or out, or edit a copy of the preset file"
                )
        return cls(config)

    @staticmethod
    def presets() -> tuple[str, ...]:
        """Names of the built-in presets."""
        return PRESETS

    @staticmethod
    def preset_path(name: str) -> Path:
        """Path of a preset's TOML file (copy it to start your own)."""
        preset_config(name)
        return Path(str(resources.files("sfanav.sfa").joinpath("presets", f"{name}.toml")))

    # ------------------------------------------------------------ info
    @property
    def input_shape(self) -> tuple[int, int, int]:
        """(height, width, channels) the network takes."""
        return tuple(self._net.input_shape)  # type: ignore[return-value]

    @property
    def n_outputs_(self) -> int:
        return self._net.n_outputs

    @property
    def period_(self) -> int | None:
        """Width in px of the panoramas the network was trained on (the
        rotation period), or None before :meth:`fit`."""
        return getattr(self, "_period", None)

    @property
    def step_(self) -> int | None:
        """The simulated-rotation step (px) of training, or None before
        :meth:`fit`."""
        return getattr(self, "_step", None)

    @property
    def delta_values_(self) -> np.ndarray:
        self._check_trained()
        return self._net.delta_values

    @property
    def beta_values_(self) -> np.ndarray:
        from .node import beta_values

        return beta_values(self.delta_values_)

    @property
    def is_fitted_(self) -> bool:
        return self._net.n_trained == self._net.n_layers

    def _check_trained(self) -> None:
        if not self.is_fitted_:
            raise NotFittedError(
                f"this network is not fitted ({self._net.n_trained} of {self._net.n_layers} layers "
                "trained); call fit first"
            )

    def describe(self) -> str:
        """A table of each layer's grid, dims and rank deficits."""
        h, w, c = self.input_shape
        lines = [
            f"Network: input {w}x{h}x{c}, {'shared' if self.config_['weight_sharing'] else 'individual'} "
            f"nodes, {self._net.n_trained}/{self._net.n_layers} layers trained",
            f"{'layer':>5} {'input':>11} {'RFs':>7} {'RF size':>7} {'stride':>6} {'in dim':>6} "
            f"{'k':>4} {'exp dim':>7} {'out':>4} {'rank deficit':>12}",
        ]
        for i, g in enumerate(self._net.geometry(), 1):
            iw, ih, ic = g["input"]
            exp_dim = comb(g["reduce_to"] + g["degree"], g["degree"]) - 1
            rd = g["rank_deficits"]
            deficit = "-" if not any(rd) and i > self._net.n_trained else (
                "/".join(str(x) for x in rd[0]) if len(rd) == 1 else f"max {max(max(r) if r else 0 for r in rd)}"
            )
            lines.append(
                f"{i:>5} {f'{iw}x{ih}x{ic}':>11} {'{}x{}'.format(*g['grid']):>7} "
                f"{'{}x{}'.format(*g['rf']):>7} {'{}x{}'.format(*g['stride']):>6} {g['in_dim']:>6} "
                f"{g['reduce_to']:>4} {exp_dim:>7} {g['n_out']:>4} {deficit:>12}"
            )
        return "\n".join(lines)

    def __repr__(self) -> str:
        h, w, c = self.input_shape
        return f"<sfanav.Network {w}x{h}x{c}, {self._net.n_layers} layers, {self.n_outputs_} outputs>"

    # ------------------------------------------------------------ training
    def fit(
        self,
        images: Any,
        rotation: Rotation | None = None,
        *,
        fast: bool = True,
        cache: bool | str = "auto",
        cache_limit: float = DEFAULT_CACHE_LIMIT,
        batch_size: int = 16,
        progress: bool = True,
        transition_weight: float = 1.0,
        pairs: tuple[Any, ...] | None = None,
        pair_layers: Sequence[int] | None = None,
        loop_closures: Any = None,
        closure_weights: Any = None,
        partners: tuple[Any, Any, Any] | None = None,
        client: Any = None,
        breaks: Any = None,
    ) -> "Network":
        """Trains the network layer by layer, in the order the images come.

        Parameters
        ----------
        images : array (N, H, W[, C]), list of images, path to an ``.npy``
            file (memory-mapped), or a function returning a fresh iterable of
            images or batches. Read in batches, several times (two passes per
            layer); never all expanded at once. ``W`` is the panorama width
            (the rotation period); the network's input width is the window.
        rotation : Rotation, default ``Rotation(step=5, window=1.0)``
        fast : bool, default True
            Exact fast training (periodic fields with multiplicities); False
            runs the naive per-view path (same result, slower). Without
            weight sharing the naive path is always used.
        cache : bool or "auto", default "auto"
            Keep each image's periodic field of the layer below in memory
            (float32 for mixed-precision networks, else float64) so later
            passes and layers need neither recomputation of the lower layers
            nor, above the first layer, the images. True caches every
            layer's input field; False streams the images in every pass and
            recomputes the lower layers; "auto" caches a layer's input field
            when all images' fields fit in ``cache_limit`` bytes (the sizes
            per layer: docs/benchmarks.md). ``cache_plan_`` records the
            choice per layer.
        cache_limit : float, default 1e9
            Byte budget of the field cache under ``cache="auto"``.
        batch_size : int
            Images per batch read from ``images`` (and per chunk of spatial
            pairs).
        progress : bool
            A progress bar per layer and pass (tqdm).
        transition_weight : float, default 1.0
            Weight of the derivative pairs *between* consecutive training
            images (per RF series, one pair: the last rotated view of image
            ``i`` and the first view of image ``i + 1``) relative to the
            pairs between consecutive views *within* an image (weight 1).
            1.0 is the thesis (one sequence of all views). Finite and >= 0
            (0: every image its own sequence). Weights of order ``K =
            ceil(W / step)`` (the views per image) give the change of
            position a say comparable to the rotation (graph-based SFA,
            Escalante & Wiskott 2013).
        pairs : (idx_a, idx_b, weights[, shifts]) or None
            Spatial pairs of training images (graph-based SFA): each
            ``(a, b, w)`` adds, at *every* simulated rotation and RF
            position, a derivative pair between view ``k`` of image ``a``
            and view ``k`` of image ``b`` with weight ``w`` (the rotation
            pairs have weight 1 each), in every layer and pass. With
            ``shifts`` (int pixels, per pair), image ``b`` is first rolled
            left by its shift, so the pair also compares two different
            orientations (random shifts penalise orientation-coding
            features, which same-view pairs of images taken at the same or
            opposite headings reward). Shifts that are multiples of
            ``rotation.step`` (with the step dividing the width) are read
            from the field cache; other shifts force ``cache=False``
            (slower; docs/gardens.md measures both).
            ``pair_layers`` (1-based layer numbers, default all) restricts
            the pairs to some layers (e.g. the top). Indices
            into ``images`` (which must then be an array or an ``.npy``
            path); weights finite and >= 0. Build them from positions with
            :func:`spatial_pairs` (supervised: the regression needs the
            positions anyway). Each pair costs about one image's share of
            the derivative statistics.
        loop_closures : LoopClosures, (past, current, shift) or None
            Loop-closure feedback (thesis 6.2.1): each image ``current[i]``
            is trained on its simulated rotation interleaved with that of
            ``np.roll(images[past[i]], shift[i], axis=2)`` (the earlier
            visit aligned to it): ``A'_0, C_0, A'_1, C_1, ...``, in every
            layer and pass, on the exact fast path (the partners' fields join
            the field cache). At most one closure per current image. Find
            them with :mod:`sfanav.loopclosure`. Needs the images as an array
            or ``.npy`` path.
        closure_weights : None, "score" or array (M,)
            Each closure's weight in [0, 1], mixing its interleaved sequence
            with the plain rotation (None: 1, the thesis; ``"score"``: the
            detector's match confidence).
        partners : (current, weights, images) or None
            Interleaving partners given as images rather than as loop
            closures: image ``current[i]`` (an index into ``images``) is
            trained on its simulated rotation interleaved with that of
            ``images[i]`` of this third array (M, H, W[, C], the training
            images' size and dtype, already aligned), mixed by ``weights[i]``
            in [0, 1] as ``closure_weights``. What
            :func:`sfanav.localization.fit_localizer` passes for invariance
            training: each image's partner is a corrupted copy of it (or of
            its loop-closure partner), so the slowness objective asks for
            outputs that ignore the corruption (docs/robustness.md). Not
            with ``loop_closures`` (build both into one set of partners);
            with ``client``, each partition trains its own images' partners.
        client : dask.distributed.Client, optional
            Train on a Dask cluster (``pip install "sfanav[dask]"``): the
            images (a list of arrays or ``.npy`` paths, one partition each;
            one array or ``.npy`` path, cut into one partition per worker;
            or a Dask array chunked along the frames) are streamed by the
            workers, their statistics merged in a tree, each layer solved
            here (:func:`sfanav.sfa.distributed.fit`; the same result up to
            rounding, with loop closures and spatial pairs too, indexing
            the frames of the whole run). No field cache (``cache`` is
            ignored). See docs/distributed.md.
        breaks : frame indices or ``"partitions"``, optional
            With ``client``: frames that start a new recording (no
            derivative pair with the frame before).

        Returns ``self``; ``input_scale_`` keeps the largest pixel value of
        the first training batch, and :meth:`transform` warns when images
        come on a scale 50 times larger or smaller (0..255 against 0..1).
        Raises ValueError / TypeError for images of the
        wrong shape, size or dtype, a window that does not match the
        network, or bad pairs; an exception raised while ``images`` is read
        comes out unchanged. The training loop runs in the Rust core
        (``sfa_core::training::fit``) with the GIL released.
        """
        if partners is not None and loop_closures is not None:
            raise ValueError("partners cannot be combined with loop_closures: give the loop closures' partners "
                             "among them (sfanav.localization.training.invariance_partners does)")
        if client is not None or breaks is not None:
            if client is None:
                raise ValueError("breaks needs client (or call sfanav.sfa.distributed.fit with client=None)")
            from .distributed import fit as distributed_fit

            return distributed_fit(self, images, rotation, client=client, breaks=breaks, fast=fast,
                                   transition_weight=transition_weight, batch_size=batch_size, progress=progress,
                                   loop_closures=loop_closures, closure_weights=closure_weights, pairs=pairs,
                                   pair_layers=pair_layers, partners=partners)
        rotation = rotation or Rotation()
        transition_weight = _check_transition_weight(transition_weight)
        shifted = False
        closures = None
        if loop_closures is None and closure_weights is not None:
            raise ValueError("closure_weights needs loop_closures")
        if loop_closures is not None:
            images = _image_array(images, "loop_closures")
            closures = closure_partners(images, loop_closures, closure_weights)
        if partners is not None:
            images = _image_array(images, "partners")
            closures = check_partners(partners, len(images), images.shape[1:], images.dtype)
        if not isinstance(rotation, Rotation):
            raise TypeError("rotation must be a sfanav.Rotation")
        if pairs is not None:
            images = _image_array(images, "pairs")
            pairs = check_pairs(pairs, len(images))
            n_layers = len(self.config_["layers"])
            if pair_layers is None:
                pair_layers = range(1, n_layers + 1)
            pair_layers = {int(x) for x in pair_layers}
            if not pair_layers <= set(range(1, n_layers + 1)):
                raise ValueError(f"pair_layers must name layers 1..{n_layers}, got {sorted(pair_layers)}")
            # cached passes read shifted pairs at shifted offsets of the cached fields: exact
            # when every shift is a multiple of the step and the step divides the period
            period0 = as_image_batch(images[:1]).shape[2]
            pairs = (*pairs[:3], pairs[3] % period0)
            shifted = bool(np.any(pairs[3]))
            if shifted and (period0 % rotation.step or np.any(pairs[3] % rotation.step)):
                cache = False  # cached fields are of the unrolled images
        batches = _batches_of(images, check_int(batch_size, "batch_size"))
        h, v, c = self.input_shape
        first = next(iter(batches()), None)
        if first is None:
            raise ValueError("no training images")
        first = as_image_batch(first)
        period = first.shape[2]
        self._check_images(first, period, training=True)
        expect_v = round(rotation.window * period)
        if expect_v != v:
            raise ValueError(
                f"the network's input is {v} px wide, but a {rotation.window:.0%} window of "
                f"{period}-px panoramas is {expect_v} px: build the network for that width"
            )
        if not (isinstance(cache, bool) or cache == "auto"):
            raise ValueError(f'cache must be True, False or "auto", got {cache!r}')
        if not (cache_limit >= 0):
            raise ValueError(f"cache_limit must be a non-negative number of bytes, got {cache_limit!r}")
        total = len(images) if hasattr(images, "__len__") and not callable(images) else None

        def checked() -> Iterable[np.ndarray]:
            for batch in batches():
                batch = as_image_batch(batch)
                self._check_images(batch, period, training=True)
                yield batch

        core_pairs: tuple[Any, ...] | None = None
        gather: Callable[[list[int]], np.ndarray] | None = None
        if pairs is not None:
            arr = images
            core_pairs = (*(x.tolist() for x in pairs[:3]), pairs[3].tolist() if shifted else None)

            def gather(ids: list[int]) -> np.ndarray:
                return as_image_batch(arr[ids])
        bars = _PassBars() if progress else None
        net = _core.Network(self.config_)
        try:
            plan = net.fit(
                checked, rotation.step, period, fast=fast, cache=None if cache == "auto" else bool(cache),
                cache_limit=float(cache_limit), transition_weight=transition_weight, pairs=core_pairs,
                pair_layers=None if pairs is None else sorted(pair_layers), gather=gather, pair_chunk=batch_size,
                closures=closures if closures and closures[0] else None, total=total, progress=bars,
            )
        finally:
            if bars is not None:
                bars.close()
        self.cache_plan_ = [(layer, bool(kept), int(size)) for layer, kept, size in plan]
        self._net = net
        self._period = period
        self._step = rotation.step
        self.input_scale_ = _pixel_scale(first)
        self.transition_weight_ = transition_weight
        self.n_pairs_ = 0 if pairs is None else len(pairs[0])
        self.n_loop_closures_ = 0 if closures is None or partners is not None else len(closures[0])
        self.n_partners_ = 0 if partners is None else len(closures[0])
        return self

    def partial_fit(self, images: Any, policy: Any = None) -> "Network":
        """Adds one run (N, H, W[, C]: the training panoramas' size, channels
        and pixel scale) to this fitted network without retraining it: the
        run's statistics join the stored ones as a recording of its own and
        the stages the policy names are solved again (default: the top
        layer's final stage, exact; :mod:`sfanav.sfa.updates`). Needs the
        training statistics (a network fitted in this process, or loaded
        from a file saved with ``include_statistics=True``). Returns
        ``self``; ValueError for a run that does not match (``self`` is
        then unchanged).

        Examples
        --------
        >>> net.fit(week1, rotation).partial_fit(week2)   # doctest: +SKIP
        """
        from .updates import NetworkUpdater

        new = NetworkUpdater(self, policy).partial_fit(images).solve()
        self._net = new._net
        return self

    def _check_scale(self, a: np.ndarray) -> None:
        """Warns when the pixel values are on another scale than in training
        (0..255 against 0..1, say): the features would change silently."""
        train = getattr(self, "input_scale_", None)
        if not train or a.size == 0:
            return
        now = _pixel_scale(a)
        if now > 0 and max(now / train, train / now) > SCALE_WARNING_RATIO:
            warnings.warn(
                f"these images hold values up to {now:.3g}, but the network was trained on values up to "
                f"{train:.3g} ({a.dtype} now): scale them as in training, or the features are not comparable",
                UserWarning, stacklevel=3)

    def _check_images(self, a: np.ndarray, period: int | None, training: bool = False) -> None:
        h, v, c = self.input_shape
        ac = 1 if a.ndim == 3 else a.shape[3]
        if a.shape[1] != h or ac != c:
            raise ValueError(
                f"images are {a.shape[2]}x{a.shape[1]} with {ac} channel(s); this network takes "
                f"{h} px high images with {c} channel(s)"
            )
        if period is not None and a.shape[2] != period:
            raise ValueError(f"all images must be {period} px wide, got {a.shape[2]}")
        if training and a.shape[2] < v:
            raise ValueError(f"panoramas of {a.shape[2]} px are narrower than the network input ({v} px)")

    # ------------------------------------------------------------ inference
    def transform(self, images: Any, *, rotations: bool = False, step: int | None = None) -> np.ndarray:
        """Slow features of images (N, H, W[, C]) or one image (H, W[, C]).

        Returns (N, n_outputs); with ``rotations=True``, (N, K, n_outputs)
        under every simulated rotation by ``step`` px (default: the training
        step), K = ceil(W / step). Images wider than the network's input are
        seen through the window at rotation 0 (their first columns).
        ValueError for a ``step`` that is not a positive integer.
        """
        self._check_trained()
        a = np.asarray(images)
        # One image is (H, W) for a gray network and (H, W, 3) for RGB.
        single = is_single_image(a, self.input_shape[2])
        if single:
            a = a[None]
        a = as_image_batch(a)
        self._check_images(a, None)
        self._check_scale(a)
        if rotations:
            s = getattr(self, "_step", 5) if step is None else step
            if isinstance(s, (bool, np.bool_)) or not isinstance(s, (int, np.integer)) or s < 1:
                raise ValueError(f"step must be a positive whole number of pixels, got {step!r}")
            out = self._net.transform_rotations(a, int(s))
        else:
            v = self.input_shape[1]
            if a.shape[2] < v:
                raise ValueError(f"images of {a.shape[2]} px are narrower than the network input ({v} px)")
            if a.shape[2] > v:
                a = np.ascontiguousarray(a[:, :, :v])
            out = self._net.transform(a)
        return out[0] if single else out

    # ------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike, *, include_statistics: bool = False) -> None:
        """Saves the network (config and trained nodes; pickle-free)."""
        save_model(path, "Network", self._state(include_statistics))

    def to_bytes(self, *, include_statistics: bool = False) -> bytes:
        """The network as the bytes of its model file (config, trained
        nodes and, with ``include_statistics``, their training statistics;
        checksummed, no pickle): for shipping it between processes.

        Examples
        --------
        >>> net = Network.from_preset("thesis-5.1")
        >>> Network.from_bytes(net.to_bytes()).input_shape
        (40, 350, 3)
        """
        return dumps("Network", self._state(include_statistics))

    @classmethod
    def from_bytes(cls, data: bytes) -> "Network":
        """A network from :meth:`to_bytes`. Raises ValueError for bytes that
        are not an unaltered network, TypeError for another type."""
        return cls.from_state(state_from_bytes(data, "Network"))

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        # pickle (e.g. Dask shipping a fitted network to workers) goes through the checked bytes
        return (Network.from_bytes, (self.to_bytes(include_statistics=True),))

    def _state(self, include_statistics: bool) -> dict[str, Any]:
        return {
            "config": self.config,
            "spec": spec_to_json(self.config_),
            "trained": self._net.n_trained,
            "step": getattr(self, "_step", None),
            "period": getattr(self, "_period", None),
            "transition_weight": getattr(self, "transition_weight_", None),
            "input_scale": getattr(self, "input_scale_", None),
            "nodes": self._net.node_states(include_statistics),
        }

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "Network":
        try:
            if not isinstance(state["config"], dict):
                # never a path or a preset name: a model file must not make sfanav read other files
                raise ValueError(f"invalid Network model state: the config must be a table, "
                                 f"got {type(state['config']).__name__}")
            obj = cls(state["config"])
            if spec_to_json(obj.config_) != state["spec"]:
                raise ValueError("invalid Network model state: config and spec disagree")
            trained = check_int(state["trained"], "trained", minimum=0)
            obj._net = _core.Network.from_states(obj.config_, state["nodes"], trained)
            if state.get("step") is not None:
                obj._step = check_int(state["step"], "step")
                obj._period = check_int(state["period"], "period")
                obj.transition_weight_ = check_positive_float(state.get("transition_weight") or 1.0,
                                                              "transition_weight")
            if state.get("input_scale") is not None:  # absent in files written before it was stored
                obj.input_scale_ = check_nonneg_float(state["input_scale"], "input_scale")
        except (KeyError, TypeError) as exc:
            raise ValueError(f"invalid Network model state: {exc}") from None
        return obj


SCALE_WARNING_RATIO = 50.0  # pixel scales this far apart (255 against 1) draw a warning


def _pixel_scale(a: np.ndarray) -> float:
    """The largest absolute pixel value of a batch."""
    return float(max(a.max(), -float(a.min()))) if a.size else 0.0  # no |a| copy of the batch


register_loader("Network", Network.from_state)
