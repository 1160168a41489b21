"""Partitioned (distributed) training of a :class:`~sfanav.Network`.

The training images are split into *partitions* (a list of arrays or
``.npy`` files, one array or ``.npy`` file cut into pieces, a
:class:`~sfanav.data.Dataset`'s frames, or a Dask array chunked along the
frames). For every layer and pass:

1. the driver ships the network (its checked model-file bytes, with the
   statistics of the stage in training only) to the workers;
2. each partition, on a worker, streams its images through the solved
   lower layers and accumulates the statistics of the stage in training
   (``_core.LayerTrainer``, ``sfa_core::LayerTrainer::resume``);
3. the partitions' statistics are merged pairwise in a tree
   (``Statistics.merge``: exact sums);
4. the driver adds the merged statistics to its network and solves the
   stage (``LayerTrainer.merge_statistics`` / ``end_pass``).

Exactness: a partition that continues the previous partition's sequence
is *primed* with the image before it, so the derivative pairs between
that image and its own first image are counted once, by this partition;
every partition gets the lag-product reference of the run's first image.
The result equals :meth:`Network.fit` up to rounding (1e-9 relative on the
node weights in the tests; the summation order differs). Frames listed in
``breaks`` start a new recording: no pair joins them to the frame before.

Faults: each partition task returns its own statistics and nothing is
accumulated in place, so Dask may rerun a task whose worker died; only
completed partitions are merged, each once.

Loop closures go to the partition holding their current image, with the
partner images gathered by the driver; spatial pairs run as extra *pair
tasks* (:mod:`sfanav.sfa.distributed_feedback`).

``client=None`` runs the same steps in this process, one partition after
another (no Dask needed). Dask is imported only when a client or a Dask
array is given (``pip install "sfanav[dask]"``). Not supported: the field
cache (every pass recomputes the lower layers of its partition). See
``docs/distributed.md``.
"""

from __future__ import annotations

import itertools
import os
import time
import uuid
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import _core
from .._checks import as_image_batch, check_int, check_nonneg_float
from .._progress import progress_bar
from .distributed_feedback import (
    PairTask,
    PartitionClosures,
    closures_by_partition,
    pair_statistics,
    pair_tasks,
    partners_by_partition,
)
from .modelfile import dumps

__all__ = ["Partition", "fit", "partitions_of"]


@dataclass(frozen=True)
class Partition:
    """One partition of the training images.

    ``source`` is an array (N, H, W[, C]), an ``.npy`` path (memory-mapped
    on the worker), a ``(Dataset, gray, size)`` triple, or None for a block
    of a Dask array (handed to the task by Dask); ``lo:hi`` are the frames
    of the source it holds; ``start`` the index of its first frame in the
    whole run. ``continues``: whether its first frame continues the
    sequence of the frame before it (the previous partition's last);
    ``breaks``: frames (counted within the partition, > 0) that start a
    new recording."""

    index: int
    start: int
    n: int
    source: Any
    lo: int = 0
    continues: bool = False
    breaks: tuple[int, ...] = ()
    prev: Any = field(default=None, repr=False)  # (source, lo) of the frame before, when it continues

    def describe(self) -> str:
        return f"partition {self.index} (frames {self.start}..{self.start + self.n - 1} of the run)"


@dataclass(frozen=True)
class _Job:
    """What every partition task of one pass needs besides its data."""

    layer: int
    pass_: int
    step: int
    period: int
    fast: bool
    transition_weight: float
    batch_size: int
    first_image: np.ndarray  # (1, H, W[, C]): the run's first image, the lag-product reference


def _is_dask_array(x: Any) -> bool:
    return type(x).__module__.startswith("dask.array") and hasattr(x, "chunks") and hasattr(x, "to_delayed")


def _is_dataset(x: Any) -> bool:
    from ..data.dataset import Dataset

    return isinstance(x, Dataset)


def _open(source: Any) -> Any:
    """An indexable array of frames for a partition's source (memory-mapped
    for ``.npy`` paths)."""
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if path.suffix != ".npy":
            raise ValueError(f"{path}: give .npy arrays of images (N, H, W[, C])")
        return np.load(path, mmap_mode="r", allow_pickle=False)
    return source


