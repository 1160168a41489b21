"""The external camera's pose relative to the ground (its extrinsics):
given in a JSON file, built from a measured position and a point it looks
at, or estimated from a marker board lying on the floor."""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .board import MarkerBoard
from .._files import write_text_atomic
from .intrinsics import CameraIntrinsics
from .markers import MarkerDetector, solve_board_pose

FORMAT = "sfanav-camera-pose"
VERSION = 1


@dataclass(frozen=True)
class CameraPose:
    """Where the camera is relative to the ground frame (x, y on the floor,
    z up, metres): ``X_cam = R @ X_ground + tvec``, OpenCV's camera axes (x
    right, y down, z forward along the optical axis).

    Parameters
    ----------
    rvec : (3,) float
        Rodrigues rotation vector of R, rad.
    tvec : (3,) float
        Translation, m.

    Raises
    ------
    ValueError
        If a value is not finite or a vector has not 3 entries.

    Examples
    --------
    >>> pose = CameraPose.look_at(position=(0, -3, 2.5), target=(0, 1, 0))
    >>> np.round(pose.position, 6)
    array([ 0., -3.,  2.5])
    >>> pose.to_json("camera_pose.json")                           # doctest: +SKIP
    """

    rvec: np.ndarray
    tvec: np.ndarray
    reprojection_error: float | None = None

    def __post_init__(self) -> None:
        for name in ("rvec", "tvec"):
            try:
                v = np.array(getattr(self, name), dtype=float).reshape(-1)
            except (TypeError, ValueError):
                raise ValueError(f"{name} must be 3 numbers, got {getattr(self, name)!r}") from None
            if v.shape != (3,) or not np.isfinite(v).all():
                raise ValueError(f"{name} must be 3 finite numbers, got {getattr(self, name)!r}")
            v.setflags(write=False)
            object.__setattr__(self, name, v)

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) R, ground to camera."""
        import cv2

        return cv2.Rodrigues(self.rvec.reshape(3, 1))[0]

    @property
    def position(self) -> np.ndarray:
        """(3,) the camera's centre in the ground frame, m."""
        return -self.rotation.T @ self.tvec

    @classmethod
    def from_rotation(cls, R: Any, tvec: Any) -> "CameraPose":
        """From a (3, 3) rotation matrix and a translation (``X_cam = R X + t``)."""
        import cv2

        R = np.asarray(R, float)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("R must be a 3x3 rotation matrix")
        return cls(cv2.Rodrigues(R)[0].reshape(3), np.asarray(tvec, float))

    @classmethod
    def look_at(cls, position: Sequence[float], target: Sequence[float]) -> "CameraPose":
        """A camera at ``position`` (m, ground frame) whose optical axis
        passes through ``target``, with no roll (image rows parallel to the
        floor).

        Raises
        ------
        ValueError
            If the camera looks straight up or down, or at itself.
        """
        c, t = np.asarray(position, float).reshape(3), np.asarray(target, float).reshape(3)
        z = t - c
        if np.linalg.norm(z) == 0:
            raise ValueError("target must differ from position")
        z = z / np.linalg.norm(z)
        x = np.cross(z, (0.0, 0.0, 1.0))
        if np.linalg.norm(x) < 1e-9:
            raise ValueError("a camera looking straight up or down has no defined roll; tilt it slightly")
        x = x / np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.stack([x, y, z])
        return cls.from_rotation(R, -R @ c)

    @classmethod
    def from_image(cls, image: np.ndarray, intrinsics: CameraIntrinsics, ground_board: MarkerBoard, *,
                   min_markers: int = 1, detector: MarkerDetector | None = None) -> "CameraPose":
        """Estimates the pose from one image of ``ground_board``, a board
        whose corners are given in the ground frame (e.g. markers lying flat
        on the floor, :func:`~sfanav.groundtruth.board.flat_board`).

        Raises
        ------
        ValueError
            If fewer than ``min_markers`` of the board's markers are found.
        """
        intrinsics.check_image(np.asarray(image))
        det = detector or MarkerDetector(ground_board.dictionary)
        pose = solve_board_pose(det.detect(image), ground_board, intrinsics, min_markers=min_markers)
        if pose is None:
            raise ValueError(f"the ground board (ids {ground_board.ids.tolist()}) is not in the image "
                             f"(need {min_markers} of its markers)")
        return cls(pose.rvec, pose.tvec, pose.reprojection_error)

    # ---------------------------------------------------------------- JSON

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> "CameraPose":
        """Reads ``{"format": "sfanav-camera-pose", "version": 1, "rvec": [..], "tvec": [..]}``
        (``"rotation"``, a 3x3 matrix, may replace ``"rvec"``).

        Raises
        ------
        FileNotFoundError, ValueError (naming the bad field)
        """
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"no camera pose file at {p}")
        try:
            doc = json.loads(p.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"camera pose {p} is not JSON ({exc})") from None
        if not isinstance(doc, dict):
            raise ValueError(f"camera pose {p}: expected a JSON object")
        if doc.get("format", FORMAT) != FORMAT:
            raise ValueError(f"camera pose {p}: field 'format' is {doc.get('format')!r}, expected {FORMAT!r}")
        if doc.get("version") != VERSION:
            raise ValueError(f"camera pose {p}: field 'version' is {doc.get('version')!r}, "
                             f"this sfanav reads version {VERSION}")
        if "tvec" not in doc:
            raise ValueError(f"camera pose {p}: field 'tvec' is missing")
        try:
            if "rvec" in doc:
                return cls(doc["rvec"], doc["tvec"])
            if "rotation" in doc:
                return cls.from_rotation(np.array(doc["rotation"], float), doc["tvec"])
        except (TypeError, ValueError) as exc:
            raise ValueError(f"camera pose {p}: {exc}") from None
        raise ValueError(f"camera pose {p}: field 'rvec' (or 'rotation') is missing")

    def to_json(self, path: str | os.PathLike, *, overwrite: bool = True) -> None:
        """Writes the pose as JSON, atomically."""
        doc = {"format": FORMAT, "version": VERSION,
               "convention": "X_cam = R(rvec) @ X_ground + tvec; ground: z up, m; camera: OpenCV axes",
               "rvec": self.rvec.tolist(), "tvec": self.tvec.tolist(),
               "position": self.position.tolist()}
        if self.reprojection_error is not None:
            doc["reprojection_error_px"] = self.reprojection_error
        write_text_atomic(path, json.dumps(doc, indent=1) + "\n", overwrite=overwrite)
