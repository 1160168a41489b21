"""Loop closures and spatial pairs in partitioned (distributed) training.

Both add statistics that involve a second image besides the sequence of
the run, and both are split so that the partitions' statistics still sum
to those of one process (:meth:`sfanav.Network.fit`):

* **Loop closures** (thesis 6.2.1). A closure belongs to the partition
  holding its *current* image: that partition's trainer interleaves the
  image's simulated rotation with the aligned partner's, exactly as the
  single-process trainer does. The driver gathers the partner images
  (arbitrary earlier frames of the run, possibly in other partitions),
  turns them to the current orientation, and gives every partition only
  its own closures, indexed within the partition
  (:func:`closures_by_partition`).
* **Spatial pairs** (graph-based SFA) join arbitrary images and add no
  samples and no sequence, so they need no partition: they are cut into
  *pair tasks* of consecutive pairs (sorted by their first image, as the
  core does) holding a bounded number of distinct images
  (:func:`pair_tasks`). A pair task starts its own trainer on the network
  of the pass, feeds its pairs a chunk at a time
  (``LayerTrainer.feed_pairs``) and returns its statistics, which are
  merged with the partitions'.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _core
from ..loopclosure.partners import aligned_partners, check_closures
from .feedback import check_partners
from .pairs import check_pairs

__all__ = ["PairTask", "PartitionClosures", "check_frames", "closures_by_partition", "pair_statistics", "pair_tasks",
           "partners_by_partition"]


@dataclass(frozen=True)
class PartitionClosures:
    """The loop closures of one partition's images: ``current`` counts the
    partition's frames (0 = its first), ``weights`` in [0, 1], ``partners``
    the aligned partner images (M, H, W[, C]) in the run's dtype;
    ``frames``: the partners' frames in the run (for error messages)."""

    current: tuple[int, ...]
    weights: tuple[float, ...]
    partners: np.ndarray
    frames: tuple[int, ...] = ()

    def __len__(self) -> int:
        return len(self.current)


@dataclass(frozen=True)
class PairTask:
    """Spatial pairs trained together: ``ids`` the distinct frames of the
    run they join (sorted), ``a``, ``b`` indices into ``ids``, ``weights``
    (> 0) and, for shifted pairs, ``shifts`` (columns, image ``b`` rolled
    left). ``owners``: the partition holding each of ``ids``."""

    index: int
    ids: tuple[int, ...]
    a: tuple[int, ...]
    b: tuple[int, ...]
    weights: tuple[float, ...]
    shifts: tuple[int, ...] | None
    owners: tuple[int, ...]

    def describe(self) -> str:
        return f"pair task {self.index} ({len(self.a)} pairs of frames {self.ids[0]}..{self.ids[-1]} of the run)"


