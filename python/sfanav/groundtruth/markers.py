"""Finding a marker board in one image and solving for its pose.

:class:`MarkerDetector` finds markers with OpenCV's ``cv2.aruco.ArucoDetector``
and, by default, refines their corners from the markers' edges
(:func:`~sfanav.groundtruth.corners.refine_corners`); :func:`solve_board_pose`
matches the detected markers to a
:class:`~sfanav.groundtruth.board.MarkerBoard` and solves one PnP problem on
the corners of all of them at once (``cv2.solvePnP`` with SQPnP, or IPPE when
all corners lie in one plane, then Levenberg-Marquardt refinement with
``cv2.solvePnPRefineLM``), leaving out markers seen at a grazing angle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .board import DEFAULT_DICTIONARY, MarkerBoard, aruco_dictionary
from .corners import refine_corners
from .intrinsics import CameraIntrinsics

REFINEMENTS = ("edges", "subpix", "contour", "apriltag", "none")


@dataclass(frozen=True)
class Detection:
    """The markers found in one image.

    Attributes
    ----------
    ids : (n,) int
    corners : (n, 4, 2) float
        Image coordinates (pixels, OpenCV's convention: the centre of the
        top-left pixel is (0, 0)) in the marker's corner order.
    """

    ids: np.ndarray
    corners: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)


def as_gray(image: Any) -> np.ndarray:
    """``image`` (uint8 (H, W), (H, W, 1) or RGB (H, W, 3)) as uint8 (H, W).

    Raises
    ------
    ValueError
        For another dtype or shape.
    """
    import cv2

    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3)):
        raise ValueError(f"an image must be uint8 (H, W) or (H, W, 3), got {img.dtype} {img.shape}")
    if img.ndim == 3:
        img = img[:, :, 0] if img.shape[2] == 1 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    return img


class MarkerDetector:
    """Detects ArUco markers of one dictionary (``cv2.aruco.ArucoDetector``).

    Parameters
    ----------
    dictionary : str
        ``cv2.aruco`` dictionary name.
    refinement : ``"edges"``, ``"subpix"``, ``"contour"``, ``"apriltag"`` or ``"none"``
        Corner refinement. ``"edges"`` (default) runs OpenCV's ``"subpix"``,
        then fits straight lines to each marker's four outer edges and
        intersects them (:func:`~sfanav.groundtruth.corners.refine_corners`);
        the others are OpenCV's own.
    parameters : cv2.aruco.DetectorParameters, optional
        Full control over OpenCV's detector (its corner refinement is then
        the one set there, still followed by the edge fit with ``"edges"``).

    Examples
    --------
    >>> det = MarkerDetector("DICT_ARUCO_ORIGINAL")
    >>> found = det.detect(gray_image)                               # doctest: +SKIP
    >>> found.ids, found.corners.shape                               # doctest: +SKIP
    (array([3, 5]), (2, 4, 2))
    """

    def __init__(self, dictionary: str = DEFAULT_DICTIONARY, *, refinement: str = "edges",
                 parameters: Any = None) -> None:
        import cv2

        if refinement not in REFINEMENTS:
            raise ValueError(f"refinement must be one of {', '.join(REFINEMENTS)}, got {refinement!r}")
        self.dictionary = dictionary
        self.refinement = refinement
        d = aruco_dictionary(dictionary)
        if parameters is None:
            parameters = cv2.aruco.DetectorParameters()
            parameters.cornerRefinementMethod = {
                "edges": cv2.aruco.CORNER_REFINE_SUBPIX, "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
                "contour": cv2.aruco.CORNER_REFINE_CONTOUR, "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
                "none": cv2.aruco.CORNER_REFINE_NONE,
            }[refinement]
            parameters.cornerRefinementMaxIterations = 100
            parameters.cornerRefinementMinAccuracy = 0.01
        self._cells = int(d.markerSize) + 2 * int(parameters.markerBorderBits)
        self._detector = cv2.aruco.ArucoDetector(d, parameters)

    def detect(self, image: Any, intrinsics: CameraIntrinsics | None = None) -> Detection:
        """The markers in ``image`` (uint8 gray (H, W) or RGB (H, W, 3)).

        ``intrinsics`` lets the edge refinement fit its lines in undistorted
        coordinates; without it edges are taken as straight in the image.
        """
        img = as_gray(image)
        corners, ids, _ = self._detector.detectMarkers(img)
        if ids is None or not len(ids):
            return Detection(np.zeros(0, np.int64), np.zeros((0, 4, 2)))
        c = np.asarray(corners, float).reshape(-1, 4, 2)
        if self.refinement == "edges":
            c = refine_corners(img, c, cells=self._cells, intrinsics=intrinsics)
        return Detection(np.asarray(ids, np.int64).reshape(-1), c)


@dataclass(frozen=True)
class BoardPose:
    """A board's pose in the camera frame: ``X_cam = R @ X_board + tvec``.

    Attributes
    ----------
    rvec, tvec : (3,) float
        Rodrigues rotation vector (rad) and translation (m).
    ids : (n,) int
        The board markers used.
    reprojection_error : float
        Root mean square distance between the detected corners and the
        board's corners projected with this pose, pixels.
    """

    rvec: np.ndarray
    tvec: np.ndarray
    ids: np.ndarray
    reprojection_error: float

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) rotation matrix R."""
        import cv2

        return cv2.Rodrigues(np.asarray(self.rvec, float).reshape(3, 1))[0]

    @property
    def n_markers(self) -> int:
        return len(self.ids)


