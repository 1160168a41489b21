"""Calibrating the external camera from images of a chessboard or a ChArUco
board: OpenCV's pattern detectors (``cv2.findChessboardCorners`` +
``cv2.cornerSubPix``, or ``cv2.aruco.CharucoDetector``) and
``cv2.calibrateCamera``."""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .._checks import check_int
from .._progress import progress_bar
from ..data.images import read_image
from .board import aruco_dictionary
from .frames import IMAGE_SUFFIXES
from .intrinsics import CameraIntrinsics
from .markers import as_gray

PATTERN_HELP = ("chessboard:COLSxROWS:SQUARE (inner corners, square side in m, e.g. chessboard:9x6:0.025) or "
                "charuco:COLSxROWS:SQUARE:MARKER[:DICT] (squares, sides in m, e.g. charuco:7x5:0.04:0.03:DICT_4X4_50)")


@dataclass(frozen=True)
class CalibrationPattern:
    """A calibration target.

    Parameters
    ----------
    kind : ``"chessboard"`` or ``"charuco"``
    cols, rows : int
        Chessboard: inner corners per row and per column (OpenCV's
        ``patternSize``). ChArUco: squares per row and per column.
    square : float
        Side of one square, m.
    marker : float
        ChArUco: side of the markers in the white squares, m.
    dictionary : str
        ChArUco: ``cv2.aruco`` dictionary name.

    Examples
    --------
    >>> CalibrationPattern.parse("chessboard:9x6:0.025")
    CalibrationPattern(kind='chessboard', cols=9, rows=6, square=0.025, marker=0.0, dictionary='DICT_4X4_50')
    """

    kind: str
    cols: int
    rows: int
    square: float
    marker: float = 0.0
    dictionary: str = "DICT_4X4_50"

    def __post_init__(self) -> None:
        if self.kind not in ("chessboard", "charuco"):
            raise ValueError(f"pattern kind must be 'chessboard' or 'charuco', got {self.kind!r}")
        least = 2 if self.kind == "chessboard" else 3
        if not (isinstance(self.cols, int) and isinstance(self.rows, int)) or min(self.cols, self.rows) < least:
            what = "inner corners" if self.kind == "chessboard" else "squares"
            raise ValueError(f"a {self.kind} needs at least {least}x{least} {what}, got {self.cols}x{self.rows}")
        if not self.square > 0:
            raise ValueError(f"the square size must be > 0 m, got {self.square}")
        if self.kind == "charuco":
            if not 0 < self.marker < self.square:
                raise ValueError(f"a ChArUco marker must be > 0 and smaller than the square ({self.square} m), "
                                 f"got {self.marker}")
            aruco_dictionary(self.dictionary)

    @classmethod
    def parse(cls, text: str) -> "CalibrationPattern":
        """From ``chessboard:9x6:0.025`` or ``charuco:7x5:0.04:0.03[:DICT_4X4_50]``.

        Raises
        ------
        ValueError
            With the expected syntax.
        """
        parts = str(text).strip().split(":")
        size = re.fullmatch(r"(\d+)x(\d+)", parts[1].strip().lower()) if len(parts) > 1 else None
        try:
            if parts[0] == "chessboard" and len(parts) == 3 and size:
                return cls("chessboard", int(size[1]), int(size[2]), float(parts[2]))
            if parts[0] == "charuco" and len(parts) in (4, 5) and size:
                d = parts[4] if len(parts) == 5 else "DICT_4X4_50"
                return cls("charuco", int(size[1]), int(size[2]), float(parts[2]), float(parts[3]), d)
        except ValueError as exc:
            raise ValueError(f"bad calibration pattern {text!r}: {exc}; expected {PATTERN_HELP}") from None
        raise ValueError(f"bad calibration pattern {text!r}; expected {PATTERN_HELP}")

    def __str__(self) -> str:
        if self.kind == "chessboard":
            return f"chessboard:{self.cols}x{self.rows}:{self.square:g}"
        return f"charuco:{self.cols}x{self.rows}:{self.square:g}:{self.marker:g}:{self.dictionary}"

    def object_points(self) -> np.ndarray:
        """Chessboard: (cols*rows, 3) inner corners in the board plane, m, in
        OpenCV's detection order (row by row)."""
        grid = np.mgrid[0:self.cols, 0:self.rows].T.reshape(-1, 2) * self.square
        return np.c_[grid, np.zeros(len(grid))].astype(np.float32)

    def charuco_board(self) -> Any:
        """The ``cv2.aruco.CharucoBoard`` of a ChArUco pattern."""
        import cv2

        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square, self.marker,
                                      aruco_dictionary(self.dictionary))


class CalibrationResult(NamedTuple):
    """What :func:`calibrate` found.

    Attributes
    ----------
    intrinsics : CameraIntrinsics
    rms : float
        RMS reprojection error over all used views, px.
    used : list of int
        Indices (in input order) of the images in which the pattern was found.
    n_images : int
        Images looked at.
    """

    intrinsics: CameraIntrinsics
    rms: float
    used: list[int]
    n_images: int