def _read(source: Any, lo: int, hi: int) -> np.ndarray:
    """Frames ``lo:hi`` of a source as a batch."""
    if isinstance(source, tuple) and len(source) == 3 and _is_dataset(source[0]):
        ds, gray, size = source
        return np.stack(list(ds.images(gray=gray, size=size, indices=np.arange(lo, hi))))
    return as_image_batch(_open(source)[lo:hi])


def _is_in_memory(source: Any) -> bool:
    return isinstance(source, np.ndarray) and not isinstance(source, np.memmap)


def _read_at(source: Any, frames: list[int]) -> np.ndarray:
    """Frames ``frames`` (in that order) of a source as a batch."""
    if isinstance(source, tuple) and len(source) == 3 and _is_dataset(source[0]):
        ds, gray, size = source
        return np.stack(list(ds.images(gray=gray, size=size, indices=np.asarray(frames))))
    return as_image_batch(_open(source)[np.asarray(frames, dtype=np.int64)])


def _read_frames(reads: Sequence[tuple[Any, int]]) -> np.ndarray:
    """The frames ``(source, frame)`` of ``reads`` as one batch, in order
    (each source read once)."""
    groups: dict[Any, tuple[Any, list[int], list[int]]] = {}
    for k, (src, f) in enumerate(reads):
        key = str(src) if isinstance(src, (str, os.PathLike)) else id(src)
        g = groups.setdefault(key, (src, [], []))
        g[1].append(k)
        g[2].append(int(f))
    batches = [(pos, _read_at(src, frames)) for src, pos, frames in groups.values()]
    first = batches[0][1]
    out = np.empty((len(reads),) + first.shape[1:], np.result_type(*(b.dtype for _, b in batches)))
    for pos, b in batches:
        out[pos] = b
    return out


def _locate(parts: list[Partition], frames: Any) -> list[tuple[Any, int]]:
    """``(source, frame of the source)`` of frames of the run."""
    starts = np.array([p.start for p in parts], dtype=np.int64)
    owner = np.searchsorted(starts, np.asarray(frames, dtype=np.int64), side="right") - 1
    return [(parts[o].source, parts[o].lo + int(f) - parts[o].start) for o, f in zip(owner.tolist(), frames)]


def _gather(images: Any, parts: list[Partition], frames: Any) -> np.ndarray:
    """Frames of the run (K, H, W[, C]), read on the driver."""
    frames = np.asarray(frames, dtype=np.int64)
    if _is_dask_array(images):
        uniq, inv = np.unique(frames, return_inverse=True)
        return as_image_batch(np.asarray(images[uniq.tolist()].compute()))[inv]
    return _read_frames(_locate(parts, frames))


def _length(source: Any) -> int:
    arr = _open(source)
    if not hasattr(arr, "shape") or len(arr.shape) not in (3, 4):
        raise ValueError(f"a partition must be an array (N, H, W[, C]) or an .npy path, got "
                         f"{getattr(arr, 'shape', type(arr).__name__)}")
    return int(arr.shape[0])


def _split(n: int, k: int) -> list[tuple[int, int]]:
    """``k`` contiguous ranges covering ``0:n`` (sizes differ by at most 1)."""
    k = max(1, min(k, n))
    edges = [round(i * n / k) for i in range(k + 1)]
    return [(edges[i], edges[i + 1]) for i in range(k) if edges[i + 1] > edges[i]]


