"""Camera intrinsics: the pinhole matrix K, lens distortion and image size
of the external camera that films the robot, read and written as OpenCV
FileStorage YAML / XML (the fields OpenCV's calibration samples write) or JSON."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._files import write_text_atomic

DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)
FORMAT = "sfanav-camera-intrinsics"
VERSION = 1


@dataclass(frozen=True)
class CameraIntrinsics:
    """A calibrated camera: ``K``, distortion coefficients and image size.

    Parameters
    ----------
    K : (3, 3) float
        ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` in pixels; fx, fy > 0.
    dist : (n,) float
        OpenCV distortion coefficients ``k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]``,
        n in 0, 4, 5, 8, 12, 14 (0: none).
    image_size : (width, height) int
        Size of the images the calibration holds for, pixels.

    Raises
    ------
    ValueError
        If a focal length is not positive, K's last row is not (0, 0, 1),
        values are not finite, the distortion has an unknown length, or the
        principal point lies outside the image.

    Examples
    --------
    >>> cam = CameraIntrinsics.from_focal(1400.0, (1920, 1080))
    >>> cam.to_file("camera.yaml")                                   # doctest: +SKIP
    >>> CameraIntrinsics.from_file("camera.yaml").fx                 # doctest: +SKIP
    1400.0
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]

    def __post_init__(self) -> None:
        try:
            K = np.array(self.K, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"camera_matrix must be a 3x3 matrix of numbers, got {self.K!r}") from None
        if K.shape != (3, 3):
            raise ValueError(f"camera_matrix must be 3x3, got shape {K.shape}")
        if not np.isfinite(K).all():
            raise ValueError("camera_matrix contains NaN or infinity")
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise ValueError(f"camera_matrix: focal lengths fx, fy must be > 0, got fx={K[0, 0]}, fy={K[1, 1]}")
        if K[1, 0] != 0 or not np.allclose(K[2], (0, 0, 1)):
            raise ValueError(f"camera_matrix must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
        try:
            dist = np.array(self.dist, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"distortion_coefficients must be numbers, got {self.dist!r}") from None
        if len(dist) not in DISTORTION_LENGTHS:
            raise ValueError(f"distortion_coefficients must have {', '.join(map(str, DISTORTION_LENGTHS))} "
                             f"values, got {len(dist)}")
        if not np.isfinite(dist).all():
            raise ValueError("distortion_coefficients contain NaN or infinity")
        size = tuple(self.image_size)
        if len(size) != 2 or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v > 0
                                     for v in size):
            raise ValueError(f"image_width and image_height must be positive integers, got {self.image_size!r}")
        w, h = int(size[0]), int(size[1])
        if not (0 <= K[0, 2] <= w and 0 <= K[1, 2] <= h):
            raise ValueError(f"camera_matrix: principal point ({K[0, 2]}, {K[1, 2]}) lies outside the "
                             f"{w}x{h} image")
        K.setflags(write=False)
        dist.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "image_size", (w, h))

    @classmethod
    def from_focal(cls, focal: float, image_size: tuple[int, int], *, dist: Any = ()) -> "CameraIntrinsics":
        """A camera with square pixels, focal length ``focal`` (px) and the
        principal point in the image centre."""
        w, h = image_size
        K = [[focal, 0.0, (w - 1) / 2], [0.0, focal, (h - 1) / 2], [0.0, 0.0, 1.0]]
        return cls(np.array(K), np.asarray(dist, float), (int(w), int(h)))

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CameraIntrinsics):
            return NotImplemented
        return (np.array_equal(self.K, other.K) and np.array_equal(self.dist, other.dist)
                and self.image_size == other.image_size)

    __hash__ = None  # type: ignore[assignment]

    def check_image(self, image: np.ndarray, what: str = "image") -> None:
        """ValueError unless ``image`` has this calibration's size."""
        h, w = image.shape[:2]
        if (w, h) != self.image_size:
            raise ValueError(f"{what} is {w}x{h} pixels but the camera was calibrated at "
                             f"{self.image_size[0]}x{self.image_size[1]}; calibrate at the recording's resolution")

    # ---------------------------------------------------------------- files

    @classmethod
    def from_file(cls, path: str | os.PathLike) -> "CameraIntrinsics":
        """Reads ``camera_matrix``, ``distortion_coefficients``,
        ``image_width`` and ``image_height`` from an OpenCV FileStorage file
        (``.yaml``, ``.yml``, ``.xml``) or a JSON file (``.json``, same field
        names; K as nested lists).

        Raises
        ------
        FileNotFoundError
            If ``path`` does not exist.
        ValueError
            If the file cannot be parsed or a field is missing or invalid (named).
        """
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"no camera intrinsics file at {p}")
        if p.suffix.lower() == ".json":
            try:
                doc = json.loads(p.read_text(encoding="utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as exc:
                raise ValueError(f"camera intrinsics {p} is not JSON ({exc})") from None
            if not isinstance(doc, dict):
                raise ValueError(f"camera intrinsics {p}: expected a JSON object")
            if "version" in doc and doc["version"] != VERSION:
                raise ValueError(f"camera intrinsics {p}: field 'version' is {doc['version']!r}, "
                                 f"this sfanav reads version {VERSION}")
            fields = doc
        else:
            fields = _read_filestorage(p)
        for name in ("camera_matrix", "image_width", "image_height"):
            if fields.get(name) is None:
                raise ValueError(f"camera intrinsics {p}: field {name!r} is missing")
        dist = fields.get("distortion_coefficients")
        size = []
        for name in ("image_width", "image_height"):
            v = fields[name]
            if isinstance(v, float) and v.is_integer():
                v = int(v)
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise ValueError(f"camera intrinsics {p}: field {name!r} must be a positive integer, got {v!r}")
            size.append(v)
        try:
            return cls(fields["camera_matrix"], [] if dist is None else dist, (size[0], size[1]))
        except ValueError as exc:
            raise ValueError(f"camera intrinsics {p}: {exc}") from None

    def to_file(self, path: str | os.PathLike, *, overwrite: bool = True) -> None:
        """Writes the intrinsics atomically: OpenCV FileStorage for ``.yaml``,
        ``.yml`` or ``.xml``, JSON for ``.json``.

        Raises
        ------
        ValueError
            For another extension.
        """
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix == ".json":
            doc = {"format": FORMAT, "version": VERSION, "camera_matrix": self.K.tolist(),
                   "distortion_coefficients": self.dist.tolist(), "image_width": self.image_size[0],
                   "image_height": self.image_size[1]}
            text = json.dumps(doc, indent=1) + "\n"
        elif suffix in (".yaml", ".yml", ".xml"):
            import cv2

            fs = cv2.FileStorage(f"intrinsics{'.xml' if suffix == '.xml' else '.yaml'}",
                                 cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
            fs.write("image_width", self.image_size[0])
            fs.write("image_height", self.image_size[1])
            fs.write("camera_matrix", self.K)
            if len(self.dist):  # no distortion: no field (OpenCV cannot store an empty matrix)
                fs.write("distortion_coefficients", self.dist.reshape(1, -1))
            text = fs.releaseAndGetString()
        else:
            raise ValueError(f"intrinsics file {p} must end in .yaml, .yml, .xml or .json")
        write_text_atomic(p, text, overwrite=overwrite)


def _read_filestorage(p: Path) -> dict[str, Any]:
    import cv2

    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # OpenCV's parser errors surface as either
        cause = exc.__cause__ or exc.__context__ or exc
        msg = str(cause).strip().splitlines()[-1] if str(cause).strip() else "parse error"
        raise ValueError(f"camera intrinsics {p} is not an OpenCV YAML/XML file ({msg})") from None
    if not fs.isOpened():
        raise ValueError(f"camera intrinsics {p} is not an OpenCV YAML/XML file")
    out: dict[str, Any] = {}
    try:
        for name in ("camera_matrix", "distortion_coefficients"):
            node = fs.getNode(name)
            if node.empty() or node.isNone():
                out[name] = None
                continue
            m = node.mat()
            if m is None:
                raise ValueError(f"camera intrinsics {p}: field {name!r} is not an OpenCV matrix")
            out[name] = np.asarray(m, float)
        for name in ("image_width", "image_height"):
            node = fs.getNode(name)
            out[name] = None if node.empty() or node.isNone() else (
                int(node.real()) if node.isInt() else float(node.real()) if node.isReal() else node.string())
    finally:
        fs.release()
    return out