def _owner(starts: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """The partition (index into ``starts``, the partitions' first frames)
    of every frame."""
    return np.searchsorted(starts, frames, side="right") - 1


def check_frames(frames: np.ndarray, hw: tuple[int, int, int], period: int, name: Callable[[int], str]) -> None:
    """Shape and finiteness of gathered frames (K, H, W[, C]); errors name
    the frame with ``name(k)``."""
    h, _, c = hw
    fc = 1 if frames.ndim == 3 else frames.shape[3]
    if frames.ndim not in (3, 4) or frames.shape[1] != h or fc != c or frames.shape[2] != period:
        raise ValueError(f"{name(0)}: images are {frames.shape[2]}x{frames.shape[1]} with {fc} channel(s), the "
                         f"run's are {period}x{h} with {c}")
    if frames.dtype.kind == "f":
        bad = ~np.isfinite(frames.reshape(len(frames), -1)).all(axis=1)
        if bad.any():
            raise ValueError(f"{name(int(np.argmax(bad)))} contains NaN or infinity")


def closures_by_partition(loop_closures: Any, weights: Any, parts: list[Any], n: int,
                          gather: Callable[[np.ndarray], np.ndarray], hw: tuple[int, int, int],
                          period: int) -> list[PartitionClosures | None]:
    """Per partition (``parts``, in run order, of ``n`` frames in all), its
    loop closures (None where it has none). ``loop_closures``,
    ``weights``: as in :meth:`sfanav.Network.fit`; ``gather(frames)``
    returns frames of the run (K, H, W[, C]). Raises ValueError /
    TypeError for bad closures, and for a bad partner image naming its
    frame and partition."""
    past, current, shift, w = check_closures(loop_closures, n, weights)
    starts = np.array([p.start for p in parts], dtype=np.int64)

    def name(j: int, i: int) -> str:
        return (f"the loop-closure partner frame {int(past[j])} of the run (partition "
                f"{int(_owner(starts, past[j:j + 1])[0])}, partner of frame {int(current[j])})")

    return _by_partition(current, w, past, parts, hw, period, lambda sel: np.asarray(gather(past[sel])), name,
                         shift=shift)


def partners_by_partition(partners: Any, parts: list[Any], n: int, frames: np.ndarray, hw: tuple[int, int, int],
                          period: int) -> list[PartitionClosures | None]:
    """Per partition (``parts``, in run order, of ``n`` frames in all), its
    share of explicit interleaving ``partners`` ``(current, weights,
    images)`` (as :meth:`sfanav.Network.fit` takes them: current indices of
    the whole run, each with its partner image, of the size and dtype of
    the run's ``frames``), None where it has none. Raises ValueError /
    TypeError as :func:`sfanav.sfa.feedback.check_partners`."""
    current, weights, imgs = check_partners(partners, n, frames.shape[1:], frames.dtype)
    cur = np.asarray(current, dtype=np.int64)

    def name(j: int, i: int) -> str:
        return f"the partner image of frame {int(cur[j])} of the run (partition {i})"

    return _by_partition(cur, np.asarray(weights), cur, parts, hw, period, lambda sel: imgs[sel], name)


def _by_partition(current: np.ndarray, weights: np.ndarray, sources: np.ndarray, parts: list[Any],
                  hw: tuple[int, int, int], period: int, images_of: Callable[[np.ndarray], np.ndarray],
                  name: Callable[[int, int], str], *, shift: np.ndarray | None = None
                  ) -> list[PartitionClosures | None]:
    """The one split of partners (M,) over ``parts``: each partition gets
    those whose ``current`` frame it holds, in run order, with their
    ``weights``, partner images ``images_of(selection)`` (checked against
    the run's size ``hw`` and ``period``; errors name partner ``j`` of
    partition ``i`` by ``name(j, i)``; rolled by ``shift`` to the current
    orientation where given) and ``sources`` (frames of the run, for
    messages); None where it has none."""
    starts = np.array([p.start for p in parts], dtype=np.int64)
    owner = _owner(starts, current)
    out: list[PartitionClosures | None] = []
    for i, part in enumerate(parts):
        sel = np.flatnonzero(owner == i)
        if not len(sel):
            out.append(None)
            continue
        sel = sel[np.argsort(current[sel], kind="stable")]
        frames = images_of(sel)
        check_frames(frames, hw, period, lambda k, sel=sel, i=i: name(int(sel[k]), i))
        if shift is not None:
            frames = aligned_partners(frames, shift[sel])
        out.append(PartitionClosures(tuple((current[sel] - part.start).tolist()), tuple(weights[sel].tolist()),
                                     np.ascontiguousarray(frames), tuple(sources[sel].tolist())))
    return out


def pair_tasks(pairs: Any, n: int, parts: list[Any], period: int, max_images: int) -> list[PairTask]:
    """The pair tasks of spatial ``pairs`` ``(idx_a, idx_b, weights[,
    shifts])`` of a run of ``n`` frames in ``parts``: the pairs with weight
    > 0 between two different images (or an image and itself rolled),
    sorted by ``(min(a, b), b)``, cut
    into runs whose distinct images number at most ``max_images`` (at
    least one pair per task). Shifts are taken modulo ``period``; a task's
    ``shifts`` is None when the pairs have none."""
    a, b, w, sh = check_pairs(pairs, n)
    sh = sh % period
    shifted = bool(np.any(sh))
    keep = np.flatnonzero((w > 0) & ((a != b) | (sh != 0)))  # an image and its rolled self make a pair
    order = keep[np.lexsort((b[keep], np.minimum(a[keep], b[keep])))]
    starts = np.array([p.start for p in parts], dtype=np.int64)
    tasks: list[PairTask] = []
    at = 0
    while at < len(order):
        ids: set[int] = set()
        end = at
        while end < len(order):
            e = order[end]
            new = {int(a[e]), int(b[e])} - ids
            if len(ids) + len(new) > max_images and end > at:
                break
            ids |= new
            end += 1
        sel = order[at:end]
        idl = np.array(sorted(ids), dtype=np.int64)
        tasks.append(PairTask(
            len(tasks), tuple(idl.tolist()), tuple(np.searchsorted(idl, a[sel]).tolist()),
            tuple(np.searchsorted(idl, b[sel]).tolist()), tuple(w[sel].tolist()),
            tuple(sh[sel].tolist()) if shifted else None, tuple(_owner(starts, idl).tolist())))
        at = end
    return tasks


def pair_statistics(net: Any, job: Any, task: PairTask, frames: np.ndarray) -> tuple[list[Any], int]:
    """The statistics that ``task``'s pairs add to the layer and pass of
    ``job`` (a list, one per node, of :class:`~sfanav.sfa.node.Statistics`)
    and 0 (images: pairs add none). ``net``: the network of the pass;
    ``frames``: the images ``task.ids`` (K, H, W[, C]). The pairs are fed
    ``job.batch_size`` at a time, as :meth:`sfanav.Network.fit` gathers
    them."""
    from .node import Statistics

    def name(k: int) -> str:
        return f"{task.describe()}: frame {task.ids[k]} of the run (partition {task.owners[k]})"

    check_frames(frames, net.input_shape, job.period, name)
    core = net._net
    tr = _core.LayerTrainer(core, job.layer, job.pass_, job.step, job.period, fast=job.fast,
                            transition_weight=job.transition_weight)
    a, b = np.asarray(task.a), np.asarray(task.b)
    chunk = max(1, job.batch_size)
    for lo in range(0, len(a), chunk):
        sa, sb = a[lo:lo + chunk], b[lo:lo + chunk]
        local = np.unique(np.concatenate([sa, sb]))
        shifts = None if task.shifts is None else list(task.shifts[lo:lo + chunk])
        try:
            tr.feed_pairs(core, np.ascontiguousarray(frames[local]), np.searchsorted(local, sa).tolist(),
                          np.searchsorted(local, sb).tolist(), list(task.weights[lo:lo + chunk]), shifts)
        except (ValueError, TypeError) as exc:
            raise type(exc)(f"{task.describe()}: {exc}") from exc
    return [Statistics.from_core(s) for s in tr.statistics(core)], 0
