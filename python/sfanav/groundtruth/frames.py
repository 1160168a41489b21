"""The external camera's recording as timestamped frames: a video file, a
folder of images named by their timestamps, or a CSV ``timestamp,image``
(the image logs :meth:`sfanav.data.Dataset.from_recording` reads)."""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..data.images import read_image

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
TIMESTAMPS = ("index", "msec")


@dataclass
class FrameSource:
    """Timestamped gray frames, read lazily: iterating yields
    ``(timestamp s, uint8 (H, W))`` in recording order.

    Attributes
    ----------
    description : str
        What was opened, for messages.
    n : int or None
        The number of frames if known (a video's count is OpenCV's estimate).
    """

    description: str
    n: int | None
    _iter: Any

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        return self._iter()

    def __len__(self) -> int:
        if self.n is None:
            raise TypeError(f"the number of frames of {self.description} is unknown")
        return self.n


def open_frames(path: str | os.PathLike, *, fps: float | None = None, timestamps: str = "index") -> FrameSource:
    """Opens a recording of the external camera.

    Parameters
    ----------
    path : path
        A video file (anything ``cv2.VideoCapture`` decodes), a folder of
        images whose file names (without extension) are their timestamps in
        seconds, or a CSV with columns ``timestamp`` (s) and ``image`` (path
        relative to the CSV's folder).
    fps : float, optional
        Videos: frame rate for the timestamps (default: the video's own).
    timestamps : ``"index"`` or ``"msec"``
        Videos: ``index / fps`` (default), or the position OpenCV reports
        for each frame (``CAP_PROP_POS_MSEC``, for variable frame rates).

    Raises
    ------
    FileNotFoundError
        If ``path`` or an image listed in the CSV does not exist.
    ValueError
        For a video without frames or frame rate, an empty folder, file names
        that are not timestamps, or a bad CSV.

    Examples
    --------
    >>> for t, gray in open_frames("camera.mp4"):                   # doctest: +SKIP
    ...     print(t, gray.shape)
    """
    if timestamps not in TIMESTAMPS:
        raise ValueError(f"timestamps must be 'index' or 'msec', got {timestamps!r}")
    if fps is not None and not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a number > 0, got {fps!r}")
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no video, image folder or image list at {p}")
    if p.is_dir():
        return _folder(p)
    if p.suffix.lower() == ".csv":
        return _image_list(p)
    return _video(p, fps, timestamps)


def _images(pairs: list[tuple[float, Path]]) -> Iterator[tuple[float, np.ndarray]]:
    for t, f in pairs:
        yield t, read_image(f, gray=True)


def _folder(p: Path) -> FrameSource:
    files = [f for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES]
    if not files:
        raise ValueError(f"image folder {p} holds no images ({', '.join(IMAGE_SUFFIXES)})")
    pairs = []
    for f in files:
        try:
            t = float(f.stem)
        except ValueError:
            raise ValueError(f"image file name {f.name!r} is not a timestamp in seconds; name the files by their "
                             "timestamps (e.g. 12.040.png) or give a CSV with columns timestamp,image") from None
        if not math.isfinite(t):
            raise ValueError(f"image file name {f.name!r} is not a finite timestamp")
        pairs.append((t, f))
    pairs.sort(key=lambda tf: tf[0])
    _check_increasing([t for t, _ in pairs], [f.name for _, f in pairs], f"image folder {p}")
    return FrameSource(f"image folder {p} ({len(pairs)} images)", len(pairs), lambda: _images(pairs))


def _image_list(p: Path) -> FrameSource:
    try:
        with open(p, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"image list {p} is not a UTF-8 CSV table ({exc})") from None
    if not rows or "timestamp" not in rows[0] or "image" not in rows[0]:
        raise ValueError(f"image list {p} needs columns timestamp,image and at least one row")
    pairs = []
    for ln, row in enumerate(rows, start=2):
        try:
            t = float(row["timestamp"])
        except (TypeError, ValueError):
            raise ValueError(f"image list {p} line {ln}: timestamp {row['timestamp']!r} is not a number") from None
        if not math.isfinite(t):
            raise ValueError(f"image list {p} line {ln}: timestamp {row['timestamp']!r} is not finite")
        img = Path(row["image"] or "")
        img = img if img.is_absolute() else p.parent / img
        if not img.is_file():
            raise FileNotFoundError(f"image {img} listed in {p} line {ln} does not exist")
        pairs.append((t, img))
    _check_increasing([t for t, _ in pairs], [f"line {i + 2}" for i in range(len(pairs))], f"image list {p}")
    return FrameSource(f"image list {p} ({len(pairs)} images)", len(pairs), lambda: _images(pairs))


def _check_increasing(ts: list[float], names: list[str], what: str) -> None:
    for i in range(1, len(ts)):
        if ts[i] <= ts[i - 1]:
            raise ValueError(f"{what}: timestamps must increase strictly; {names[i]} (t={ts[i]}) does not come "
                             f"after {names[i - 1]} (t={ts[i - 1]})")


def _video(p: Path, fps: float | None, timestamps: str) -> FrameSource:
    import cv2

    cap = cv2.VideoCapture(str(p))
    try:
        if not cap.isOpened():
            raise ValueError(f"{p} is not a video OpenCV can read (nor an image folder or a .csv image list)")
        ok, _ = cap.read()
        if not ok:
            raise ValueError(f"video {p} has no frames OpenCV can decode")
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        rate = fps if fps is not None else float(cap.get(cv2.CAP_PROP_FPS) or 0)
    finally:
        cap.release()
    if timestamps == "index" and not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"video {p} does not state its frame rate; pass fps= (--fps)")

    def frames() -> Iterator[tuple[float, np.ndarray]]:
        cap = cv2.VideoCapture(str(p))
        try:
            i = 0
            last = -math.inf
            while True:
                ok, frame = cap.read()
                if not ok:
                    break
                if timestamps == "msec":
                    t = float(cap.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0
                    if not t > last:
                        raise ValueError(f"video {p}: frame {i} has position {t} s, not after {last} s; "
                                         "use timestamps='index'")
                else:
                    t = i / rate
                last = t
                gray = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
                yield t, gray
                i += 1
        finally:
            cap.release()

    return FrameSource(f"video {p} ({count or 'unknown number of'} frames)", count or None, frames)