def partitions_of(images: Any, *, n_partitions: int | None = None, breaks: Any = None,
                  gray: bool = False, size: tuple[int, int] | None = None) -> list[Partition]:
    """The partitions of ``images`` (see :func:`fit`) with their sequence
    links. ``breaks``: frame indices of the whole run that start a new
    recording, or ``"partitions"`` (every partition its own recording); a
    Dataset also breaks wherever its ``run`` column changes."""
    ranges: list[tuple[Any, int, int]] = []  # (source, lo, hi), in run order
    if _is_dask_array(images):
        if images.ndim not in (3, 4):
            raise ValueError(f"images must have shape (N, H, W) or (N, H, W, C), got {images.shape}")
        lo = 0
        for c in images.chunks[0]:
            ranges.append((None, lo, lo + c))
            lo += c
    elif _is_dataset(images):
        run_breaks = [i for i in range(1, len(images)) if images.runs[i] != images.runs[i - 1]]
        extra = [] if breaks is None or isinstance(breaks, str) else list(breaks)
        breaks = breaks if isinstance(breaks, str) else sorted(set(run_breaks) | {int(b) for b in extra})
        src = (images, bool(gray), size)
        ranges = [(src, a, b) for a, b in _split(len(images), n_partitions or 1)]
    elif isinstance(images, (np.ndarray, str, os.PathLike)):
        n = _length(images)
        ranges = [(images, a, b) for a, b in _split(n, n_partitions or 1)]
    elif isinstance(images, (list, tuple)):
        if n_partitions is not None:
            raise ValueError("n_partitions splits one array, .npy file or Dataset; a list is already partitioned")
        for i, src in enumerate(images):
            if not isinstance(src, (np.ndarray, str, os.PathLike)):
                raise TypeError(f"partition {i}: give an array (N, H, W[, C]) or an .npy path, "
                                f"got {type(src).__name__}")
            ranges.append((src, 0, _length(src)))
    else:
        raise TypeError("distributed training reads a list of arrays or .npy paths, one array or .npy path, "
                        f"a Dataset or a Dask array, not {type(images).__name__}")
    ranges = [r for r in ranges if r[2] > r[1]]
    if not ranges:
        raise ValueError("no training images")
    total = sum(hi - lo for _, lo, hi in ranges)
    starts = np.cumsum([0] + [hi - lo for _, lo, hi in ranges[:-1]]).tolist()
    if isinstance(breaks, str):
        if breaks != "partitions":
            raise ValueError(f'breaks must be frame indices or "partitions", got {breaks!r}')
        bset = set(starts)
    else:
        bset = set()
        for b in [] if breaks is None else list(breaks):
            b = check_int(b, "a break", minimum=0)
            if b >= total:
                raise ValueError(f"break {b} is beyond the {total} training images")
            bset.add(b)
    parts = []
    for i, ((src, lo, hi), start) in enumerate(zip(ranges, starts)):
        n = hi - lo
        cont = i > 0 and start not in bset
        prev = None
        if cont:
            psrc, _, phi = ranges[i - 1]
            prev = (psrc, phi - 1)
        local = tuple(sorted(b - start for b in bset if start < b < start + n))
        parts.append(Partition(i, int(start), n, src, lo, cont, local, prev))
    return parts


# ------------------------------------------------------------------ worker side


def _network_from_bytes(data: bytes) -> Any:
    from .network import Network

    return Network.from_bytes(data)


def _check_batch(batch: np.ndarray, part: Partition, offset: int, job: _Job, hw: tuple[int, int, int]) -> None:
    """Shape and finiteness of a partition's batch, with errors naming the
    partition and frame."""
    h, _, c = hw
    bc = 1 if batch.ndim == 3 else batch.shape[3]
    if batch.shape[1] != h or bc != c or batch.shape[2] != job.period:
        raise ValueError(f"{part.describe()}: images are {batch.shape[2]}x{batch.shape[1]} with {bc} channel(s), "
                         f"the run's are {job.period}x{h} with {c}")
    if batch.dtype.kind == "f":
        bad = ~np.isfinite(batch.reshape(len(batch), -1)).all(axis=1)
        if bad.any():
            k = offset + int(np.argmax(bad))
            raise ValueError(f"{part.describe()}: frame {k} of the partition (frame {part.start + k} of the run) "
                             "contains NaN or infinity")