def match_board(detection: Detection, board: MarkerBoard) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The board markers in ``detection``: (ids (n,), object corners (n, 4, 3)
    m, image corners (n, 4, 2) px). Ids seen more than once in the image are
    left out (they cannot be told apart)."""
    ids = detection.ids.tolist()
    obj, img, used = [], [], []
    for k, mid in enumerate(ids):
        if ids.count(mid) > 1:
            continue
        hit = np.nonzero(board.ids == mid)[0]
        if len(hit):
            obj.append(board.corners[int(hit[0])])
            img.append(detection.corners[k])
            used.append(mid)
    if not used:
        return np.zeros(0, np.int64), np.zeros((0, 4, 3)), np.zeros((0, 4, 2))
    return np.array(used, np.int64), np.array(obj), np.array(img)


def _pnp(obj: np.ndarray, img: np.ndarray, cam: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray] | None:
    import cv2

    obj, img = obj.reshape(-1, 3), img.reshape(-1, 2)
    centred = obj - obj.mean(axis=0)
    planar = np.linalg.svd(centred, compute_uv=False)[-1] < 1e-6 * max(1.0, float(np.abs(centred).max()))
    ok, rvec, tvec = cv2.solvePnP(obj, img, cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE if planar else cv2.SOLVEPNP_SQPNP)
    if not ok or not np.isfinite(rvec).all() or not np.isfinite(tvec).all():
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, cam.K, cam.dist, rvec, tvec,
                                      criteria=(cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12))
    return rvec.reshape(3), tvec.reshape(3)


def view_angles(board_corners: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """(n,) angle between each marker's front normal and its line of sight
    to the camera, rad (0: seen head-on; above pi/2: seen from behind)."""
    import cv2

    R = cv2.Rodrigues(np.asarray(rvec, float).reshape(3, 1))[0]
    c = np.asarray(board_corners, float) @ R.T + np.asarray(tvec, float).reshape(3)
    normal = np.cross(c[:, 3] - c[:, 0], c[:, 1] - c[:, 0])  # front normal of TL, TR, BR, BL
    to_cam = -c.mean(axis=1)
    cos = np.sum(normal * to_cam, axis=1) / (np.linalg.norm(normal, axis=1) * np.linalg.norm(to_cam, axis=1))
    return np.arccos(np.clip(cos, -1, 1))


def solve_board_pose(detection: Detection, board: MarkerBoard, intrinsics: CameraIntrinsics, *,
                     min_markers: int = 1, max_view_angle: float = 70.0) -> BoardPose | None:
    """The board's pose from the detected markers, or None with fewer than
    ``min_markers`` usable board markers in view.

    One PnP over the corners of every detected board marker: SQPnP (all
    corners in one plane: IPPE), refined by Levenberg-Marquardt on the
    reprojection error. Markers seen at more than ``max_view_angle``
    degrees from head-on (their corners are the least precise) are then
    dropped and the pose solved again, unless no marker would be left (then
    all are kept); None if fewer than ``min_markers`` would be left.

    Examples
    --------
    >>> pose = solve_board_pose(MarkerDetector().detect(img), board, cam)   # doctest: +SKIP
    >>> pose.tvec, pose.reprojection_error                                  # doctest: +SKIP
    """
    import cv2

    ids, obj, img = match_board(detection, board)
    if len(ids) < max(1, min_markers):
        return None
    sol = _pnp(obj, img, intrinsics)
    if sol is None:
        return None
    if len(ids) > 1:
        angles = view_angles(obj, *sol)
        keep = angles <= math.radians(max_view_angle)
        if keep.any() and not keep.all():
            if keep.sum() < max(1, min_markers):
                return None
            ids, obj, img = ids[keep], obj[keep], img[keep]
            sol = _pnp(obj, img, intrinsics)
            if sol is None:
                return None
    rvec, tvec = sol
    proj = cv2.projectPoints(obj.reshape(-1, 3), rvec, tvec, intrinsics.K, intrinsics.dist)[0].reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum((proj - img.reshape(-1, 2)) ** 2, axis=1))))
    return BoardPose(rvec.copy(), tvec.copy(), ids, rms)