def _image_items(images: Any) -> Iterable[tuple[str, Any]]:
    if isinstance(images, (str, os.PathLike)):
        p = Path(images)
        if not p.exists():
            raise FileNotFoundError(f"no calibration image folder at {p}")
        if not p.is_dir():
            raise ValueError(f"{p} is not a folder of calibration images")
        files = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise ValueError(f"calibration folder {p} holds no images ({', '.join(IMAGE_SUFFIXES)})")
        return [(str(f), f) for f in files]
    return ((f"image {i}", im) for i, im in enumerate(images))


def _find_chessboard(gray: np.ndarray, pattern: CalibrationPattern) -> tuple[np.ndarray, np.ndarray] | None:
    import cv2

    size = (pattern.cols, pattern.rows)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, size, flags=flags)
    if not found:
        return None
    corners = corners.reshape(-1, 2).astype(np.float32)
    # window: under half the smallest distance between neighbouring corners
    grid = corners.reshape(pattern.rows, pattern.cols, 2)
    step = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(), np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
    win = int(max(2, min(11, step * 0.4)))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    corners = cv2.cornerSubPix(gray, corners.reshape(-1, 1, 2), (win, win), (-1, -1), criteria)
    return pattern.object_points(), corners.reshape(-1, 2)


def _find_charuco(gray: np.ndarray, detector: Any, board: Any) -> tuple[np.ndarray, np.ndarray] | None:
    cc, ci, _, _ = detector.detectBoard(gray)
    if cc is None or ci is None or len(ci) < 6:
        return None
    obj, img = board.matchImagePoints(cc, ci)
    if obj is None or len(obj) < 6:
        return None
    obj = np.asarray(obj, np.float32).reshape(-1, 3)
    if np.linalg.matrix_rank(obj[:, :2] - obj[0, :2], tol=1e-9) < 2:
        return None  # all corners on one line
    return obj, np.asarray(img, np.float32).reshape(-1, 2)


def calibrate(images: Any, pattern: CalibrationPattern | str = "chessboard:9x6:0.025", *, min_views: int = 5,
              flags: int = 0, progress: bool = False) -> CalibrationResult:
    """Calibrates a camera from images of a chessboard or ChArUco board.

    Parameters
    ----------
    images : path or iterable
        A folder of images, or paths / uint8 arrays (gray or RGB) of one size.
    pattern : CalibrationPattern or str
        E.g. ``"chessboard:9x6:0.025"`` (9 x 6 inner corners, 25 mm squares)
        or ``"charuco:7x5:0.04:0.03:DICT_4X4_50"``.
    min_views : int
        Fewest images that must show the pattern.
    flags : int
        ``cv2.calibrateCamera`` flags (e.g. ``cv2.CALIB_FIX_K3``).
    progress : bool
        Show a progress bar while detecting.

    Returns
    -------
    CalibrationResult
        ``intrinsics``, ``rms`` (px), ``used`` and ``n_images``.

    Raises
    ------
    FileNotFoundError
        If the folder or an image path does not exist.
    ValueError
        If fewer than ``min_views`` images show the pattern, images differ in
        size, or the pattern is malformed.

    Examples
    --------
    >>> result = calibrate("calib_images/", "chessboard:9x6:0.025")      # doctest: +SKIP
    >>> result.intrinsics.to_file("camera.yaml"); result.rms             # doctest: +SKIP
    0.21
    """
    import cv2

    if isinstance(pattern, str):
        pattern = CalibrationPattern.parse(pattern)
    if not isinstance(pattern, CalibrationPattern):
        raise TypeError(f"pattern must be a CalibrationPattern or a string, got {type(pattern).__name__}")
    min_views = check_int(min_views, "min_views")
    items = _image_items(images)
    detector = board = None
    if pattern.kind == "charuco":
        board = pattern.charuco_board()
        detector = cv2.aruco.CharucoDetector(board)
    obj_pts, img_pts, used = [], [], []
    size: tuple[int, int] | None = None
    first = ""
    n = 0
    bar = progress_bar(progress, len(items) if isinstance(items, list) else None, "calibration")
    try:
        for i, (name, item) in enumerate(items):
            n += 1
            gray = read_image(item, gray=True) if isinstance(item, (str, os.PathLike)) else as_gray(item)
            hw = (gray.shape[1], gray.shape[0])
            if size is None:
                size, first = hw, name
            elif hw != size:
                raise ValueError(f"{name} is {hw[0]}x{hw[1]} pixels, unlike {first} ({size[0]}x{size[1]}); "
                                 "calibrate with images of one size")
            found = _find_chessboard(gray, pattern) if detector is None else _find_charuco(gray, detector, board)
            if found is not None:
                obj_pts.append(found[0])
                img_pts.append(found[1])
                used.append(i)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    if n == 0:
        raise ValueError("no calibration images given")
    if len(used) < min_views:
        raise ValueError(f"only {len(used)} of {n} images show the {pattern}; calibration needs at least "
                         f"{min_views} (check the pattern size: COLSxROWS counts "
                         f"{'inner corners' if pattern.kind == 'chessboard' else 'squares'})")
    assert size is not None
    rms, K, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, size, None, None, flags=flags)
    intr = CameraIntrinsics(np.asarray(K, float), np.asarray(dist, float).reshape(-1), size)
    return CalibrationResult(intr, float(rms), used, n)