def _partition_statistics(net_bytes: bytes, job: _Job, part: Partition, data: Any = None,
                          prev: Any = None, closures: PartitionClosures | None = None) -> tuple[list[Any], int]:
    """One partition's statistics of the layer and pass in training: a list
    (one per node) of :class:`~sfanav.sfa.node.Statistics` and the number
    of images. ``data``: the partition's frames when Dask hands them over
    (a Dask array block, or an in-memory partition held on the cluster);
    ``prev``: the frame before the partition (1, H, W[, C]) when the
    partition continues the sequence (else read from ``part.prev``);
    ``closures``: the loop closures of the partition's images."""
    from .node import Statistics

    net = _network_from_bytes(net_bytes)
    core = net._net
    hw = net.input_shape
    tr = _core.LayerTrainer(core, job.layer, job.pass_, job.step, job.period, fast=job.fast,
                            transition_weight=job.transition_weight)
    tr.set_reference_image(core, job.first_image)
    try:
        if closures is not None:
            if closures.current[-1] >= part.n:
                raise ValueError(f"a loop closure names frame {closures.current[-1]} of the partition, which has "
                                 f"{part.n}")
            tr.set_loop_closures(core, list(closures.current), list(closures.weights), closures.partners)
        if part.continues:
            if prev is None:
                psrc, pi = part.prev
                prev = _read(psrc, pi, pi + 1)
            prev = as_image_batch(prev)
            try:
                _check_batch(prev, part, 0, job, hw)
            except ValueError as exc:
                raise ValueError(f"the frame before {part.describe()} is bad: {exc}") from None
            tr.prime(core, prev)
        frames = as_image_batch(data) if data is not None else None
        if frames is not None and len(frames) != part.n:
            raise ValueError(f"{part.describe()}: {len(frames)} frames, expected {part.n}")
        cuts = sorted({0, part.n, *range(0, part.n, job.batch_size), *part.breaks})
        for a, b in itertools.pairwise(cuts):
            batch = frames[a:b] if frames is not None else _read(part.source, part.lo + a, part.lo + b)
            _check_batch(batch, part, a, job, hw)
            if a in part.breaks:
                tr.break_sequence()
            tr.feed(core, batch)
        stats = tr.statistics(core)
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        if "partition" not in msg:
            msg = f"{part.describe()}: {msg}"
        raise type(exc)(msg) from exc
    return [Statistics.from_core(s) for s in stats], int(tr.images_seen)


def _pair_statistics(net_bytes: bytes, job: _Job, task: PairTask, data: Any = None,
                     reads: Sequence[tuple[Any, int]] | None = None) -> tuple[list[Any], int]:
    """A pair task's statistics (and 0 images). ``data``: the task's frames
    (``task.ids``) when the driver or Dask hands them over; else they are
    read from ``reads`` (``(source, frame)`` per frame)."""
    if data is None:
        if reads is None:
            raise ValueError(f"{task.describe()}: no frames given")
        try:
            data = _read_frames(reads)
        except (ValueError, TypeError, OSError) as exc:
            raise type(exc)(f"{task.describe()}: {exc}") from exc
    return pair_statistics(_network_from_bytes(net_bytes), job, task, as_image_batch(data))


def _merge(a: tuple[list[Any], int], b: tuple[list[Any], int]) -> tuple[list[Any], int]:
    """Two partial results merged (new objects: inputs are not modified, so
    a rerun task never sees its input merged twice)."""
    out = []
    for x, y in zip(a[0], b[0]):
        m = x.copy()
        m.merge(y)
        out.append(m)
    return out, a[1] + b[1]


def _tree(items: list[Any], merge: Any) -> Any:
    while len(items) > 1:
        items = [merge(items[i], items[i + 1]) if i + 1 < len(items) else items[i] for i in range(0, len(items), 2)]
    return items[0]


# ------------------------------------------------------------------ driver


def _pass_bytes(net: Any, layer: int, pass_: int) -> bytes:
    """The network as the tasks of a pass need it: its checked model-file
    bytes with the training statistics of the stage in training only (the
    trained layers and the solved stages travel without theirs)."""
    state = net._state(include_statistics=True)
    for i, nodes in enumerate(state["nodes"]):
        for node in nodes:
            for k, stage in enumerate(node["stages"]):
                if (i, k) != (layer, pass_):
                    stage["stats"] = None
    return dumps("Network", state)


