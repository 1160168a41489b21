"""Where images to train on or to localize come from: a dataset directory
(sfanav format or an insect-navigation database), a folder of images or a
video, as one :class:`ImageSource` (:func:`open_images`); :func:`select_run`
and :func:`load_run` read one run of a dataset into memory, preprocessed."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import check_int
from .._progress import Log, progress_bar, stderr_log
from .dataset import Dataset
from .images import read_image
from .preprocessing import Preprocessing, Preprocessor

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")


VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv")


@dataclass
class ImageSource:
    """Images to localize: ``batches(batch_size)`` yields uint8 arrays in
    order; ``frames`` are their ids (dataset frame ids, else 0, 1, ...);
    ``xy`` the ground truth (datasets only, else None; NaN where unknown);
    ``odometry`` the odometry poses (N, 3) (datasets only, else None; NaN
    where unknown); ``timestamps`` the images' times in seconds (datasets
    only, else None; :meth:`times` also covers videos); ``stamps_ns`` the
    same times exactly, int64 nanoseconds (datasets with a ``stamp_ns``
    column, e.g. imported from a bag, else None); ``fps`` a video's frame
    rate; ``n`` the count if known."""

    kind: str
    description: str
    n: int | None
    frames: np.ndarray | None
    xy: np.ndarray | None
    _batches: Callable[[int], Iterator[np.ndarray]]
    odometry: np.ndarray | None = None
    timestamps: np.ndarray | None = None
    fps: float | None = None
    stamps_ns: np.ndarray | None = None

    def batches(self, batch_size: int = 64) -> Iterator[np.ndarray]:
        return self._batches(check_int(batch_size, "batch_size"))

    def times(self, n: int) -> np.ndarray | None:
        """The times (s) of the first ``n`` images: a dataset's timestamps, a
        video's frame index / frame rate, else None (an image folder)."""
        if self.timestamps is not None:
            return self.timestamps[:n]
        if self.fps:
            return np.arange(n) / self.fps
        return None


def _is_dataset_dir(p: Path) -> bool:
    return any((p / f).exists() for f in ("frames.csv", "metadata.json", "database_entries.csv"))


def _one_camera(ds: Dataset, camera: str | None) -> Dataset:
    if camera is not None:
        if camera not in set(ds.cameras.tolist()):
            raise ValueError(f"no camera {camera!r} in {ds.root}; cameras: {', '.join(sorted(set(ds.cameras.tolist())))}")
        return ds.select(camera=camera)
    cams = sorted(set(ds.cameras.tolist()))
    if len(cams) > 1:
        if "center" in cams:
            return ds.select(camera="center")
        raise ValueError(f"{ds.root} has several cameras ({', '.join(cams)}); choose one with --camera")
    return ds


def select_run(ds: Dataset, run: str | None, camera: str | None = None) -> Dataset:
    """The images of one run (all if ``run`` is None) and one camera."""
    if run is not None:
        runs = sorted(set(ds.runs.tolist()))
        if run not in runs:
            raise ValueError(f"no run {run!r} in {ds.root}; runs: {', '.join(runs)}")
        ds = ds.select(run=run)
    ds = _one_camera(ds, camera)
    if len(ds) == 0:
        raise ValueError(f"no images in {ds.root} for run {run!r}")
    return ds


def open_images(path: str | os.PathLike, *, run: str | None = None, camera: str | None = None) -> ImageSource:
    """A dataset directory (sfanav format or an insect-navigation database),
    a folder of images (``.png``, ``.jpg``, ..., in sorted name order) or a
    video file (read with ``cv2.VideoCapture``) as an :class:`ImageSource`.
    ``run`` and ``camera`` filter a dataset."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no such file or directory: {p}")
    if p.is_dir():
        if _is_dataset_dir(p):
            ds = select_run(Dataset(p), run, camera)
            gray = False

            def ds_batches(bs: int) -> Iterator[np.ndarray]:
                return ds.images(batch_size=bs, gray=gray)

            return ImageSource("dataset", f"dataset {p} ({len(ds)} images)", len(ds), ds.frames.copy(),
                               ds.poses[:, :2].copy(), ds_batches, ds.odometry.copy(), ds.timestamps.astype(float),
                               stamps_ns=None if ds.stamps_ns is None else ds.stamps_ns.copy())
        if run is not None:
            raise ValueError(f"--run applies to datasets; {p} is an image folder")
        files = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise ValueError(f"{p} holds no images ({', '.join(IMAGE_SUFFIXES)}) and is not a dataset")

        def folder_batches(bs: int) -> Iterator[np.ndarray]:
            buf: list[np.ndarray] = []
            for f in files:
                img = read_image(f)
                if buf and img.shape != buf[0].shape:
                    raise ValueError(f"image {f} has shape {img.shape}, unlike {buf[0].shape} before it")
                buf.append(img)
                if len(buf) == bs:
                    yield np.stack(buf)
                    buf = []
            if buf:
                yield np.stack(buf)

        return ImageSource("folder", f"image folder {p} ({len(files)} images)", len(files),
                           np.arange(len(files)), None, folder_batches)
    if run is not None:
        raise ValueError(f"--run applies to datasets; {p} is a file")
    import cv2

    cap = cv2.VideoCapture(str(p))
    ok = cap.isOpened()
    count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0) if ok else 0
    fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0) if ok else 0.0
    cap.release()
    if not ok:
        raise ValueError(f"{p} is not a dataset, an image folder or a video OpenCV can read")

    def video_batches(bs: int) -> Iterator[np.ndarray]:
        cap = cv2.VideoCapture(str(p))
        buf: list[np.ndarray] = []
        try:
            while True:
                ok, frame = cap.read()
                if not ok:
                    break
                buf.append(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB) if frame.ndim == 3 else frame)
                if len(buf) == bs:
                    yield np.stack(buf)
                    buf = []
        finally:
            cap.release()
        if buf:
            yield np.stack(buf)

    return ImageSource("video", f"video {p} (~{count} frames)", count or None, None, None, video_batches,
                       fps=fps if 0 < fps < 10_000 else None)


def load_run(ds: Dataset, prep: Preprocessing, *, mirror: Any = None, log: Log = stderr_log,
             progress: bool = False, batch_size: int = 64,
             preprocessor: Preprocessor | None = None, jitter: float = 0.0,
             seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """All images of a (one-camera) dataset as the network's input array and
    their positions (N, 2) in metres.

    The images are converted by ``preprocessor``, or by a new
    :class:`Preprocessor` with ``mirror``, ``jitter`` (centre jitter in
    pixels for omnidirectional images: a training augmentation) and
    ``seed``; giving both a preprocessor and a jitter is a ValueError.

    Examples
    --------
    >>> X, xy = load_run(ds.select(run="train"), prep, jitter=5.0, seed=0)  # doctest: +SKIP
    """
    if preprocessor is not None and (jitter or seed is not None):
        raise ValueError("load_run: give the jitter and seed to the Preprocessor, not beside it")
    conform = preprocessor or Preprocessor(prep, mirror=mirror, log=log, jitter=jitter, seed=seed)
    out: np.ndarray | None = None
    bar = progress_bar(progress, len(ds), "reading images")
    i = 0
    for batch in ds.images(batch_size=batch_size):
        b = conform(batch)
        if out is None:
            out = np.empty((len(ds),) + b.shape[1:], b.dtype)
        out[i : i + len(b)] = b
        i += len(b)
        if bar is not None:
            bar.update(len(b))
    if bar is not None:
        bar.close()
    if out is None:
        raise ValueError(f"no images in {ds.root}")
    return out, ds.poses[:, :2].copy()
