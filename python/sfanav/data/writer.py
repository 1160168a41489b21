"""Writing sfanav datasets: :class:`DatasetWriter` streams images and their
rows, :func:`write_dataset` writes a whole run at once. A dataset is complete
only once its ``metadata.json`` exists, which is written last (atomically,
with the number of images the reader checks); a writer left by an exception
(an interrupted ``sfanav simulate``, say) writes none, so the folder is not
taken for a dataset. A staged writer (``staged=True``, what ``sfanav
import`` uses) goes further: it writes into a hidden folder beside the
destination and moves it into place only when complete, so an error leaves
nothing, and a dataset it replaces stays until then."""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import check_int
from .._files import write_text_atomic
from .images import write_image
from .schema import (
    COLUMNS,
    FORMAT,
    GYRO_COLUMN,
    GYRO_UNITS,
    INT64_MAX,
    OPTIONAL_COLUMNS,
    STAMP_UNITS,
    UNITS,
    VERSION,
    check_name,
    columns_of,
    format_float,
    stamps_disagree,
)


class DatasetWriter:
    """Writes an sfanav dataset image by image (rows are streamed to
    ``frames.csv``; ``metadata.json`` is written on :meth:`close`).

    Parameters
    ----------
    path : directory to create
    metadata : dict, optional
        Extra metadata (JSON-able), e.g. world, cameras, conditions.
    overwrite : bool
        Replace an existing dataset at ``path`` (refused otherwise).
    extra_columns : sequence of str
        Names of extra per-image columns given to :meth:`add`. The optional
        gyro column ``gyro_heading`` (rad, cumulative) is one of them; its
        values must then be finite numbers.
    exact_stamps : bool
        The dataset has the column ``stamp_ns``: every row's time as an
        integer count of nanoseconds (given to :meth:`add` as ``stamp_ns``,
        the same time as ``timestamp``, which stays float seconds).
    staged : bool
        Write into a hidden temporary folder beside ``path``
        (``.NAME.part-XXXX``) and move it to ``path`` on :meth:`close`: an
        error or an interrupt (:meth:`abort`) removes it and leaves ``path``
        as it was, so a dataset that ``overwrite`` replaces is kept until
        the new one is complete. Without it, files are written to ``path``
        directly (which callers writing files of their own beside the
        dataset, as the simulator's ``world.json``, rely on).

    Attributes
    ----------
    path : Path
        The dataset's destination.
    folder : Path
        Where the files are written while the writer is open: ``path``, or
        the temporary folder of a staged writer.

    Examples
    --------
    >>> with DatasetWriter("out") as w:                       # doctest: +SKIP
    ...     w.add(img, frame=0, timestamp=0.0, pose=(0, 0, 0))
    >>> with DatasetWriter("bag-run", exact_stamps=True) as w:  # doctest: +SKIP
    ...     w.add(img, frame=0, timestamp=ns / 1e9, stamp_ns=ns, pose=(0, 0, 0))
    """

    def __init__(self, path: str | os.PathLike, metadata: dict[str, Any] | None = None, *,
                 overwrite: bool = False, extra_columns: Sequence[str] = (), exact_stamps: bool = False,
                 staged: bool = False):
        self.path = Path(path)
        self.metadata = dict(metadata or {})
        json.dumps(self.metadata)  # fail early on non-JSON metadata
        self.extra = [check_name(c, "extra column name") for c in extra_columns]
        clash = set(self.extra) & set(COLUMNS + OPTIONAL_COLUMNS)
        if clash:
            raise ValueError(f"extra columns {sorted(clash)} clash with the standard columns")
        self.exact_stamps = bool(exact_stamps)
        self._overwrite = overwrite
        self._replace = _check_destination(self.path, overwrite)
        if staged:
            # beside the destination (a symbolic link's target), so that the final move is a rename
            dest = self.path.resolve() if self.path.is_symlink() else self.path
            dest.parent.mkdir(parents=True, exist_ok=True)
            self.folder = Path(tempfile.mkdtemp(prefix=f".{dest.name}.part-", dir=dest.parent))
            self._dest: Path | None = dest
        else:
            if self._replace:
                shutil.rmtree(self.path)
            self.folder = self.path
            self._dest = None
        try:
            (self.folder / "images").mkdir(parents=True, exist_ok=True)
            self._file = open(self.folder / "frames.csv", "w", newline="")
        except BaseException:
            if self._dest is not None:
                shutil.rmtree(self.folder, ignore_errors=True)
            raise
        self._csv = csv.writer(self._file)
        self._csv.writerow(list(columns_of(self.exact_stamps)) + self.extra)
        self._seen: set[tuple[int, str]] = set()
        self.count = 0
        self._shapes: dict[str, list[int]] = {}

    def add(self, image: np.ndarray, *, frame: int, timestamp: float, pose: Sequence[float],
            odometry: Sequence[float] | None = None, camera: str = "center", condition: str = "default",
            run: str = "0", stamp_ns: int | None = None, **extra: Any) -> str:
        """Writes one image (PNG) and its row; returns the image's relative path.
        ``pose`` and ``odometry`` are (x m, y m, heading rad), finite;
        ``stamp_ns`` the exact time in integer ns (required with
        ``exact_stamps``, refused without)."""
        key, camera, condition, run, t = self._check_row(frame, timestamp, stamp_ns, camera, condition, run, extra)
        x, y, th = _triple(pose, "pose")
        odo = _triple(odometry, "odometry") if odometry is not None else (math.nan,) * 3
        rel = f"images/{int(frame):06d}_{camera}.png"
        img = np.asarray(image)
        write_image(self.folder / rel, img)
        self._shapes.setdefault(camera, list(img.shape))
        self._write_row(key, run, t, (x, y, th), odo, condition, rel, extra)
        return rel

    def add_file(self, source: str | os.PathLike, *, frame: int, timestamp: float, pose: Sequence[float],
                 odometry: Sequence[float] | None = None, camera: str = "center", condition: str = "default",
                 run: str = "0", stamp_ns: int | None = None, **extra: Any) -> str:
        """Copies an existing image file (any format OpenCV reads, kept as it
        is) into the dataset with its row; returns its relative path. Pose and
        odometry entries may be NaN (unknown, written as empty cells)."""
        src = Path(source)
        if not src.exists():
            raise FileNotFoundError(f"image file {src} does not exist")
        key, camera, condition, run, t = self._check_row(frame, timestamp, stamp_ns, camera, condition, run, extra)
        pose_v = _triple(pose, "pose", allow_nan=True)
        odo = _triple(odometry, "odometry", allow_nan=True) if odometry is not None else (math.nan,) * 3
        rel = f"images/{int(frame):06d}_{camera}{src.suffix.lower()}"
        shutil.copy2(src, self.folder / rel)
        self._write_row(key, run, t, pose_v, odo, condition, rel, extra)
        return rel

    def add_encoded(self, data: bytes, suffix: str, *, shape: Sequence[int], frame: int, timestamp: float,
                    pose: Sequence[float], odometry: Sequence[float] | None = None, camera: str = "center",
                    condition: str = "default", run: str = "0", stamp_ns: int | None = None, **extra: Any) -> str:
        """Writes an image that is already an image file's bytes (``suffix``
        ``.png`` or ``.jpg``, e.g. a compressed camera message kept as it is)
        with its row; ``shape`` is the decoded image's shape. Pose and
        odometry entries may be NaN (unknown, written as empty cells).
        Returns the image's relative path."""
        if suffix not in (".png", ".jpg"):
            raise ValueError(f"suffix must be '.png' or '.jpg', got {suffix!r}")
        key, camera, condition, run, t = self._check_row(frame, timestamp, stamp_ns, camera, condition, run, extra)
        pose_v = _triple(pose, "pose", allow_nan=True)
        odo = _triple(odometry, "odometry", allow_nan=True) if odometry is not None else (math.nan,) * 3
        rel = f"images/{int(frame):06d}_{camera}{suffix}"
        with open(self.folder / rel, "wb") as f:
            f.write(data)
        self._shapes.setdefault(camera, [int(s) for s in shape])
        self._write_row(key, run, t, pose_v, odo, condition, rel, extra)
        return rel

    def _check_row(self, frame: Any, timestamp: Any, stamp_ns: Any, camera: Any, condition: Any, run: Any,
                   extra: dict[str, Any]) -> tuple[tuple[int, str], str, str, str, tuple[float, int | None]]:
        if self._file.closed:
            raise ValueError("this DatasetWriter is closed")
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or frame < 0:
            raise ValueError(f"frame must be a non-negative integer, got {frame!r}")
        camera = check_name(camera, "camera")
        condition = check_name(condition, "condition")
        run = check_name(run, "run")
        key = (int(frame), camera)
        if key in self._seen:
            raise ValueError(f"frame {frame} of camera {camera!r} was already written")
        t = float(timestamp)
        if not math.isfinite(t):
            raise ValueError(f"timestamp must be finite, got {timestamp!r}")
        ns = None
        if stamp_ns is not None:
            if not self.exact_stamps:
                raise ValueError("stamp_ns given, but the writer has no exact stamps; pass exact_stamps=True")
            ns = check_int(stamp_ns, "stamp_ns", minimum=0)
            if ns > INT64_MAX:
                raise ValueError(f"stamp_ns must fit an int64 (ns), got {ns}")
            if stamps_disagree(t, ns):
                raise ValueError(f"timestamp {t!r} s and stamp_ns {ns} ({ns / 1e9!r} s) disagree; they are one "
                                 "time, in seconds and in integer nanoseconds")
        elif self.exact_stamps:
            raise ValueError("this writer has exact stamps (exact_stamps=True): give stamp_ns (integer ns) with "
                             "every image")
        unknown = set(extra) - set(self.extra)
        if unknown:
            raise ValueError(f"unknown extra columns {sorted(unknown)}; declare them in extra_columns")
        if GYRO_COLUMN in self.extra:
            g = extra.get(GYRO_COLUMN)
            if isinstance(g, (bool, np.bool_)) or not isinstance(g, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(g):
                raise ValueError(f"{GYRO_COLUMN} (the gyro's heading, rad) must be a finite number in every row, "
                                 f"got {g!r}")
        return key, camera, condition, run, (t, ns)

    def _write_row(self, key: tuple[int, str], run: str, t: tuple[float, int | None], pose: Sequence[float],
                   odo: Sequence[float], condition: str, rel: str, extra: dict[str, Any]) -> None:
        self._seen.add(key)
        times = [repr(t[0])] + ([str(t[1])] if self.exact_stamps else [])
        self._csv.writerow([key[0], run, *times, *(format_float(v) for v in pose), *(format_float(v) for v in odo),
                            key[1], condition, rel] + [_cell(extra.get(c)) for c in self.extra])
        self.count += 1

    def close(self) -> None:
        """Completes the dataset: writes ``metadata.json`` and, for a staged
        writer, moves the dataset to ``path`` (replacing the one there)."""
        if self._file.closed:
            return
        self._file.close()
        units = {**UNITS, **STAMP_UNITS} if self.exact_stamps else dict(UNITS)
        if GYRO_COLUMN in self.extra:
            units = {**units, **GYRO_UNITS}
        meta = {"format": FORMAT, "version": VERSION, "units": units, "n_images": self.count,
                "image_shapes": self._shapes, **self.metadata}
        try:
            write_text_atomic(self.folder / "metadata.json", json.dumps(meta, indent=1, default=_json_default))
            if self._dest is not None:
                _move_into_place(self.folder, self._dest, self._overwrite)
        except BaseException:
            self._discard()
            raise

    def abort(self) -> None:
        """Stops writing without completing the dataset: ``frames.csv`` is
        closed and no ``metadata.json`` is written, so readers refuse it; a
        staged writer removes its temporary folder (``path`` stays as it was)."""
        if not self._file.closed:
            self._file.close()
            self._discard()

    def _discard(self) -> None:
        if self._dest is not None:
            shutil.rmtree(self.folder, ignore_errors=True)

    def __enter__(self) -> "DatasetWriter":
        return self

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        if exc_type is None:
            self.close()
        else:  # an error or an interrupt: the dataset is incomplete
            self.abort()


def _check_destination(path: Path, overwrite: bool) -> bool:
    """Whether ``path`` holds a dataset to replace (refusing what must not
    be replaced); False for a new or empty folder."""
    if not path.exists():
        return False
    if not path.is_dir():
        raise FileExistsError(f"{path} exists and is not a directory")
    if not any(path.iterdir()):
        return False
    if not overwrite:
        raise FileExistsError(f"{path} is not empty; pass overwrite=True (--overwrite) to replace it")
    if not (path / "metadata.json").exists() and not (path / "frames.csv").exists():
        raise FileExistsError(f"{path} is not empty and not an sfanav dataset; refusing to overwrite it")
    return True


def _move_into_place(folder: Path, dest: Path, overwrite: bool) -> None:
    """Renames the complete dataset ``folder`` to ``dest``; a dataset at
    ``dest`` is renamed aside first and removed once the new one is in place
    (put back if the rename fails). Between the two renames ``dest`` is
    briefly absent: a rename cannot swap two folders."""
    if not _check_destination(dest, overwrite):  # checked again: the folder may have changed meanwhile
        if dest.is_dir():
            dest.rmdir()  # empty: nothing is lost
        os.rename(folder, dest)
        return
    aside = Path(tempfile.mkdtemp(prefix=f".{dest.name}.old-", dir=dest.parent))
    aside.rmdir()
    os.rename(dest, aside)
    try:
        os.rename(folder, dest)
    except BaseException:
        os.rename(aside, dest)
        raise
    shutil.rmtree(aside, ignore_errors=True)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.integer, np.floating, np.bool_)):
        return o.item()
    raise TypeError(f"metadata value of type {type(o).__name__} is not JSON-able")


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, (float, np.floating)):
        return format_float(float(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return check_name(v, "extra value")


def _triple(v: Any, what: str, *, allow_nan: bool = False) -> tuple[float, float, float]:
    try:
        a, b, c = (float(e) for e in v)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be (x m, y m, heading rad), got {v!r}") from None
    if not all(math.isfinite(e) or (allow_nan and math.isnan(e)) for e in (a, b, c)):
        raise ValueError(f"{what} must be finite, got {v!r}")
    return a, b, c