def _first_frames(images: Any, parts: list[Partition], k: int) -> np.ndarray:
    """The run's first ``k`` frames (at most the first partition's)."""
    p = parts[0]
    k = min(k, p.n)
    if _is_dask_array(images):
        return as_image_batch(np.asarray(images[:k].compute()))
    return _read(p.source, p.lo, p.lo + k)


PAIR_TASK_IMAGES = 128
"""Default bound on the distinct images of one pair task."""


def fit(network: Any, images: Any, rotation: Any = None, *, client: Any = None, n_partitions: int | None = None,
        breaks: Any = None, fast: bool = True, transition_weight: float = 1.0, batch_size: int = 16,
        progress: bool = False, gray: bool = False, size: tuple[int, int] | None = None,
        loop_closures: Any = None, closure_weights: Any = None, pairs: Any = None, pair_layers: Any = None,
        pair_task_images: int = PAIR_TASK_IMAGES, partners: Any = None,
        on_pass: Callable[[dict[str, Any]], None] | None = None) -> Any:
    """Trains ``network`` (every layer, from scratch) on partitioned images,
    on a Dask cluster (``client``) or in this process (``client=None``).

    Parameters
    ----------
    network : sfanav.Network
    images : list of arrays / ``.npy`` paths (one partition each), one
        array or ``.npy`` path (cut into ``n_partitions``), a Dataset (cut
        into ``n_partitions``; read with ``gray`` and ``size``), or a Dask
        array (one partition per chunk along the frames). The order of the
        partitions is the order of the run.
    rotation : Rotation, default ``Rotation()``
    client : dask.distributed.Client or None
    n_partitions : int, optional
        Pieces of one array, file or Dataset (default: the client's
        workers, or 1).
    breaks : frame indices (of the whole run) that start a new recording,
        or ``"partitions"``. Default: one sequence (a Dataset breaks where
        its ``run`` changes).
    fast, transition_weight, batch_size : as in :meth:`Network.fit`
    loop_closures, closure_weights : as in :meth:`Network.fit`, with frame
        indices of the whole run. Each closure is trained by the partition
        holding its current image; the driver reads the partner images.
    partners : explicit interleaving partners ``(current, weights, images)``
        of frames of the whole run, as in :meth:`Network.fit` (the
        invariance training of :func:`sfanav.localization.fit_localizer`);
        each goes to the partition holding its current frame. Not with
        ``loop_closures``.
    pairs, pair_layers : spatial pairs ``(idx_a, idx_b, weights[, shifts])``
        of frames of the whole run and the (1-based) layers that take them,
        as in :meth:`Network.fit`; trained by pair tasks of at most
        ``pair_task_images`` distinct images each (read by the workers from
        ``.npy`` paths and Datasets; else gathered once per fit and held on
        the cluster).
    progress : bool
        A bar per pass counting the tasks done.
    on_pass : callable, optional
        Called after every pass with a dict: ``layer``, ``pass`` (0-based),
        ``partitions``, ``pair_tasks`` (run in this pass), ``images``,
        ``network_bytes`` (the network shipped to the workers),
        ``statistics_bytes`` (the statistics one task returns),
        ``map_seconds`` (the tasks and the merge tree), ``solve_seconds``
        (the driver's merge into the network and solve) and
        ``serialize_seconds`` (the network to bytes).

    Returns ``network``, fitted. The result equals ``network.fit(all images,
    ...)`` with the same closures and pairs and ``cache=False`` up to
    rounding (with breaks: the same run with each recording starting a new
    sequence). Errors in a partition name it and the frame; a bad partner
    image or pair image names its frame of the run and its partition.
    """
    from .network import Network, Rotation

    if not isinstance(network, Network):
        raise TypeError(f"network must be a sfanav.Network, got {type(network).__name__}")
    rotation = rotation or Rotation()
    if not isinstance(rotation, Rotation):
        raise TypeError("rotation must be a sfanav.Rotation")
    transition_weight = check_nonneg_float(transition_weight, "transition_weight")
    batch_size = check_int(batch_size, "batch_size")
    pair_task_images = check_int(pair_task_images, "pair_task_images", minimum=2)
    if loop_closures is None and closure_weights is not None:
        raise ValueError("closure_weights needs loop_closures")
    if partners is not None and loop_closures is not None:
        raise ValueError("partners cannot be combined with loop_closures: give the loop closures' partners among them")
    if pairs is None and pair_layers is not None:
        raise ValueError("pair_layers needs pairs")
    if client is not None:
        _check_client(client)
    if n_partitions is not None:
        n_partitions = check_int(n_partitions, "n_partitions")
    elif client is not None and (isinstance(images, (np.ndarray, str, os.PathLike)) or _is_dataset(images)):
        n_partitions = max(1, len(client.scheduler_info().get("workers", {})))
    dask_array = _is_dask_array(images)
    if dask_array:
        if client is None:
            raise ValueError("a Dask array needs a client (or compute it and pass the array)")
        images = images.rechunk({i: -1 for i in range(1, images.ndim)})
    parts = partitions_of(images, n_partitions=n_partitions, breaks=breaks, gray=gray, size=size)
    n_total = sum(p.n for p in parts)
    first = _first_frames(images, parts, batch_size)
    period = first.shape[2]
    network._check_images(first, period, training=True)
    v = network.input_shape[1]
    if round(rotation.window * period) != v:
        raise ValueError(
            f"the network's input is {v} px wide, but a {rotation.window:.0%} window of "
            f"{period}-px panoramas is {round(rotation.window * period)} px: build the network for that width"
        )
    n_layers = len(network.config_["layers"])
    tasks: list[PairTask] = []
    pair_at: set[int] = set()
    n_pairs = 0
    if pairs is not None:
        wanted = {int(x) for x in (range(1, n_layers + 1) if pair_layers is None else pair_layers)}
        if not wanted <= set(range(1, n_layers + 1)):
            raise ValueError(f"pair_layers must name layers 1..{n_layers}, got {sorted(wanted)}")
        pair_at = {x - 1 for x in wanted}
        tasks = pair_tasks(pairs, n_total, parts, period, pair_task_images)
        n_pairs = len(np.asarray(pairs[0]))
    closures: list[PartitionClosures | None] = [None] * len(parts)
    if loop_closures is not None:
        closures = closures_by_partition(loop_closures, closure_weights, parts, n_total,
                                         lambda f: _gather(images, parts, f), network.input_shape, period)
    if partners is not None:
        closures = partners_by_partition(partners, parts, n_total, first, network.input_shape, period)
    net = Network(network.config)
    runner: Any = (_DaskRunner(client, images if dask_array else None, parts, closures, tasks) if client is not None
                   else _LocalRunner(parts, closures, tasks))
    try:
        for layer in range(n_layers):
            pass_ = 0
            while True:
                job = _Job(layer, pass_, rotation.step, period, bool(fast), transition_weight, batch_size,
                           np.ascontiguousarray(first[:1]))
                t0 = time.perf_counter()
                net_bytes = _pass_bytes(net, layer, pass_)
                t1 = time.perf_counter()
                with_pairs = layer in pair_at
                n_tasks = len(parts) + (len(tasks) if with_pairs else 0)
                bar = progress_bar(progress, n_tasks, f"layer {layer + 1}/{n_layers} pass {pass_ + 1}", unit="task")
                try:
                    stats, n = runner.run(net_bytes, job, bar, with_pairs)
                finally:
                    if bar is not None:
                        bar.close()
                t2 = time.perf_counter()
                tr = _core.LayerTrainer(net._net, layer, pass_, rotation.step, period, fast=bool(fast),
                                        transition_weight=transition_weight)
                tr.merge_statistics(net._net, [s._acc for s in stats], n)
                done = tr.end_pass(net._net)
                if on_pass is not None:
                    on_pass({"layer": layer, "pass": pass_, "partitions": len(parts),
                             "pair_tasks": n_tasks - len(parts), "images": n, "network_bytes": len(net_bytes),
                             "statistics_bytes": sum(len(s.to_bytes()) for s in stats), "map_seconds": t2 - t1,
                             "solve_seconds": time.perf_counter() - t2, "serialize_seconds": t1 - t0})
                if done:
                    break
                pass_ += 1
    finally:
        runner.close()
    network._net = net._net
    network._period = period
    network._step = rotation.step
    network.cache_plan_ = []
    network.input_scale_ = float(max(first.max(), -float(first.min())))  # as Network.fit: the first batch's
    network.transition_weight_ = transition_weight
    network.n_pairs_ = n_pairs
    n_interleaved = sum(len(c) for c in closures if c is not None)
    network.n_loop_closures_ = 0 if partners is not None else n_interleaved
    network.n_partners_ = n_interleaved if partners is not None else 0
    network.n_partitions_ = len(parts)
    return network


