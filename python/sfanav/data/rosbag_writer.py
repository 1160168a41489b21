"""Writing ROS bags: :class:`BagWriter` records camera images, poses and
odometry as ROS 1 or ROS 2 messages, so that sfanav's results (the
estimates of ``sfanav localize``) replay in rviz, Foxglove or PlotJuggler,
and so that tests and benchmarks can make the bags a robot would record.

The bag is written under a temporary name beside its destination and
renamed on :meth:`BagWriter.close`: an interrupted run leaves no bag that
looks complete. Needs the optional dependency ``rosbags``
(``pip install "sfanav[ros]"``).
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import as_int_array, check_int
from .ros_messages import (
    COMPRESSED_IMAGE,
    IMAGE,
    JPEG_QUALITY,
    ODOMETRY,
    POSE_STAMPED,
    image_message,
    odometry_message,
    pose_message,
    require_rosbags,
    typestore,
)

BAG_SUFFIXES = (".bag", ".mcap", ".db3")
"""The bag files :class:`BagWriter` writes: ROS 1 ``.bag``, ROS 2 ``.mcap``
(MCAP storage) and ``.db3`` (SQLite storage, one file without its
``metadata.yaml``, as ``ros2 bag`` and ``rosbags`` open it)."""


UNITS = ("s", "ns")


MAX_SEC = 2**31 - 1
"""The largest whole second of a stamp: ``rosbags`` writes the seconds of
ROS 1 and ROS 2 times as int32 (2038-01-19 as a Unix time)."""


def stamp_ns(t: Any, what: str = "timestamp") -> int:
    """A time in seconds as integer nanoseconds (finite, >= 0: ROS times are
    unsigned; below 2**31 s). Float seconds hold a Unix time to a few
    hundred ns only: give exact times as integer ns (:func:`check_stamp_ns`)."""
    try:
        v = float(t)
    except (TypeError, ValueError):
        raise TypeError(f"{what} must be a number of seconds, got {t!r}") from None
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"{what} must be a finite number of seconds >= 0, got {t!r}")
    if v >= MAX_SEC + 1:
        raise ValueError(f"{what} must be below 2**31 s (a ROS time's seconds are int32), got {t!r} s; "
                         "integer nanoseconds need unit='ns'")
    sec = math.floor(v)  # whole seconds apart: v * 1e9 would round Unix times to 256 ns
    return int(sec) * 1_000_000_000 + int(round((v - sec) * 1e9))


def check_stamp_ns(t: Any, what: str = "stamp") -> int:
    """A time given as integer nanoseconds, checked (an integer, >= 0, below
    2**31 s) and returned as an int, exactly."""
    ns = check_int(t, what, minimum=0)
    if ns >= (MAX_SEC + 1) * 1_000_000_000:
        raise ValueError(f"{what} must be below 2**31 s (a ROS time's seconds are int32), got {ns} ns")
    return ns


class BagWriter:
    """Writes a ROS bag message by message.

    Parameters
    ----------
    path : path
        ``NAME.bag``: a ROS 1 bag. ``NAME.mcap``: a ROS 2 bag in one MCAP
        file (Foxglove and ``ros2 bag play`` open it). ``NAME.db3``: a ROS 2
        bag in one SQLite file (``ros2 bag``'s default storage up to
        Humble; the file alone, without a ``metadata.yaml``). A name without
        suffix: a ROS 2 bag folder (``metadata.yaml`` and an SQLite
        ``.db3`` file, what ``ros2 bag record`` writes by default up to ROS 2
        Humble).
    overwrite : bool
        Replace an existing bag at ``path`` (refused otherwise).
    unit : ``"s"`` or ``"ns"``
        The unit of every stamp and record time given to the ``add_*``
        methods: float seconds (default; exact to a few hundred ns for a
        Unix time), or integer nanoseconds (exact: what a ROS header holds).

    Raises
    ------
    ImportError
        Without ``rosbags`` (``pip install "sfanav[ros]"``).
    FileExistsError
        If ``path`` exists and ``overwrite`` is false.
    FileNotFoundError
        If the folder of ``path`` does not exist.
    ValueError
        For another suffix.

    Examples
    --------
    >>> with BagWriter("run.bag") as bag:                          # doctest: +SKIP
    ...     bag.add_image("/camera/image_raw", 0.1, image)         # (60, 600, 3) uint8 RGB
    ...     bag.add_odometry("/odom", 0.1, (1.0, 2.0, 0.5))        # x m, y m, heading rad
    """

    def __init__(self, path: str | os.PathLike, *, overwrite: bool = False, unit: str = "s"):
        if unit not in UNITS:
            raise ValueError(f"unit must be 's' (float seconds) or 'ns' (integer nanoseconds), got {unit!r}")
        self.unit = unit
        require_rosbags()
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in BAG_SUFFIXES + ("",):
            raise ValueError(f"{self.path}: a bag is NAME.bag (ROS 1), NAME.mcap or NAME.db3 (ROS 2) or a folder "
                             "NAME (ROS 2)")
        if not self.path.parent.is_dir():
            raise FileNotFoundError(f"the folder {self.path.parent} for {self.path.name} does not exist")
        if self.path.exists() and not overwrite:
            raise FileExistsError(f"{self.path} exists; pass overwrite=True (--overwrite) to replace it")
        if self.path.exists() and suffix == "" and not (self.path / "metadata.yaml").exists():
            raise FileExistsError(f"{self.path} exists and is not a ROS 2 bag folder; refusing to replace it")
        self.ros = 1 if suffix == ".bag" else 2
        self.store = typestore(self.ros)
        self._tmp = self.path.parent / f".{self.path.name}.part"
        _remove(self._tmp)
        try:
            self._tmp.mkdir()
        except OSError as exc:  # name the bag asked for, not the temporary folder
            raise type(exc)(exc.errno, exc.strerror, str(self.path)) from None
        self._inner = self._tmp / (self.path.name if self.ros == 1 else self.path.stem)
        if self.ros == 1:
            self._writer: Any = Writer1(self._inner)
        else:
            plugin = StoragePlugin.MCAP if suffix == ".mcap" else StoragePlugin.SQLITE3
            self._writer = Writer2(self._inner, version=9, storage_plugin=plugin)
        self._overwrite = overwrite
        self._connections: dict[str, tuple[Any, str]] = {}
        self._seq: dict[str, int] = {}
        self.count = 0
        try:
            self._writer.open()
        except BaseException:
            _remove(self._tmp)
            raise
        self._open = True

    def _write(self, topic: str, msgtype: str, msg: Any, record_ns: int) -> None:
        if not self._open:
            raise ValueError("this BagWriter is closed")
        if not isinstance(topic, str) or not topic.startswith("/") or any(c.isspace() for c in topic):
            raise ValueError(f"a topic is a name starting with '/' without spaces, got {topic!r}")
        if topic not in self._connections:
            conn = self._writer.add_connection(topic, msgtype, typestore=self.store)
            self._connections[topic] = (conn, msgtype)
        conn, have = self._connections[topic]
        if have != msgtype:
            raise ValueError(f"topic {topic} carries {have} messages, not {msgtype}")
        ser = self.store.serialize_ros1 if self.ros == 1 else self.store.serialize_cdr
        self._writer.write(conn, record_ns, ser(msg, msgtype))
        self._seq[topic] = self._seq.get(topic, 0) + 1
        self.count += 1

    def _stamps(self, stamp: Any, record_time: Any) -> tuple[int, int]:
        conv = check_stamp_ns if self.unit == "ns" else stamp_ns
        ns = conv(stamp, "stamp")
        return ns, ns if record_time is None else conv(record_time, "record_time")

    def add_image(self, topic: str, stamp: float | int, image: np.ndarray, *, fmt: str = "raw",
                  encoding: str | None = None, frame_id: str = "camera",
                  record_time: float | int | None = None, quality: int = JPEG_QUALITY) -> None:
        """Writes a uint8 RGB (H, W, 3) or gray (H, W) image taken at ``stamp``
        (s, or ns with ``unit="ns"``) as a ``sensor_msgs/Image``
        (``fmt="raw"``, ``encoding`` ``rgb8``, ``bgr8`` or ``mono8``) or a
        ``sensor_msgs/CompressedImage`` (``fmt="png"`` or ``"jpeg"``, JPEG at ``quality``). ``record_time``
        (same unit) is when the bag received it (default: ``stamp``)."""
        ns, rec = self._stamps(stamp, record_time)
        msg = image_message(self.store, ns, image, fmt=fmt, encoding=encoding, frame_id=frame_id,
                            seq=self._seq.get(topic, 0), quality=quality)
        self._write(topic, IMAGE if fmt == "raw" else COMPRESSED_IMAGE, msg, rec)

    def add_pose(self, topic: str, stamp: float | int, pose: Any, *, frame_id: str = "map",
                 record_time: float | int | None = None) -> None:
        """Writes a ``geometry_msgs/PoseStamped`` at ``pose`` = (x m, y m,
        heading rad), z = 0, at ``stamp`` (s, or ns with ``unit="ns"``)."""
        ns, rec = self._stamps(stamp, record_time)
        self._write(topic, POSE_STAMPED, pose_message(self.store, ns, _pose3(pose), frame_id=frame_id,
                                                      seq=self._seq.get(topic, 0)), rec)

    def add_odometry(self, topic: str, stamp: float | int, pose: Any, *, frame_id: str = "odom",
                     child_frame_id: str = "base_link", record_time: float | int | None = None) -> None:
        """Writes a ``nav_msgs/Odometry`` at ``pose`` = (x m, y m, heading
        rad) at ``stamp`` (s, or ns with ``unit="ns"``); velocities and
        covariances zero (unknown)."""
        ns, rec = self._stamps(stamp, record_time)
        msg = odometry_message(self.store, ns, _pose3(pose), frame_id=frame_id, child_frame_id=child_frame_id,
                               seq=self._seq.get(topic, 0))
        self._write(topic, ODOMETRY, msg, rec)

    def close(self) -> None:
        """Completes the bag and moves it to its destination."""
        if not self._open:
            return
        self._open = False
        try:
            self._writer.close()
            suffix = self.path.suffix.lower()
            src = self._inner / f"{self._inner.name}{suffix}" if suffix in (".mcap", ".db3") else self._inner
            if self.path.exists():
                _remove(self.path)
            os.replace(src, self.path)
        finally:
            _remove(self._tmp)

    def abort(self) -> None:
        """Stops writing and removes the unfinished bag (nothing is left at ``path``)."""
        if self._open:
            self._open = False
            try:
                self._writer.abort()
            finally:
                _remove(self._tmp)

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


ESTIMATE_TOPIC = "/sfanav/estimate"


FUSED_TOPIC = "/sfanav/fused"


def write_estimates(path: str | os.PathLike, stamps: Any, xy: Any, fused: Any = None, *, frame_id: str = "map",
                    child_frame_id: str = "base_link", overwrite: bool = False, unit: str = "s") -> int:
    """Writes localization results as a ROS bag that replays in rviz,
    Foxglove or PlotJuggler: every estimate as a
    ``geometry_msgs/PoseStamped`` on ``/sfanav/estimate`` (x, y; orientation
    the identity, as a single image's estimate has no heading), and the
    fused track (odometry + estimates) as ``nav_msgs/Odometry`` on
    ``/sfanav/fused`` (x, y, heading; velocities and covariances zero, i.e.
    unknown). Rows with a non-finite estimate are left out.

    Parameters
    ----------
    path : ``NAME.bag`` (ROS 1), ``NAME.mcap`` or ``NAME.db3`` (ROS 2, MCAP or SQLite storage)
    stamps : (N,) seconds, >= 0, or integer nanoseconds with ``unit="ns"``
        The images' times (the header stamps and the bag's record times).
        Give a dataset's ``stamps_ns`` where it has them: then every
        estimate carries exactly its image's header stamp (float seconds
        hold a Unix time to a few hundred ns only, too coarse for ROS's
        exact-time synchronisation).
    xy : (N, 2) metres
    fused : (N, 3), optional
        x m, y m, heading rad.
    frame_id : str
        The frame of the positions (default ``map``).
    unit : ``"s"`` or ``"ns"``
        The unit of ``stamps``; ``"ns"`` takes integers only.

    Returns
    -------
    int
        The number of messages written.

    Examples
    --------
    >>> write_estimates("estimates.bag", ds.stamps_ns, xy, fused, unit="ns")   # doctest: +SKIP
    """
    if Path(path).suffix.lower() not in BAG_SUFFIXES:
        raise ValueError(f"{path}: estimates are written to NAME.bag (ROS 1), NAME.mcap or NAME.db3 (ROS 2)")
    if unit not in UNITS:
        raise ValueError(f"unit must be 's' (float seconds) or 'ns' (integer nanoseconds), got {unit!r}")
    if unit == "ns":
        try:
            t: Any = as_int_array(np.asarray(stamps).reshape(-1), "stamps")
        except TypeError as exc:
            raise TypeError(f"{exc}: unit='ns' takes integer nanoseconds (float seconds: unit='s')") from None
        stamp_list = [check_stamp_ns(v, "stamp") for v in t.tolist()]
    else:
        t = np.asarray(stamps, float).reshape(-1)
        stamp_list = [stamp_ns(v, "stamp") for v in t]
    P = np.asarray(xy, float)
    if P.ndim != 2 or P.shape[1] != 2 or len(P) != len(t):
        raise ValueError(f"xy must have shape ({len(t)}, 2) (one row per stamp), got {P.shape}")
    F = None if fused is None else np.asarray(fused, float)
    if F is not None and F.shape != (len(t), 3):
        raise ValueError(f"fused must have shape ({len(t)}, 3), got {F.shape}")
    with BagWriter(path, overwrite=overwrite, unit="ns") as bag:
        for i, ns in enumerate(stamp_list):
            if np.isfinite(P[i]).all():
                bag.add_pose(ESTIMATE_TOPIC, ns, (P[i, 0], P[i, 1], 0.0), frame_id=frame_id)
            if F is not None and np.isfinite(F[i]).all():
                bag.add_odometry(FUSED_TOPIC, ns, F[i], frame_id=frame_id, child_frame_id=child_frame_id)
        count = bag.count
    return count


def _pose3(pose: Any) -> tuple[float, float, float]:
    try:
        x, y, th = (float(v) for v in pose)
    except (TypeError, ValueError):
        raise ValueError(f"a pose is (x m, y m, heading rad), got {pose!r}") from None
    if not all(math.isfinite(v) for v in (x, y, th)):
        raise ValueError(f"a pose must be finite, got {pose!r}")
    return x, y, th


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    elif p.exists() or p.is_symlink():
        p.unlink()
