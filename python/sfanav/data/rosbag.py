"""Reading ROS bags: a robot's recorded runs (camera images, wheel odometry,
optionally a ground-truth pose; one run per bag) as an sfanav dataset.

:func:`import_bag` (and :meth:`sfanav.Dataset.from_bag`, ``sfanav import``)
reads ROS 1 bags (``.bag``), ROS 2 bag folders (SQLite or MCAP storage) and
single ``.db3`` or ``.mcap`` files with the pure-Python ``rosbags`` library
(no ROS installation; ``pip install "sfanav[ros]"``). Every image gets the
odometry and ground-truth pose linearly interpolated at its timestamp, the
heading (the quaternion's yaw) along the shorter arc: the rules of
:meth:`sfanav.Dataset.from_recording`. Poses are never invented: images
before the first or after the last pose message, or in a gap between two
messages longer than ``max_gap``, are an error, dropped, or kept with an
empty pose (``outside``), and every gap is reported.

The import streams: a first pass reads the poses and the image timestamps
(small), a second decodes the images one at a time and writes them with a
staged :class:`~sfanav.data.writer.DatasetWriter`, so a bag larger than
memory imports in bounded memory. The dataset is written into a hidden
folder beside ``out`` and moved there only when complete: an import that
fails (a bad image names its message and stamp) or is interrupted leaves
nothing, and a dataset it would replace (``overwrite``) stays as it was.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._progress import Log, progress_bar, stderr_log
from .images import encode_png
from .ros_messages import (
    COMPRESSED_IMAGE,
    IMAGE,
    IMAGE_TYPES,
    POSE_TYPES,
    compressed_suffix,
    decode_image,
    field_problem,
    pose_of,
    raw_image_shape,
    require_rosbags,
    stamp_of,
    typestore,
)
from .schema import check_name, format_stamp_ns
from .writer import DatasetWriter

TIME_SOURCES = ("header", "bag")


OUTSIDE = ("error", "drop", "empty")


MAX_LISTED_GAPS = 100


MAX_POSITION = 1e9
"""Largest |x| or |y| (m) a pose message may hold: far beyond any frame a
robot uses (UTM and Earth-centred coordinates stay below 1e7 m), and small
enough that interpolating between two poses cannot overflow. A larger
value is a corrupt or unset message, refused with its stamp and value."""


@dataclass(frozen=True)
class BagTopic:
    """One topic of a bag: its name, message type (ROS 2 style, e.g.
    ``sensor_msgs/msg/Image``; None if it carries several) and message count."""

    name: str
    msgtype: str | None
    count: int


@dataclass(frozen=True)
class BagInfo:
    """What a bag holds: ``ros`` (1 or 2), ``start`` and ``end`` (s, the
    times the bag recorded; None if empty) and its topics."""

    path: Path
    ros: int
    start: float | None
    end: float | None
    topics: tuple[BagTopic, ...]

    def topic(self, name: str) -> BagTopic | None:
        return next((t for t in self.topics if t.name == name), None)

    def describe(self) -> str:
        """A table of the topics with their types, counts and rates."""
        span = (self.end - self.start) if self.start is not None and self.end is not None else 0.0
        head = (f"{self.path} (ROS {self.ros}): {sum(t.count for t in self.topics)} messages on "
                f"{len(self.topics)} topics over {span:.1f} s")
        if not self.topics:
            return head
        rows = [("topic", "type", "messages", "rate")]
        for t in self.topics:
            rate = f"{(t.count - 1) / span:.1f} Hz" if span > 0 and t.count > 1 else "-"
            rows.append((t.name, t.msgtype or "(several types)", str(t.count), rate))
        w = [max(len(r[i]) for r in rows) for i in range(4)]
        lines = [f"{a:<{w[0]}}  {b:<{w[1]}}  {c:>{w[2]}}  {d:>{w[3]}}" for a, b, c, d in rows]
        return head + "\n" + "\n".join(lines)

    def describe_topics(self) -> str:
        """The topics in one line, for error messages."""
        return ", ".join(f"{t.name} ({t.msgtype}, {t.count})" for t in self.topics) or "none"


def _unreadable(path: Path, exc: BaseException) -> ValueError:
    return ValueError(f"cannot read the bag {path}: {_reason(exc)} (truncated, damaged, still being recorded, or "
                      "not a bag? rosbag reindex / ros2 bag reindex repairs an unfinished recording)")


def _reason(exc: BaseException) -> str:
    """What went wrong, in one line: the exception's text (its type's name
    for a text-less one; an allocation a corrupt length asked for is said so)."""
    msg = " ".join(" ".join(str(a) for a in exc.args).split())
    if isinstance(exc, MemoryError):
        return f"a length in the bag asks for more memory than there is{': ' + msg if msg else ''}"
    return msg or type(exc).__name__


class _Bag:
    """An open bag (``rosbags.highlevel.AnyReader``) whose failures are
    ValueErrors naming the bag.

    Any exception the reader raises while parsing the file (its own errors,
    ``OSError`` "Invalid data stream" of a damaged bz2 chunk, ``RuntimeError``
    "LZ4F_decompress failed" of an lz4 one, ``struct.error``, ``sqlite3``'s
    errors, a ``MemoryError`` from a corrupt length, ...) is the file's
    fault, so every one becomes ``cannot read the bag NAME: ...``; only
    KeyboardInterrupt and the like pass through."""

    def __init__(self, path: str | os.PathLike):
        require_rosbags()
        from rosbags.highlevel import AnyReader

        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"no bag at {self.path}")
        try:
            self.reader = AnyReader([self.path], default_typestore=typestore(2))
        except Exception as exc:  # noqa: BLE001 - the reader failing on the file's bytes: see the class
            raise _unreadable(self.path, exc) from None

    def __enter__(self) -> "_Bag":
        try:
            self.reader.open()
        except Exception as exc:  # noqa: BLE001 - see the class
            self._close()
            raise _unreadable(self.path, exc) from None
        return self

    def __exit__(self, *exc: Any) -> None:
        self._close()

    def _close(self) -> None:
        with contextlib.suppress(Exception):  # closing a damaged or half-opened bag: nothing to save
            self.reader.close()

    def info(self) -> BagInfo:
        r = self.reader
        topics = tuple(BagTopic(name, t.msgtype, int(t.msgcount)) for name, t in sorted(r.topics.items()))
        n = sum(t.count for t in topics)
        return BagInfo(self.path, 2 if r.is2 else 1, r.start_time / 1e9 if n else None,
                       r.end_time / 1e9 if n else None, topics)

    def messages(self, topic: str) -> Iterator[tuple[int, Any]]:
        """(time the bag recorded it in ns, message) of every message of ``topic``, in bag order."""
        conns = [c for c in self.reader.connections if c.topic == topic]
        k = 0
        try:
            it = self.reader.messages(connections=conns)
        except Exception as exc:  # noqa: BLE001 - see the class
            raise _unreadable(self.path, exc) from None
        while True:
            try:
                conn, ns, raw = next(it)
            except StopIteration:
                return
            except Exception as exc:  # noqa: BLE001 - see the class
                raise _unreadable(self.path, exc) from None
            try:
                msg = self.reader.deserialize(raw, conn.msgtype)
            except Exception as exc:  # noqa: BLE001 - the message's bytes do not make its type
                raise ValueError(f"bag {self.path}: message {k} of {topic} is not a valid {conn.msgtype}: "
                                 f"{_reason(exc)}") from None
            problem = field_problem(msg)
            if problem is not None:
                raise ValueError(f"bag {self.path}: message {k} of {topic} is not a {conn.msgtype} as ROS defines "
                                 f"it (the bag's own definition differs?): {problem}")
            yield int(ns), msg
            k += 1


def bag_info(path: str | os.PathLike) -> BagInfo:
    """The topics of a bag with their types and message counts.

    Raises
    ------
    FileNotFoundError, ValueError (not a readable bag), ImportError
    (without ``rosbags``: ``pip install "sfanav[ros]"``).

    Examples
    --------
    >>> print(bag_info("run.bag").describe())          # doctest: +SKIP
    """
    with _Bag(path) as bag:
        return bag.info()


# ---------------------------------------------------------------- poses

@dataclass
class _Track:
    """A pose topic: times (ns, strictly increasing) and poses (n, 3)."""

    topic: str
    what: str
    ns: np.ndarray
    poses: np.ndarray


def _check_topic(info: BagInfo, topic: Any, kinds: tuple[str, ...], what: str) -> str:
    if not isinstance(topic, str) or not topic:
        raise TypeError(f"the {what} topic must be a topic name, got {topic!r}")
    t = info.topic(topic)
    if t is None:
        raise ValueError(f"bag {info.path} has no topic {topic} (the {what} topic); its topics: "
                         f"{info.describe_topics()}")
    if t.msgtype not in kinds:
        raise TypeError(f"topic {topic} of {info.path} carries {t.msgtype or 'several types'}, not {what} "
                        f"({' or '.join(kinds)})")
    if t.count == 0:
        raise ValueError(f"topic {topic} of {info.path} has no messages")
    return topic


def _stamp(msg: Any, rec_ns: int, time: str, topic: str, k: int) -> int:
    if time == "bag":
        return rec_ns
    ns = stamp_of(msg)
    if ns == 0:
        raise ValueError(f"message {k} of {topic} has no header stamp (0); pass time='bag' (--time bag) to use "
                         "the times the bag recorded the messages")
    return ns


def _read_track(bag: _Bag, topic: str, what: str, time: str) -> _Track:
    ns: list[int] = []
    poses: list[tuple[float, float, float]] = []
    for k, (rec, msg) in enumerate(bag.messages(topic)):
        t = _stamp(msg, rec, time, topic, k)
        x, y, h = pose_of(msg)
        if not (math.isfinite(x) and math.isfinite(y)) or max(abs(x), abs(y)) > MAX_POSITION:
            raise ValueError(f"message {k} of {topic} ({what}, t={_sec(t)} s) has the position x={x!r}, y={y!r} m: "
                             + ("not finite" if not (math.isfinite(x) and math.isfinite(y)) else
                                f"beyond {MAX_POSITION:g} m from the origin, not a position (a corrupt message?)"))
        if what == "odometry" and not math.isfinite(h):
            raise ValueError(f"message {k} of {topic} (odometry, t={_sec(t)} s) has no orientation (a zero or "
                             "non-finite quaternion)")
        ns.append(t)
        poses.append((x, y, h))
    t = np.array(ns, np.int64)
    if len(t) < 2:
        raise ValueError(f"{what} topic {topic} needs at least 2 messages to interpolate, got {len(t)}")
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if len(bad):
        i = int(bad[0])
        raise ValueError(f"{what} topic {topic}: timestamps must increase strictly; message {i + 1} "
                         f"(t={_sec(t[i + 1])} s) does not come after message {i} (t={_sec(t[i])} s)"
                         + ("; with time='bag' (--time bag) the bag's own order is used" if time == "header" else ""))
    return _Track(topic, what, t, np.array(poses, float))


def _sec(ns: Any) -> str:
    """A time in ns as seconds for a message, exactly (``1733000000.190123455``, ``1000.5``, ``1000.0``)."""
    return format_stamp_ns(ns)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _interpolate(track: _Track, ns: np.ndarray, max_gap_ns: float) -> tuple[np.ndarray, np.ndarray]:
    """The track's poses at the times ``ns`` (linear; heading on the shorter
    arc, wrapped to [-pi, pi)) and a status per time: 0 covered, 1 before
    the first message, 2 after the last, 3 in a gap longer than max_gap."""
    tp = track.ns
    i = np.clip(np.searchsorted(tp, ns, side="right") - 1, 0, len(tp) - 2)
    dt = (tp[i + 1] - tp[i]).astype(float)
    frac = np.clip((ns - tp[i]).astype(float) / dt, 0.0, 1.0)
    P = track.poses
    out = np.empty((len(ns), 3))
    for c in (0, 1):
        out[:, c] = P[i, c] + frac * (P[i + 1, c] - P[i, c])
    d = _wrap(P[i + 1, 2] - P[i, 2])
    with np.errstate(invalid="ignore"):
        h = np.where(frac == 0, P[i, 2], np.where(frac == 1, P[i + 1, 2], P[i, 2] + frac * d))
    out[:, 2] = _wrap(h)
    status = np.zeros(len(ns), np.int8)
    status[(dt > max_gap_ns) & (frac > 0) & (frac < 1)] = 3
    status[ns < tp[0]] = 1
    status[ns > tp[-1]] = 2
    return out, status


def _gaps(track: _Track, max_gap_ns: float) -> list[list[float]]:
    k = np.nonzero(np.diff(track.ns) > max_gap_ns)[0]
    return [[track.ns[j] / 1e9, track.ns[j + 1] / 1e9] for j in k]


def _apply_outside(track: _Track, status: np.ndarray, values: np.ndarray, img_ns: np.ndarray, keep: np.ndarray,
                   outside: str, max_gap: float, notes: list[str]) -> dict[str, Any]:
    """Enforces ``outside`` for one track; returns its report for the
    metadata and adds a note on its gaps to ``notes``."""
    max_gap_ns = max_gap * 1e9
    gaps = _gaps(track, max_gap_ns)
    n_out, n_gap = int(np.isin(status, (1, 2)).sum()), int((status == 3).sum())
    what, topic = track.what, track.topic
    if outside == "error":
        if n_out:
            j = int(np.nonzero(np.isin(status, (1, 2)))[0][0])
            raise ValueError(
                f"{n_out} image(s) lie outside the time span of the {what} topic {topic} "
                f"[{_sec(track.ns[0])}, {_sec(track.ns[-1])}] s, first image {j} at t={_sec(img_ns[j])} s; "
                "pass outside='drop' (--outside drop) to leave them out, or 'empty' to keep them without a pose")
        if n_gap:
            j = int(np.nonzero(status == 3)[0][0])
            k = int(np.searchsorted(track.ns, img_ns[j])) - 1
            raise ValueError(
                f"{n_gap} image(s) fall in gaps of the {what} topic {topic} longer than max_gap={max_gap} s, "
                f"first image {j} at t={_sec(img_ns[j])} s, between messages at {_sec(track.ns[k])} and "
                f"{_sec(track.ns[k + 1])} s; pass outside='drop' (--outside drop) to leave them out, 'empty' "
                "to keep them without a pose, or a larger max_gap (--max-gap)")
    elif outside == "drop":
        keep &= status == 0
    else:
        values[status != 0] = np.nan
    if gaps or n_out or n_gap:
        done = {"error": "", "drop": ", left out", "empty": f", kept without {what}"}[outside]
        longest = max((b - a for a, b in gaps), default=0.0)
        notes.append(f"{what} topic {topic}: {len(gaps)} gap(s) longer than {max_gap} s"
            + (f" (longest {longest:.2f} s)" if gaps else "") + f"; {n_gap} image(s) in them and {n_out} outside "
            f"its time span{done if (n_gap or n_out) else ''}")
    return {"topic": topic, "messages": len(track.ns), "gaps": len(gaps), "gap_intervals_s": gaps[:MAX_LISTED_GAPS],
            "images_in_gaps": n_gap, "images_outside": n_out}


# ---------------------------------------------------------------- import

def _choose_image_topic(info: BagInfo, image_topic: str | None) -> str:
    if image_topic is not None:
        return _check_topic(info, image_topic, IMAGE_TYPES, "image")
    cands = [t.name for t in info.topics if t.msgtype in IMAGE_TYPES and t.count]
    if len(cands) == 1:
        return cands[0]
    if not cands:
        raise ValueError(f"bag {info.path} has no image topic ({' or '.join(IMAGE_TYPES)}); its topics: "
                         f"{info.describe_topics()}")
    raise ValueError(f"bag {info.path} has several image topics ({', '.join(cands)}); choose one with "
                     "image_topic= (--image-topic)")


def _check_options(time: str, outside: str, max_gap: Any) -> float:
    if time not in TIME_SOURCES:
        raise ValueError(f"time must be 'header' (the messages' header stamps) or 'bag' (when the bag recorded "
                         f"them), got {time!r}")
    if outside not in OUTSIDE:
        raise ValueError(f"outside must be one of {', '.join(OUTSIDE)}, got {outside!r}")
    if isinstance(max_gap, bool) or not isinstance(max_gap, (int, float, np.integer, np.floating)):
        raise TypeError(f"max_gap must be a number of seconds, got {max_gap!r}")
    if not (math.isfinite(max_gap) and max_gap > 0):
        raise ValueError(f"max_gap must be a positive number of seconds, got {max_gap!r}")
    return float(max_gap)


def _image_file(msg: Any) -> tuple[bytes, str, tuple[int, ...]]:
    """The bytes, suffix and decoded shape of an image message as a dataset
    file: PNG and JPEG messages kept as they are, raw images as PNG."""
    img = decode_image(msg)
    if msg.__msgtype__ == COMPRESSED_IMAGE:
        data = np.asarray(msg.data, np.uint8)
        suffix = compressed_suffix(data)
        if suffix is not None:
            return data.tobytes(), suffix, img.shape
    return encode_png(img), ".png", img.shape


@dataclass
class _Plan:
    """One bag's images after the first pass: their stamps (ns), which are
    kept, and their ground truth and odometry (N, 3; NaN unknown)."""

    path: Path
    run: str
    ros: int
    topic: str
    img_ns: np.ndarray
    keep: np.ndarray
    gt: np.ndarray
    odo: np.ndarray
    report: dict[str, Any]
    notes: list[str]
    shape: tuple[int, ...] | None = None  # of the raw images; None for compressed ones


def _plan(path: Path, run: str, image_topic: str | None, odom_topic: str | None, pose_topic: str | None,
          time: str, outside: str, max_gap: float) -> _Plan:
    """The first pass over a bag: poses, image stamps, the checks and the matching."""
    with _Bag(path) as b:
        info = b.info()
        topic = _choose_image_topic(info, image_topic)
        tracks = []
        if odom_topic is not None:
            tracks.append(_read_track(b, _check_topic(info, odom_topic, POSE_TYPES, "odometry"), "odometry", time))
        if pose_topic is not None:
            tracks.append(_read_track(b, _check_topic(info, pose_topic, POSE_TYPES, "ground truth"),
                                      "ground truth", time))
        stamps: list[int] = []
        layouts: list[tuple[int, ...] | str | None] = []
        for k, (rec, m) in enumerate(b.messages(topic)):
            stamps.append(_stamp(m, rec, time, topic, k))
            layouts.append(_raw_layout(m))
        img_ns = np.array(stamps, np.int64)
    _check_image_order(topic, img_ns, time)
    keep = np.ones(len(img_ns), bool)
    values: dict[str, np.ndarray] = {}
    reports: dict[str, Any] = {}
    notes = [] if image_topic is not None else [f"images from {topic}, the bag's only image topic"]
    for tr in tracks:
        v, status = _interpolate(tr, img_ns, max_gap * 1e9)
        reports[tr.what.replace(" ", "_")] = _apply_outside(tr, status, v, img_ns, keep, outside, max_gap, notes)
        values[tr.what] = v
    n = int(keep.sum())
    if n == 0:
        raise ValueError(f"no image of {topic} in {path} lies within the time span of the pose topics")
    shape = _check_raw_images(path, topic, img_ns, layouts, keep)
    if n < len(keep):
        notes.append(f"{len(keep) - n} of {len(keep)} images left out (no pose at their time)")
    unknown = np.full((len(img_ns), 3), np.nan)
    report = {"path": str(path), "ros": info.ros, "run": run,
              "topics": {"image": topic, "odometry": odom_topic, "ground_truth": pose_topic},
              "images_in_bag": len(img_ns), "images_left_out": len(img_ns) - n, "poses": reports}
    return _Plan(path, run, info.ros, topic, img_ns, keep, values.get("ground truth", unknown),
                 values.get("odometry", unknown), report, notes, shape)


def _check_image_order(topic: str, img_ns: np.ndarray, time: str) -> None:
    """Image stamps must increase strictly: two frames with one stamp are
    refused here, naming both with their exact stamps, because a dataset
    whose run repeats a stamp would import but not train from odometry
    (``sfanav train`` needs the frames' times to increase)."""
    bad = np.nonzero(np.diff(img_ns) <= 0)[0]
    if not len(bad):
        return
    i = int(bad[0])
    a, b = int(img_ns[i]), int(img_ns[i + 1])
    how = (f"images {i} and {i + 1} have the same stamp t={_sec(a)} s ({a} ns)" if a == b else
           f"image {i + 1} (t={_sec(b)} s) is earlier than image {i} (t={_sec(a)} s)")
    more = f"; {len(bad)} such pairs in all" if len(bad) > 1 else ""
    hint = "; with time='bag' (--time bag) the times the bag recorded them are used" if time == "header" else ""
    raise ValueError(f"image topic {topic}: timestamps must increase strictly; {how}{more}{hint}")


def _raw_layout(msg: Any) -> tuple[int, ...] | str | None:
    """The decoded shape of a raw image message, or why it does not decode;
    None for a compressed image (known only once decoded)."""
    if msg.__msgtype__ != IMAGE:
        return None
    try:
        return raw_image_shape(msg)
    except ValueError as exc:
        return str(exc)


def _check_raw_images(path: Path, topic: str, img_ns: np.ndarray, layouts: list[Any],
                      keep: np.ndarray) -> tuple[int, ...] | None:
    """The first pass's check of the raw images to be written: each decodes
    (encoding, size, data length) and all share one shape, which is returned
    (None for compressed images, checked as they are decoded)."""
    first: tuple[int, ...] | None = None
    for k in np.nonzero(keep)[0]:
        v = layouts[k]
        if isinstance(v, str):
            raise ValueError(f"{_image_name(path, topic, int(k), img_ns[k])}: {v}")
        if v is not None and first is None:
            first = v
        elif v is not None and v != first:
            raise ValueError(f"{_image_name(path, topic, int(k), img_ns[k])} has shape {v}, unlike {first} before it")
    return first


def _write_images(plan: _Plan, w: DatasetWriter, frame: int, camera: str, condition: str, shape: list[Any],
                  bar: Any) -> int:
    """The second pass over a bag: decodes and writes its kept images from
    frame id ``frame`` on; returns the next frame id. ``shape`` holds the
    first image's shape (all must share it)."""
    k = -1
    with _Bag(plan.path) as b:
        for k, (_, msg) in enumerate(b.messages(plan.topic)):
            if k >= len(plan.img_ns):
                break
            if not plan.keep[k]:
                continue
            try:
                data, suffix, shp = _image_file(msg)
            except ValueError as exc:
                raise ValueError(f"{_image_name(plan.path, plan.topic, k, plan.img_ns[k])}: {exc}") from None
            if not shape:
                shape.append(shp)
            elif shp != shape[0]:
                raise ValueError(f"{_image_name(plan.path, plan.topic, k, plan.img_ns[k])} has shape {shp}, "
                                 f"unlike {shape[0]} before it")
            ns = int(plan.img_ns[k])
            w.add_encoded(data, suffix, shape=shp, frame=frame, timestamp=ns / 1_000_000_000, stamp_ns=ns,
                          pose=plan.gt[k], odometry=plan.odo[k], camera=camera, condition=condition, run=plan.run)
            frame += 1
            if bar is not None:
                bar.update(1)
        if k + 1 != len(plan.img_ns):
            raise ValueError(f"bag {plan.path} changed while it was read ({len(plan.img_ns)} images of "
                             f"{plan.topic}, then {k + 1})")
    return frame


def _image_name(path: Path, topic: str, k: int, ns: Any) -> str:
    """Image message ``k`` of a bag, for an error: its index, topic, bag and stamp (ns)."""
    return f"image {k} of {topic} in {path} (t={_sec(ns)} s)"


def _runs(paths: list[Path], run: Any) -> list[str]:
    if run is None:
        names = ["0"] if len(paths) == 1 else [p.stem or p.name for p in paths]
    elif isinstance(run, str):
        if len(paths) != 1:
            raise ValueError(f"give one run name per bag ({len(paths)} bags), got {run!r}")
        names = [run]
    else:
        names = [str(r) for r in run]
        if len(names) != len(paths):
            raise ValueError(f"give one run name per bag: {len(paths)} bags, {len(names)} run names")
    names = [check_name(r, "run") for r in names]
    if len(set(names)) != len(names):
        raise ValueError(f"each bag needs a run name of its own, got {', '.join(names)}")
    return names


def import_bag(bag: Any, out: str | os.PathLike, *, image_topic: str | None = None,
               odom_topic: str | None = None, pose_topic: str | None = None, run: Any = None,
               camera: str = "center", condition: str = "default", time: str = "header", outside: str = "error",
               max_gap: float = 1.0, overwrite: bool = False, progress: bool = False,
               log: Log = stderr_log) -> Any:
    """Imports recorded runs from ROS bags (one run per bag) as an sfanav
    dataset and returns it opened (see :meth:`sfanav.Dataset.from_bag`,
    which calls this)."""
    from .dataset import Dataset

    paths = [Path(bag)] if isinstance(bag, (str, os.PathLike)) else [Path(b) for b in bag]
    if not paths:
        raise ValueError("no bag given")
    max_gap = _check_options(time, outside, max_gap)
    runs = _runs(paths, run)
    camera, condition = check_name(camera, "camera"), check_name(condition, "condition")
    if odom_topic is None and pose_topic is None:
        raise ValueError("give the odometry topic (odom_topic=, --odom-topic), the ground-truth pose topic "
                         "(pose_topic=, --pose-topic) or both: the images need poses")
    out = Path(out)
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise FileExistsError(f"{out} is not empty; pass overwrite=True (--overwrite) to replace it")
    plans = [_plan(p, r, image_topic, odom_topic, pose_topic, time, outside, max_gap) for p, r in zip(paths, runs)]
    raw = [p for p in plans if p.shape is not None]
    for p in raw[1:]:
        if p.shape != raw[0].shape:
            k = int(np.argmax(p.keep))
            raise ValueError(f"{_image_name(p.path, p.topic, k, p.img_ns[k])} has shape {p.shape}, unlike "
                             f"{raw[0].shape} of the images of {raw[0].path}: the runs of one dataset share one size")
    for plan in plans:
        for note in plan.notes:
            log(note if len(plans) == 1 else f"{plan.path.name}: {note}")
    meta = {"source": "rosbag", "time": "header stamps" if time == "header" else "bag record times",
            "interpolation": "linear on timestamps, heading along the shorter arc", "max_gap_s": max_gap,
            "outside": outside, "images_left_out": sum(p.report["images_left_out"] for p in plans),
            "bags": [p.report for p in plans]}
    total = sum(int(p.keep.sum()) for p in plans)
    bar = progress_bar(progress, total, "importing")
    shape: list[Any] = []
    frame = 0
    try:
        with DatasetWriter(out, meta, overwrite=overwrite, exact_stamps=True, staged=True) as w:
            for plan in plans:
                frame = _write_images(plan, w, frame, camera, condition, shape, bar)
    finally:
        if bar is not None:
            bar.close()
    return Dataset(out)