class _LocalRunner:
    """Runs the tasks of a pass in this process, one after another."""

    def __init__(self, parts: list[Partition], closures: list[PartitionClosures | None],
                 tasks: list[PairTask]) -> None:
        self.parts, self.closures, self.tasks = parts, closures, tasks
        self.reads = [_locate(parts, t.ids) for t in tasks]

    def run(self, net_bytes: bytes, job: _Job, bar: Any, with_pairs: bool) -> tuple[list[Any], int]:
        results = []
        for p, c in zip(self.parts, self.closures):
            results.append(_partition_statistics(net_bytes, job, p, closures=c))
            if bar is not None:
                bar.update(1)
        for t, r in zip(self.tasks, self.reads) if with_pairs else ():
            results.append(_pair_statistics(net_bytes, job, t, reads=r))
            if bar is not None:
                bar.update(1)
        return _tree(results, _merge)

    def close(self) -> None:
        pass


def _identity(x: Any) -> Any:
    return x


MALLOC_WARNING = (
    "the Dask workers run with MALLOC_TRIM_THRESHOLD_={value} (the Dask nanny's default), which makes sfanav's "
    "training about 2x slower on Linux (glibc then maps and unmaps every large buffer anew); start the workers "
    "with the dask config distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_ set to None "
    "(docs/distributed.md)")


