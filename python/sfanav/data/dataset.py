"""One dataset format for simulated and real recordings, and readers.

The sfanav dataset is a directory::

    metadata.json     # {"format": "sfanav-dataset", "version": 1, "units": ..., "cameras": ..., ...}
    frames.csv        # one row per image, columns below
    images/           # PNG files (any format OpenCV reads is accepted on input)

``frames.csv`` columns (``COLUMNS``), then any extra columns:

=============  =====================================================================
frame          integer frame id (the cameras of one robot pose share it)
run            name of the run (e.g. ``train``, ``test``, ``lines``)
timestamp      seconds
stamp_ns       optional: the same time exactly, integer nanoseconds (int64; the
               header stamps of an imported ROS bag; :attr:`Dataset.stamps_ns`)
x, y           ground-truth position of the camera that took the image (m); empty if unknown
heading        ground-truth heading (rad, counter-clockwise from +x); empty if unknown
odom_x, ...    wheel-odometry estimate of the same (m, m, rad); empty if unknown
gyro_heading   optional (after the image column): the heading integrated from a
               yaw gyro (rad, continuous, cumulative from the run's start;
               :attr:`Dataset.gyro`)
camera         camera name (``center``, ``left``, ``right``)
condition      lighting or recording condition
image          image path relative to the dataset directory
=============  =====================================================================

:class:`Dataset` reads this format, and two others:

* the layout of the public panoramic image databases of the
  insect-navigation community: a folder of images with
  ``database_entries.csv`` (``X [mm], Y [mm], Z [mm], Heading [degrees],
  Filename, ...``) and optionally ``database_metadata.yaml``;
* real recordings (images with timestamps plus a separate pose log) via
  :meth:`Dataset.from_recording`, which assigns each image its pose by
  linear interpolation on the timestamps (thesis 4.2.2).

Images are read lazily (:meth:`Dataset.images`).
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._progress import progress_bar
from .images import read_image
from .._checks import as_int_array
from .schema import (
    COLUMNS,
    FLOAT_COLUMNS,
    FORMAT,
    GYRO_COLUMN,
    INSECT_ENTRIES,
    INSECT_METADATA,
    INT64_MAX,
    STAMP_COLUMN,
    UNITS,
    VERSION,
    check_name,
    stamps_disagree,
)
from .writer import DatasetWriter


def write_dataset(path: str | os.PathLike, images: Iterable[np.ndarray], poses: Any, *,
                  timestamps: Any = None, odometry: Any = None, cameras: Any = None, conditions: Any = None,
                  runs: Any = None, frames: Any = None, extra: dict[str, Any] | None = None,
                  metadata: dict[str, Any] | None = None, overwrite: bool = False,
                  progress: bool = False, stamps_ns: Any = None, gyro: Any = None) -> "Dataset":
    """Writes an sfanav dataset from arrays and returns it opened.

    Parameters
    ----------
    images : iterable of uint8 (H, W[, 3]) arrays, N of them (read lazily)
    poses : (N, 3) x m, y m, heading rad
    timestamps : (N,) s, default 0, 1, 2, ... (or ``stamps_ns`` / 1e9)
    stamps_ns : (N,) int, optional
        The same times exactly, in integer nanoseconds (the ``stamp_ns``
        column).
    odometry : (N, 3), optional
    cameras, conditions, runs : (N,) names or one name; default ``center``,
        ``default``, ``0``
    frames : (N,) int, default 0 .. N-1
    extra : dict of name to (N,) extra columns
    gyro : (N,) float, optional
        The heading integrated from a yaw gyro (rad, continuous; the
        ``gyro_heading`` column, :attr:`Dataset.gyro`).
    """
    P = np.asarray(poses, float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"poses must have shape (N, 3), got {P.shape}")
    n = len(P)

    def col(v: Any, default: Any, name: str) -> np.ndarray:
        if v is None:
            return np.full(n, default, dtype=object)
        if isinstance(v, str):
            return np.full(n, v, dtype=object)
        a = np.asarray(v)
        if a.shape[:1] != (n,):
            raise ValueError(f"{name} must have {n} entries (one per pose), got shape {a.shape}")
        return a

    ns = None
    if stamps_ns is not None:
        ns = as_int_array(stamps_ns, "stamps_ns")
        if ns.shape != (n,):
            raise ValueError(f"stamps_ns must have {n} entries (one per pose), got shape {ns.shape}")
    if timestamps is not None:
        ts = col(timestamps, None, "timestamps")
    else:
        ts = ns / 1e9 if ns is not None else np.arange(n, dtype=float)
    O = None if odometry is None else np.asarray(odometry, float)
    if O is not None and O.shape != (n, 3):
        raise ValueError(f"odometry must have shape ({n}, 3), got {O.shape}")
    cams = col(cameras, "center", "cameras")
    conds = col(conditions, "default", "conditions")
    rns = col(runs, "0", "runs")
    frs = col(frames, None, "frames") if frames is not None else np.arange(n)
    ext = {k: col(v, None, f"extra column {k!r}") for k, v in (extra or {}).items()}
    if gyro is not None:
        if GYRO_COLUMN in ext:
            raise ValueError(f"give the gyro as gyro= or as extra[{GYRO_COLUMN!r}], not both")
        g = np.asarray(gyro)
        if g.dtype.kind not in "iuf" or g.shape != (n,):
            raise ValueError(f"gyro must be {n} numbers (rad, one per pose), got shape {g.shape} dtype {g.dtype}")
        ext[GYRO_COLUMN] = g.astype(float)
    it = iter(images)
    with DatasetWriter(path, metadata, overwrite=overwrite, extra_columns=list(ext), exact_stamps=ns is not None) as w:
        bar = progress_bar(progress, n, "writing")
        for i in range(n):
            try:
                img = next(it)
            except StopIteration:
                raise ValueError(f"got {i} images for {n} poses") from None
            w.add(img, frame=int(frs[i]), timestamp=float(ts[i]), pose=P[i],
                  odometry=None if O is None else O[i], camera=str(cams[i]), condition=str(conds[i]),
                  run=str(rns[i]), stamp_ns=None if ns is None else int(ns[i]), **{k: v[i] for k, v in ext.items()})
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        if next(it, None) is not None:
            raise ValueError(f"got more images than the {n} poses")
    return Dataset(path)


class Dataset:
    """A recording: images with poses, read lazily.

    ``Dataset(path)`` opens an sfanav dataset directory (``metadata.json`` +
    ``frames.csv``) or an insect-navigation image database
    (``database_entries.csv``). Real recordings with a separate pose log are
    imported with :meth:`from_recording`.

    Parameters
    ----------
    path : directory
    camera, condition, run : str, optional
        Keep only these images (same as :meth:`select`).

    Attributes
    ----------
    root : Path
        The dataset directory.
    metadata : dict
    columns : dict of str to ndarray (N,)
        Every column, including extra ones.
    """

    def __init__(self, path: str | os.PathLike, *, camera: str | None = None, condition: str | None = None,
                 run: str | None = None):
        root = Path(path)
        if not root.exists():
            raise FileNotFoundError(f"no dataset at {root}")
        if root.is_file():
            if root.name in ("frames.csv", "metadata.json", INSECT_ENTRIES):
                root = root.parent
            else:
                raise ValueError(f"{root} is a file; give the dataset directory")
        if (root / "frames.csv").exists() or (root / "metadata.json").exists():
            cols, meta = _read_sfanav(root)
        elif (root / INSECT_ENTRIES).exists():
            cols, meta = _read_insect(root)
        else:
            raise ValueError(
                f"{root} is not a dataset: expected metadata.json and frames.csv (sfanav format) "
                f"or {INSECT_ENTRIES} (insect-navigation image database)"
            )
        self._init(root, cols, meta)
        filt = {k: v for k, v in (("camera", camera), ("condition", condition), ("run", run)) if v is not None}
        if filt:
            sub = self.select(**filt)
            self._init(sub.root, sub.columns, sub.metadata)

    def _init(self, root: Path, cols: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
        self.root = root
        self.columns = cols
        self.metadata = meta

    @classmethod
    def _from_columns(cls, root: Path, cols: dict[str, np.ndarray], meta: dict[str, Any]) -> "Dataset":
        ds = object.__new__(cls)
        ds._init(root, cols, meta)
        return ds

    # ------------------------------------------------------------ table

    def __len__(self) -> int:
        return len(self.columns["frame"])

    def __repr__(self) -> str:
        cams = sorted(set(self.cameras.tolist()))
        conds = sorted(set(self.conditions.tolist()))
        runs = sorted(set(self.runs.tolist()))
        return (f"Dataset({str(self.root)!r}, {len(self)} images, runs={runs}, cameras={cams}, "
                f"conditions={conds[:5]}{'...' if len(conds) > 5 else ''})")

    @property
    def poses(self) -> np.ndarray:
        """Ground truth (N, 3): x (m), y (m), heading (rad)."""
        c = self.columns
        return np.column_stack([c["x"], c["y"], c["heading"]])

    @property
    def odometry(self) -> np.ndarray:
        """Odometry (N, 3): x (m), y (m), heading (rad); NaN where unknown."""
        c = self.columns
        return np.column_stack([c["odom_x"], c["odom_y"], c["odom_heading"]])

    @property
    def has_odometry(self) -> bool:
        return bool(len(self)) and bool(np.isfinite(self.odometry).all())

    @property
    def timestamps(self) -> np.ndarray:
        """(N,) seconds."""
        return self.columns["timestamp"]

    @property
    def stamps_ns(self) -> np.ndarray | None:
        """(N,) int64: the same times exactly, in nanoseconds (the ``stamp_ns``
        column: e.g. the header stamps of a ROS bag's images); None for a
        dataset without it (simulated ones, and all written before it existed)."""
        return self.columns.get(STAMP_COLUMN)

    @property
    def gyro(self) -> np.ndarray | None:
        """(N,) float: the heading integrated from a yaw gyro (rad, continuous,
        cumulative from each run's start; the ``gyro_heading`` column): the
        gyro's turn between two frames of a run is the difference of their
        values. None for a dataset without a gyro.

        Examples
        --------
        >>> ds = Dataset("survey")                     # doctest: +SKIP
        >>> turns = np.diff(ds.select(run="train").gyro)  # doctest: +SKIP
        """
        return self.columns.get(GYRO_COLUMN)

    @property
    def frames(self) -> np.ndarray:
        return self.columns["frame"]

    @property
    def cameras(self) -> np.ndarray:
        return self.columns["camera"]

    @property
    def conditions(self) -> np.ndarray:
        return self.columns["condition"]

    @property
    def runs(self) -> np.ndarray:
        return self.columns["run"]

    @property
    def image_paths(self) -> list[Path]:
        """Absolute path of each image."""
        return [Path(p) if os.path.isabs(p) else self.root / p for p in self.columns["image"]]

    def column(self, name: str) -> np.ndarray:
        """Any column by name (standard or extra)."""
        if name not in self.columns:
            raise KeyError(f"no column {name!r}; available: {', '.join(self.columns)}")
        return self.columns[name]

    def subset(self, indices: Any) -> "Dataset":
        """The images at ``indices`` (int array or boolean mask), in that order."""
        idx = np.asarray(indices)
        if idx.dtype == bool:
            if idx.shape != (len(self),):
                raise ValueError(f"boolean mask must have shape ({len(self)},), got {idx.shape}")
        elif idx.size and not np.issubdtype(idx.dtype, np.integer):
            raise TypeError("indices must be integers or a boolean mask")
        return Dataset._from_columns(self.root, {k: v[idx] for k, v in self.columns.items()}, self.metadata)

    def select(self, **filters: Any) -> "Dataset":
        """Images whose columns equal the given values, e.g.
        ``ds.select(run="train", camera="left")``; a list or tuple value
        keeps any of its values."""
        mask = np.ones(len(self), bool)
        for k, v in filters.items():
            col = self.column(k)
            vals = list(v) if isinstance(v, (list, tuple, set)) else [v]
            mask &= np.isin(col, np.array(vals, dtype=col.dtype if col.dtype != object else object))
        return self.subset(mask)

    # ------------------------------------------------------------ images

    def image(self, i: int, gray: bool = False, size: tuple[int, int] | None = None) -> np.ndarray:
        """Image ``i`` as uint8 (H, W, 3) RGB or (H, W) gray; ``size`` = (width, height)."""
        n = len(self)
        if not -n <= int(i) < n:
            raise IndexError(f"image index {i} out of range for {n} images")
        return read_image(self.image_paths[int(i)], gray, size)

    def images(self, batch_size: int | None = None, *, gray: bool = False, size: tuple[int, int] | None = None,
               indices: Any = None) -> Iterator[np.ndarray]:
        """Iterates over the images, reading them from disk as it goes.

        Parameters
        ----------
        batch_size : int, optional
            Yield arrays (n, H, W[, 3]) of up to ``batch_size`` images;
            default one image at a time.
        gray : bool
        size : (width, height), optional
            Resize every image (they must then share a size to be batched).
        indices : array, optional
            Only these images, in this order.
        """
        paths = self.image_paths
        idx = range(len(paths)) if indices is None else np.asarray(indices).reshape(-1)
        if batch_size is None:
            for i in idx:
                yield read_image(paths[int(i)], gray, size)
            return
        if isinstance(batch_size, bool) or not isinstance(batch_size, (int, np.integer)) or batch_size < 1:
            raise ValueError(f"batch_size must be a positive integer, got {batch_size!r}")
        buf: list[np.ndarray] = []
        for i in idx:
            img = read_image(paths[int(i)], gray, size)
            if buf and img.shape != buf[0].shape:
                raise ValueError(
                    f"image {paths[int(i)]} has shape {img.shape}, unlike {buf[0].shape} before it; "
                    "pass size=(width, height) or select one camera"
                )
            buf.append(img)
            if len(buf) == batch_size:
                yield np.stack(buf)
                buf = []
        if buf:
            yield np.stack(buf)

    def load_images(self, *, gray: bool = False, size: tuple[int, int] | None = None,
                    progress: bool = False) -> np.ndarray:
        """All images in one array (N, H, W[, 3]) uint8."""
        bar = progress_bar(progress, len(self), "reading")
        out = None
        for i, img in enumerate(self.images(gray=gray, size=size)):
            if out is None:
                out = np.empty((len(self),) + img.shape, np.uint8)
            elif img.shape != out.shape[1:]:
                raise ValueError(f"image {i} has shape {img.shape}, unlike {out.shape[1:]}; pass size=")
            out[i] = img
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        return out if out is not None else np.empty((0,), np.uint8)

    # ------------------------------------------------------------ real recordings

    @classmethod
    def from_recording(cls, images: str | os.PathLike, poses: str | os.PathLike, *,
                       out: str | os.PathLike | None = None, camera: str = "center", condition: str = "default",
                       run: str = "0", heading_unit: str = "rad", outside: str = "error",
                       overwrite: bool = False) -> "Dataset":
        """Imports a real recording: images with timestamps plus a separate
        pose log (e.g. from an external marker tracker); every image gets the
        pose linearly interpolated at its timestamp (thesis 4.2.2), the
        heading along the shorter arc.

        Parameters
        ----------
        images : path
            A CSV with columns ``timestamp`` (s) and ``image`` (path relative
            to the CSV's folder), or a directory of images whose file names
            (without extension) are their timestamps in seconds.
        poses : path
            CSV with columns ``timestamp, x, y, heading`` (s, m, m,
            ``heading_unit``), optionally ``odom_x, odom_y, odom_heading``;
            timestamps strictly increasing.
        out : path, optional
            Also write the result as an sfanav dataset there (images copied).
        heading_unit : ``"rad"`` or ``"deg"``
        outside : ``"error"`` or ``"drop"``
            What to do with images taken before the first or after the last pose.

        Raises
        ------
        FileNotFoundError for missing files; ValueError for bad rows,
        unsorted timestamps, or images outside the pose log's time span.
        """
        if heading_unit not in ("rad", "deg"):
            raise ValueError(f"heading_unit must be 'rad' or 'deg', got {heading_unit!r}")
        if outside not in ("error", "drop"):
            raise ValueError(f"outside must be 'error' or 'drop', got {outside!r}")
        img_t, img_paths, img_root = _read_image_log(Path(images))
        pose_cols = _read_csv_columns(Path(poses), required=("timestamp", "x", "y", "heading"),
                                      floats=("timestamp", "x", "y", "heading", "odom_x", "odom_y", "odom_heading"),
                                      what="pose log")
        pt = pose_cols["timestamp"]
        if len(pt) < 2:
            raise ValueError(f"pose log {poses} needs at least 2 rows to interpolate, got {len(pt)}")
        bad = np.nonzero(np.diff(pt) <= 0)[0]
        if len(bad):
            i = int(bad[0])
            raise ValueError(
                f"pose log {poses}: timestamps must increase strictly; row {i + 2} (t={float(pt[i + 1])!r}) "
                f"does not come after row {i + 1} (t={float(pt[i])!r}); sort the log"
            )
        bad = np.nonzero(np.diff(img_t) < 0)[0]
        if len(bad):
            i = int(bad[0])
            raise ValueError(
                f"image log {images}: timestamps must not decrease; image {img_paths[i + 1]} "
                f"(t={float(img_t[i + 1])!r}) comes after {img_paths[i]} (t={float(img_t[i])!r})"
            )
        inside = (img_t >= pt[0]) & (img_t <= pt[-1])
        if not inside.all():
            n_out = int((~inside).sum())
            if outside == "error":
                j = int(np.nonzero(~inside)[0][0])
                raise ValueError(
                    f"{n_out} image(s) lie outside the pose log's time span [{float(pt[0])}, {float(pt[-1])}] s, "
                    f"first {img_paths[j]} at t={float(img_t[j])}; pass outside='drop' to leave them out"
                )
            img_t = img_t[inside]
            img_paths = [p for p, k in zip(img_paths, inside) if k]
        if not len(img_t):
            raise ValueError("no image lies within the pose log's time span")
        scale = np.pi / 180 if heading_unit == "deg" else 1.0
        cols: dict[str, np.ndarray] = {
            "frame": np.arange(len(img_t)),
            "run": np.full(len(img_t), check_name(run, "run"), dtype=object),
            "timestamp": img_t,
            "x": np.interp(img_t, pt, pose_cols["x"]),
            "y": np.interp(img_t, pt, pose_cols["y"]),
            "heading": _interp_angle(img_t, pt, pose_cols["heading"] * scale),
        }
        if "odom_x" in pose_cols:
            cols["odom_x"] = np.interp(img_t, pt, pose_cols["odom_x"])
            cols["odom_y"] = np.interp(img_t, pt, pose_cols["odom_y"])
            cols["odom_heading"] = _interp_angle(img_t, pt, pose_cols["odom_heading"] * scale)
        else:
            cols["odom_x"] = cols["odom_y"] = cols["odom_heading"] = np.full(len(img_t), np.nan)
        cols["camera"] = np.full(len(img_t), check_name(camera, "camera"), dtype=object)
        cols["condition"] = np.full(len(img_t), check_name(condition, "condition"), dtype=object)
        cols["image"] = np.array([str(Path(p).resolve()) for p in img_paths], dtype=object)
        cols = {k: cols[k] for k in COLUMNS}
        meta = {"format": FORMAT, "version": VERSION, "units": UNITS, "source": "recording",
                "images": str(images), "poses": str(poses), "interpolation": "linear on timestamps"}
        ds = cls._from_columns(img_root, cols, meta)
        if out is None:
            return ds
        with DatasetWriter(out, {k: v for k, v in meta.items() if k not in ("format", "version", "units")},
                           overwrite=overwrite) as w:
            for i, src in enumerate(ds.image_paths):
                w.add_file(src, frame=i, timestamp=float(img_t[i]), run=cols["run"][i],
                           pose=(cols["x"][i], cols["y"][i], cols["heading"][i]),
                           odometry=(cols["odom_x"][i], cols["odom_y"][i], cols["odom_heading"][i]),
                           camera=cols["camera"][i], condition=cols["condition"][i])
        return Dataset(out)

    @classmethod
    def from_bag(cls, bag: str | os.PathLike | Sequence[str | os.PathLike], out: str | os.PathLike, *,
                 image_topic: str | None = None, odom_topic: str | None = None, pose_topic: str | None = None,
                 run: str | Sequence[str] | None = None,
                 camera: str = "center", condition: str = "default", time: str = "header",
                 outside: str = "error", max_gap: float = 1.0, overwrite: bool = False, progress: bool = False,
                 log: Any = None) -> "Dataset":
        """Imports a robot's recorded runs from ROS bags (one run per bag) as
        an sfanav dataset at ``out`` and returns it opened.

        Reads ROS 1 bags (``.bag``), ROS 2 bag folders (SQLite or MCAP) and
        single ``.db3`` / ``.mcap`` files with the pure-Python ``rosbags``
        (``pip install "sfanav[ros]"``; no ROS installation). Images are
        decoded (``sensor_msgs/Image`` in ``rgb8``, ``bgr8``, ``mono8``,
        ``rgba8``, ``bgra8``, ``mono16``, 8-bit Bayer (demosaiced);
        ``sensor_msgs/CompressedImage`` JPEG or PNG, kept as they are) and
        not altered otherwise:
        omnidirectional images stay omnidirectional for the unwarping of
        training and localization. Each image gets the odometry and the
        ground truth linearly interpolated at its timestamp, the heading (the
        quaternion's yaw) along the shorter arc, as :meth:`from_recording`
        does. The import streams (bounded memory) and is atomic: the
        dataset is written into a hidden folder beside ``out`` and renamed
        to ``out`` once complete, so a failed or interrupted import leaves
        nothing, and a dataset ``overwrite`` would replace stays until then.

        Parameters
        ----------
        bag : path or sequence of paths
            A ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap``
            file; several bags become several runs of one dataset (the
            topics and options apply to each).
        out : path
            The dataset to write (a new or empty folder, unless ``overwrite``).
        image_topic : str, optional
            ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage`` topic;
            default: the bag's only image topic.
        odom_topic : str, optional
            Wheel odometry (``nav_msgs/Odometry``, or a pose type): the
            ``odom_x, odom_y, odom_heading`` columns.
        pose_topic : str, optional
            Ground truth (``geometry_msgs/PoseStamped``,
            ``geometry_msgs/PoseWithCovarianceStamped`` or
            ``nav_msgs/Odometry``): the ``x, y, heading`` columns (empty
            without it). At least one of ``odom_topic`` and ``pose_topic``.
        run : str or sequence of str, optional
            The run's name (one per bag); default ``0`` for one bag, else the
            bags' file names without suffix.
        camera, condition : str
            Names of the images' camera and recording condition.
        time : ``"header"`` or ``"bag"``
            The messages' header stamps (default), or the times the bag
            recorded them (for drivers that leave the stamps at 0).
        outside : ``"error"``, ``"drop"`` or ``"empty"``
            What to do with images no pose covers (before a pose topic's first
            message, after its last, or in a gap between two messages longer
            than ``max_gap``): raise (default), leave them out, or keep them
            with that pose empty (NaN; never zeros).
        max_gap : float
            Longest interval (s) between two pose messages that is
            interpolated across (default 1).
        progress : bool
            A progress bar.
        log : callable, optional
            Receives the notes (gaps, images left out); default stderr.

        Returns
        -------
        Dataset
            Timestamps in seconds (the bag's clock) and the same stamps
            exactly as int64 nanoseconds (:attr:`stamps_ns`, the images'
            header stamps), positions in metres and headings in radians in
            the frames of the pose topics.

        Raises
        ------
        FileNotFoundError
            No bag at ``bag``.
        ValueError
            A missing topic, unsorted or missing (0) stamps, images no pose
            covers (``outside="error"``), a truncated or damaged bag; an
            image that does not decode (an unsupported encoding, data cut
            short) or whose size differs from the earlier images', named by
            its topic, index and stamp; ``out`` not empty (FileExistsError).
        TypeError
            A topic of the wrong message type.
        ImportError
            Without ``rosbags``.

        Examples
        --------
        >>> ds = Dataset.from_bag(["run1.bag", "run2.bag"], "garden", image_topic="/camera/image_raw",
        ...                       odom_topic="/odom", run=["train", "test"])  # doctest: +SKIP
        >>> ds.select(run="train").odometry.shape                           # doctest: +SKIP
        (5000, 3)
        """
        from .._progress import stderr_log
        from .rosbag import import_bag

        return import_bag(bag, out, image_topic=image_topic, odom_topic=odom_topic, pose_topic=pose_topic,
                          run=run, camera=camera, condition=condition, time=time, outside=outside,
                          max_gap=max_gap, overwrite=overwrite, progress=progress,
                          log=stderr_log if log is None else log)


def _interp_angle(t: np.ndarray, tp: np.ndarray, ang: np.ndarray) -> np.ndarray:
    """Linear interpolation of angles (rad) along the shorter arc, wrapped to [-pi, pi)."""
    return (np.interp(t, tp, np.unwrap(ang)) + np.pi) % (2 * np.pi) - np.pi


def _read_image_log(path: Path) -> tuple[np.ndarray, list[Path], Path]:
    if not path.exists():
        raise FileNotFoundError(f"no image log or image directory at {path}")
    if path.is_dir():
        exts = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm"}
        files = [p for p in path.iterdir() if p.suffix.lower() in exts]
        if not files:
            raise ValueError(f"image directory {path} holds no images")
        stamps = []
        for p in files:
            try:
                stamps.append(float(p.stem))
            except ValueError:
                raise ValueError(
                    f"image file name {p.name!r} is not a timestamp in seconds; name the files by their "
                    "timestamps or give a CSV with columns timestamp,image"
                ) from None
        order = np.argsort(stamps, kind="stable")
        return np.array(stamps)[order], [files[i] for i in order], path
    cols = _read_csv_columns(path, required=("timestamp",), floats=("timestamp",), what="image log")
    name = "image" if "image" in cols else "filename" if "filename" in cols else None
    if name is None:
        raise ValueError(f"image log {path} needs a column 'image' (or 'filename') with the image paths")
    paths = [Path(p) if os.path.isabs(p) else path.parent / p for p in cols[name]]
    for p in paths:
        if not p.exists():
            raise FileNotFoundError(f"image file {p} listed in {path} does not exist")
    return cols["timestamp"], paths, path.parent


def _read_csv_columns(path: Path, *, required: Sequence[str], floats: Sequence[str], what: str,
                      ints: Sequence[str] = (), nonempty: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """Columns of a CSV file; ``required`` columns must exist, ``nonempty``
    ones (default: the required ones) must have a value in every row."""
    nonempty = required if nonempty is None else nonempty
    if not path.exists():
        raise FileNotFoundError(f"no {what} at {path}")
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except UnicodeDecodeError as exc:
        raise ValueError(f"{what} {path} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except csv.Error as exc:
        raise ValueError(f"{what} {path} is not a CSV table ({exc})") from None
    if not rows:
        raise ValueError(f"{what} {path} is empty")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in required if c not in header]
    if missing:
        raise ValueError(f"{what} {path} lacks column(s) {', '.join(missing)} (has {', '.join(header)})")
    data: dict[str, list[Any]] = {h: [] for h in header}
    for ln, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise ValueError(f"{what} {path} line {ln}: {len(row)} fields, expected {len(header)}")
        for h, cell in zip(header, row):
            cell = cell.strip()
            if h in floats:
                try:
                    v = float(cell) if cell != "" else math.nan
                except ValueError:
                    raise ValueError(f"{what} {path} line {ln}: column {h!r} has {cell!r}, not a number") from None
                if cell != "" and not math.isfinite(v):
                    raise ValueError(f"{what} {path} line {ln}: column {h!r} is not finite ({cell!r})")
                if h in nonempty and cell == "":
                    raise ValueError(f"{what} {path} line {ln}: column {h!r} is empty")
                data[h].append(v)
            elif h in ints:
                try:
                    v = int(cell)
                except ValueError:
                    raise ValueError(f"{what} {path} line {ln}: column {h!r} has {cell!r}, not an integer") from None
                if not -INT64_MAX - 1 <= v <= INT64_MAX:
                    raise ValueError(f"{what} {path} line {ln}: column {h!r} has {cell}, out of the int64 range")
                data[h].append(v)
            else:
                data[h].append(cell)
    out: dict[str, np.ndarray] = {}
    for h, vals in data.items():
        if h in floats:
            out[h] = np.array(vals, float)
        elif h in ints:
            out[h] = np.array(vals, np.int64)
        else:
            out[h] = np.array(vals, dtype=object)
    return out


def _read_sfanav(root: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    mpath, fpath = root / "metadata.json", root / "frames.csv"
    if not mpath.exists():
        raise FileNotFoundError(f"dataset {root} has no metadata.json")
    if not fpath.exists():
        raise FileNotFoundError(f"dataset {root} has no frames.csv")
    try:
        meta = json.loads(mpath.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise ValueError(f"{mpath} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except RecursionError:
        raise ValueError(f"{mpath} nests too deeply to be dataset metadata") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{mpath} is not valid JSON: {exc}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ValueError(f"{mpath} is not sfanav dataset metadata (format {meta.get('format') if isinstance(meta, dict) else None!r})")
    version = meta.get("version", 0)
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ValueError(f"{mpath}: version must be a positive integer, got {version!r}")
    if version > VERSION:
        raise ValueError(f"dataset version {version} is newer than this sfanav reads ({VERSION}); upgrade sfanav")
    cols = _read_csv_columns(fpath, required=COLUMNS, floats=FLOAT_COLUMNS + (GYRO_COLUMN,),
                             ints=("frame", STAMP_COLUMN), what="frames table", nonempty=("timestamp",))
    gyro = cols.get(GYRO_COLUMN)
    if gyro is not None and not np.isfinite(gyro).all():
        i = int(np.nonzero(~np.isfinite(gyro))[0][0])
        raise ValueError(f"frames table {fpath} line {i + 2}: column {GYRO_COLUMN!r} is empty; the gyro's heading "
                         "(rad) must be given in every row")
    ns = cols.get(STAMP_COLUMN)
    if ns is not None:
        bad = np.nonzero((ns < 0) | stamps_disagree(cols["timestamp"], ns))[0]
        if len(bad):
            i = int(bad[0])
            raise ValueError(f"frames table {fpath} line {i + 2}: " + (
                f"stamp_ns {int(ns[i])} is negative" if ns[i] < 0 else
                f"timestamp {float(cols['timestamp'][i])!r} s and stamp_ns {int(ns[i])} ({int(ns[i]) / 1e9!r} s) "
                "disagree; they are one time, in seconds and in integer nanoseconds"))
    # x, y, heading (ground truth) and the odometry may be empty: a robot's own runs have no ground truth
    # timestamps must not decrease within one run, camera and condition
    groups: dict[tuple[str, str, str], list[int]] = {}
    for i, key in enumerate(zip(cols["run"], cols["camera"], cols["condition"])):
        groups.setdefault(key, []).append(i)
    for (run, cam, cond), idx_list in groups.items():
        idx = np.array(idx_list)
        bad = np.nonzero(np.diff(cols["timestamp"][idx]) < 0)[0]
        if len(bad):
            i = int(idx[bad[0] + 1])
            raise ValueError(
                f"frames table {fpath} line {i + 2}: timestamp {float(cols['timestamp'][i])!r} is earlier than the "
                f"previous image of run {run!r}, camera {cam!r}, condition {cond!r}; timestamps must be sorted"
            )
        bad = np.nonzero(np.diff(ns[idx]) < 0)[0] if ns is not None else []
        if len(bad):
            i = int(idx[bad[0] + 1])
            raise ValueError(
                f"frames table {fpath} line {i + 2}: stamp_ns {int(ns[i])} is earlier than the previous image of "
                f"run {run!r}, camera {cam!r}, condition {cond!r}; timestamps must be sorted"
            )
    seen: dict[tuple[int, str], int] = {}
    for i, (frame, cam) in enumerate(zip(cols["frame"], cols["camera"])):
        if frame < 0:
            raise ValueError(f"frames table {fpath} line {i + 2}: frame {int(frame)} is negative")
        first = seen.setdefault((int(frame), cam), i)
        if first != i:
            raise ValueError(f"frames table {fpath} line {i + 2}: frame {int(frame)} of camera {cam!r} "
                             f"repeats line {first + 2}")
    for i, rel in enumerate(cols["image"]):
        if not rel:
            raise ValueError(f"frames table {fpath} line {i + 2}: empty image path")
        p = root / rel
        if os.path.isabs(rel) or os.path.normpath(rel).split(os.sep)[0] == os.pardir:
            raise ValueError(f"frames table {fpath} line {i + 2}: image path {rel!r} lies outside the dataset")
        if not p.is_file():
            raise FileNotFoundError(f"dataset {root} is incomplete: {rel} (frames table line {i + 2}) does not exist")
    expected = meta.get("n_images")
    if expected is not None and (isinstance(expected, bool) or not isinstance(expected, int)
                                 or expected != len(cols["image"])):
        raise ValueError(f"dataset {root} is incomplete or altered: {mpath.name} says {expected!r} images, "
                         f"{fpath.name} has {len(cols['image'])} rows")
    for k in cols:
        if k not in COLUMNS and k not in (STAMP_COLUMN, GYRO_COLUMN):
            cols[k] = _infer(cols[k])
    return cols, meta


def _infer(values: np.ndarray) -> np.ndarray:
    """An extra column as integers, else floats (empty = NaN), else strings."""
    try:
        return np.array([int(v) for v in values], np.int64)
    except ValueError:
        pass
    try:
        return np.array([float(v) if v != "" else math.nan for v in values], float)
    except ValueError:
        return values


def _read_insect(root: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    epath = root / INSECT_ENTRIES
    need = ("X [mm]", "Y [mm]", "Z [mm]", "Heading [degrees]", "Filename")
    fl = ("X [mm]", "Y [mm]", "Z [mm]", "Heading [degrees]", "Timestamp [ms]")
    cols = _read_csv_columns(epath, required=need, floats=fl, what="database entries")
    n = len(cols["Filename"])
    meta: dict[str, Any] = {"format": FORMAT, "version": VERSION, "units": UNITS,
                            "source": "insect-navigation image database"}
    mpath = root / INSECT_METADATA
    if mpath.exists():
        try:
            import yaml
        except ImportError as exc:  # pragma: no cover - a declared dependency
            raise ImportError(f"reading {INSECT_METADATA} needs PyYAML (pip install pyyaml)") from exc
        text = mpath.read_text()
        # OpenCV FileStorage writes a "%YAML:1.0" directive that PyYAML rejects
        lines = [ln for ln in text.splitlines() if not ln.startswith("%YAML")]
        try:
            doc = yaml.safe_load("\n".join(lines)) or {}
        except yaml.YAMLError as exc:
            raise ValueError(f"{mpath} is not valid YAML: {exc}") from None
        meta["database_metadata"] = doc.get("metadata", doc) if isinstance(doc, dict) else doc
    t = cols["Timestamp [ms]"] / 1000.0 if "Timestamp [ms]" in cols else np.arange(n, dtype=float)
    for name in ("X [mm]", "Y [mm]", "Heading [degrees]"):
        bad = np.nonzero(~np.isfinite(cols[name]))[0]
        if len(bad):
            raise ValueError(f"database entries {epath} line {int(bad[0]) + 2}: {name!r} is empty")
    dbm = meta.get("database_metadata")
    kind = dbm.get("type") if isinstance(dbm, dict) else None
    out: dict[str, np.ndarray] = {
        "frame": np.arange(n),
        "run": np.full(n, str(kind) if kind else "0", dtype=object),
        "timestamp": t,
        "x": cols["X [mm]"] / 1000.0,
        "y": cols["Y [mm]"] / 1000.0,
        "heading": np.radians(cols["Heading [degrees]"]),
        "odom_x": np.full(n, np.nan),
        "odom_y": np.full(n, np.nan),
        "odom_heading": np.full(n, np.nan),
        "camera": np.full(n, "center", dtype=object),
        "condition": np.full(n, "default", dtype=object),
        "image": cols["Filename"],
        "z": cols["Z [mm]"] / 1000.0,
    }
    for g in ("Grid X", "Grid Y", "Grid Z"):
        if g in cols:
            try:
                out[g.lower().replace(" ", "_")] = cols[g].astype(np.int64)
            except ValueError:
                raise ValueError(f"database entries {epath}: column {g!r} must hold integers") from None
    for i, f in enumerate(out["image"]):
        if not f:
            raise ValueError(f"database entries {epath} line {i + 2}: empty Filename")
    return out, meta