def _worker_malloc_setting() -> tuple[str, str | None]:
    """A worker's platform and MALLOC_TRIM_THRESHOLD_ (run on the workers)."""
    import sys

    return sys.platform, os.environ.get("MALLOC_TRIM_THRESHOLD_")


def _warn_about_malloc(client: Any) -> None:
    """Warns when Linux workers run with MALLOC_TRIM_THRESHOLD_ set: glibc
    then keeps its mmap threshold fixed, and the core's large temporary
    buffers cost page faults on every allocation."""
    values = sorted({v for plat, v in client.run(_worker_malloc_setting).values()
                     if plat.startswith("linux") and v is not None})
    if values:
        warnings.warn(MALLOC_WARNING.format(value=", ".join(values)), UserWarning, stacklevel=4)


def _readable(source: Any) -> bool:
    """Whether workers read ``source`` themselves (a path or a Dataset)."""
    return isinstance(source, (str, os.PathLike)) or (isinstance(source, tuple) and len(source) == 3
                                                      and _is_dataset(source[0]))


def _check_client(client: Any) -> None:
    try:
        from distributed import Client
    except ImportError as exc:  # pragma: no cover - exercised without dask
        raise ImportError('distributed training needs Dask: pip install "sfanav[dask]"') from exc
    if not isinstance(client, Client):
        raise TypeError(f"client must be a dask.distributed.Client, got {type(client).__name__}")


class _DaskRunner:
    """Runs the tasks of a pass on a Dask cluster and merges their results
    in a tree on the workers."""

    def __init__(self, client: Any, array: Any, parts: list[Partition], closures: list[PartitionClosures | None],
                 tasks: list[PairTask]) -> None:
        _check_client(client)
        _warn_about_malloc(client)
        self.client = client
        self.parts = parts
        self.tasks = tasks
        self.token = uuid.uuid4().hex[:8]
        self.inputs = self._inputs(array, closures)
        self.pair_inputs = self._pair_inputs(array)

    def _hold(self, obj: Any, name: str) -> Any:
        """A future of ``obj`` kept on the cluster for the whole fit. The
        object is part of the task's spec, so Dask recomputes it if the
        worker holding it dies (a scattered object would be lost)."""
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*[Ll]arge graph")
            return self.client.submit(_identity, obj, key=f"sfanav-input-{self.token}-{name}", pure=False)

    def _inputs(self, array: Any, closures: list[PartitionClosures | None]) -> list[tuple[Any, ...]]:
        """Per partition: (partition as the task sees it, data, prev,
        closures). For a Dask array, futures of its blocks and of the frames
        before them, computed once for the whole fit (Dask recomputes them
        from the array's graph if a worker holding them dies; submitting
        the same keys again in every pass races with their release); for an
        in-memory array, its frames held on the cluster once for the fit;
        else (None, None): the task reads its source."""
        held = [None if c is None else self._hold(c, f"closures-{p.index}") for p, c in zip(self.parts, closures)]
        if array is not None:
            blocks = array.to_delayed().ravel().tolist()
            data = self.client.compute(blocks)
            out = []
            for p, d, c in zip(self.parts, data, held):
                prev = self.client.compute(array[p.start - 1 : p.start]) if p.continues else None
                out.append((p, d, prev, c))
            return out
        out = []
        for p, c in zip(self.parts, held):
            d = q = None
            task_part = p
            if _is_in_memory(p.source):
                d = self._hold(p.source[p.lo : p.lo + p.n], f"part-{p.index}")
                task_part = replace(p, source=None)
            if p.continues and _is_in_memory(p.prev[0]):
                psrc, pi = p.prev
                q = self._hold(np.ascontiguousarray(psrc[pi : pi + 1]), f"prev-{p.index}")
                task_part = replace(task_part, prev=None)
            out.append((task_part, d, q, c))
        return out

    def _pair_inputs(self, array: Any) -> list[tuple[Any, Any]]:
        """Per pair task: (data, reads). Workers read ``.npy`` paths and
        Datasets themselves; frames of a Dask array are computed once for
        the fit, frames of in-memory arrays gathered here once and held on
        the cluster."""
        out = []
        for t in self.tasks:
            if array is not None:
                out.append((self.client.compute(array[list(t.ids)]), None))
                continue
            reads = _locate(self.parts, t.ids)
            if all(_readable(src) for src, _ in reads):
                out.append((None, reads))
            else:
                out.append((self._hold(_read_frames(reads), f"pairs-{t.index}"), None))
        return out

    def run(self, net_bytes: bytes, job: _Job, bar: Any, with_pairs: bool) -> tuple[list[Any], int]:
        from distributed import as_completed

        c = self.client
        tag = f"{self.token}-l{job.layer}p{job.pass_}"
        # held like the inputs (a scatter to a worker that died since the last pass would fail); the workers
        # fetch them from each other
        net_f, job_f = self._hold(net_bytes, f"network-{tag}"), self._hold(job, f"job-{tag}")
        futures = [
            c.submit(_partition_statistics, net_f, job_f, p, d, q, cl, key=f"sfanav-partition-{tag}-{p.index}",
                     pure=False)
            for p, d, q, cl in self.inputs
        ]
        if with_pairs:
            futures += [
                c.submit(_pair_statistics, net_f, job_f, t, d, r, key=f"sfanav-pairs-{tag}-{t.index}", pure=False)
                for t, (d, r) in zip(self.tasks, self.pair_inputs)
            ]
        level, depth = futures, 0
        while len(level) > 1:
            nxt = []
            for i in range(0, len(level), 2):
                if i + 1 < len(level):
                    nxt.append(c.submit(_merge, level[i], level[i + 1], key=f"sfanav-merge-{tag}-{depth}-{i}",
                                        pure=False))
                else:
                    nxt.append(level[i])
            level, depth = nxt, depth + 1
        if bar is not None:
            for _ in as_completed(futures):
                bar.update(1)
        try:
            return level[0].result()
        finally:
            del futures, level, net_f, job_f  # released, not cancelled (a rerun task may still need them)

    def close(self) -> None:
        self.inputs = []
        self.pair_inputs = []
