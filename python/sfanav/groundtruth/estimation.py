"""The robot's ground-truth track from an external camera's recording of
its marker board (thesis 4.2.1): :func:`estimate_poses`.

Per frame: detect the markers, solve the board's pose in the camera frame
(:func:`~sfanav.groundtruth.markers.solve_board_pose`), and carry it into the
ground frame with the camera's pose; then (``planar=True``, the default) refit
x, y and heading with the robot held on the ground plane and level.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from typing import Any

import numpy as np

from .._checks import check_int, check_positive_float
from .._progress import Log, progress_bar, quiet_log
from .board import MarkerBoard
from .extrinsics import CameraPose
from .frames import FrameSource, open_frames
from .intrinsics import CameraIntrinsics
from .markers import BoardPose, Detection, MarkerDetector, as_gray, match_board, solve_board_pose
from .posetrack import PoseTrack


def robot_in_ground(board_pose: BoardPose, camera: CameraPose) -> tuple[np.ndarray, np.ndarray]:
    """(R (3, 3), p (3,)): the robot frame in the ground frame,
    ``X_ground = R @ X_robot + p``, from the board's pose in the camera."""
    Rc = camera.rotation
    return Rc.T @ board_pose.rotation, Rc.T @ (board_pose.tvec - camera.tvec)


def heading_of(R: np.ndarray) -> float:
    """Yaw (rad, [-pi, pi)) of the rotated x axis in the ground plane."""
    h = math.atan2(R[1, 0], R[0, 0])
    return (h + math.pi) % (2 * math.pi) - math.pi


def _planar_project(q: np.ndarray, obj: np.ndarray, camera: CameraPose, cam: CameraIntrinsics) -> np.ndarray:
    import cv2

    c, s = math.cos(q[2]), math.sin(q[2])
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return cv2.projectPoints(obj @ R.T + (q[0], q[1], 0.0), camera.rvec, camera.tvec, cam.K,
                             cam.dist)[0].reshape(-1)


def fit_planar(obj: np.ndarray, img: np.ndarray, camera: CameraPose, intrinsics: CameraIntrinsics,
               start: tuple[float, float, float], *, iterations: int = 20) -> tuple[np.ndarray, float]:
    """Fits (x, y, heading) of a robot on the ground plane (z = 0, level) to
    image points by Gauss-Newton on the reprojection error.

    Parameters
    ----------
    obj : (n, 3) board corners in the robot frame, m
    img : (n, 2) their image points, px
    camera : the camera's pose in the ground frame
    start : initial (x m, y m, heading rad)

    Returns
    -------
    ((3,) x, y, heading; RMS reprojection error px)
    """
    q = np.array(start, float)
    target = img.reshape(-1)
    r = _planar_project(q, obj, camera, intrinsics) - target
    eps = np.array([1e-6, 1e-6, 1e-6])
    for _ in range(iterations):
        J = np.empty((len(r), 3))
        for j in range(3):
            dq = np.zeros(3)
            dq[j] = eps[j]
            J[:, j] = (_planar_project(q + dq, obj, camera, intrinsics)
                       - _planar_project(q - dq, obj, camera, intrinsics)) / (2 * eps[j])
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        q_new = q + step
        r_new = _planar_project(q_new, obj, camera, intrinsics) - target
        if r_new @ r_new > r @ r:
            break
        q, r = q_new, r_new
        if np.abs(step).max() < 1e-10:
            break
    q[2] = (q[2] + math.pi) % (2 * math.pi) - math.pi
    return q, float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2) * 2))


def _frames(frames: Any) -> tuple[Iterable[tuple[float, np.ndarray]], int | None, str]:
    if isinstance(frames, (str, os.PathLike)):
        frames = open_frames(frames)
    if isinstance(frames, FrameSource):
        return frames, frames.n, frames.description
    n = len(frames) if hasattr(frames, "__len__") else None
    return frames, n, "frames"


def estimate_poses(frames: Any, intrinsics: CameraIntrinsics, board: MarkerBoard, *,
                   camera_pose: CameraPose | MarkerBoard | None = None, planar: bool = True,
                   min_markers: int = 1, max_view_angle: float = 60.0, max_reprojection_error: float = 2.0,
                   detector: MarkerDetector | None = None, progress: bool = False,
                   log: Log = quiet_log) -> PoseTrack:
    """The robot's pose in the ground frame in every frame.

    Parameters
    ----------
    frames : path, FrameSource or iterable of (timestamp s, uint8 image)
        A video, an image folder or CSV image list (:func:`open_frames`), or
        the frames themselves; timestamps must increase strictly.
    intrinsics : CameraIntrinsics
        The external camera's calibration; frames must have its image size.
    board : MarkerBoard
        The markers on the robot, in the robot frame.
    camera_pose : CameraPose, MarkerBoard or None
        Where the camera is relative to the ground: a :class:`CameraPose`
        (given); a ground board (markers whose corners are given in the
        ground frame, lying on the floor: the pose is estimated from the
        first frame that shows it); or None: the ground frame is the robot's
        frame at its first detected pose (x = y = heading = 0 there).
    planar : bool
        Fit x, y and heading with the robot's origin on the ground plane
        and the robot level (default): far less noise than the free 6-DoF
        pose, for a robot on a flat floor. False keeps the 6-DoF pose
        (uneven ground, or a camera pose known only roughly).
    min_markers : int
        Fewest board markers a frame needs for a pose.
    max_view_angle : float
        Markers seen at more than this angle from head-on (degrees) are left
        out when others are in view.
    max_reprojection_error : float
        Poses with a larger RMS reprojection error (px) are rejected (gaps).
    detector : MarkerDetector, optional
        Default: ``MarkerDetector(board.dictionary)`` (edge-refined corners).
    progress : bool
        Show a progress bar.
    log : callable
        Receives one line about the camera pose when it is estimated.

    Returns
    -------
    PoseTrack
        One row per frame; frames without a pose hold NaN (gaps), never zeros.

    Raises
    ------
    ValueError
        On frames of another size than the calibration, timestamps that do
        not increase, or a ground board never seen.

    Examples
    --------
    >>> cam = CameraIntrinsics.from_file("camera.yaml")                   # doctest: +SKIP
    >>> board = MarkerBoard.from_json("board.json")                       # doctest: +SKIP
    >>> track = estimate_poses("run.mp4", cam, board,
    ...                        camera_pose=CameraPose.from_json("pose.json"))  # doctest: +SKIP
    >>> track.to_csv("poses.csv")                                         # doctest: +SKIP
    """
    check_int(min_markers, "min_markers")
    max_view_angle = check_positive_float(max_view_angle, "max_view_angle")
    max_reprojection_error = check_positive_float(max_reprojection_error, "max_reprojection_error")
    if not isinstance(board, MarkerBoard):
        raise TypeError(f"board must be a MarkerBoard, got {type(board).__name__}")
    ground_board = camera_pose if isinstance(camera_pose, MarkerBoard) else None
    if ground_board is not None:
        shared = sorted(set(ground_board.ids.tolist()) & set(board.ids.tolist()))
        if ground_board.dictionary == board.dictionary and shared:
            raise ValueError(f"the robot's board and the ground board share marker ids {shared}")
    camera: CameraPose | None = camera_pose if isinstance(camera_pose, CameraPose) else None
    if camera_pose is not None and camera is None and ground_board is None:
        raise TypeError(f"camera_pose must be a CameraPose, a MarkerBoard or None, got {type(camera_pose).__name__}")
    det = detector or MarkerDetector(board.dictionary)
    ground_det = None
    if ground_board is not None:
        ground_det = det if ground_board.dictionary == det.dictionary else MarkerDetector(ground_board.dictionary)
    source, n, what = _frames(frames)
    rows: list[tuple[float, ...]] = []
    n_rejected = 0
    last_t = -math.inf
    bar = progress_bar(progress, n, "ground truth", unit="frame")
    try:
        for k, (t, image) in enumerate(source):
            t = float(t)
            if not math.isfinite(t) or t <= last_t:
                raise ValueError(f"{what}: frame {k} has timestamp {t}, not after {last_t}; "
                                 "timestamps must increase strictly")
            last_t = t
            gray = as_gray(image)
            intrinsics.check_image(gray, f"frame {k} of {what}")
            found = det.detect(gray, intrinsics)
            if camera is None and ground_board is not None and ground_det is not None:
                g = found if ground_det is det else ground_det.detect(gray, intrinsics)
                gp = solve_board_pose(g, ground_board, intrinsics, min_markers=min_markers,
                                      max_view_angle=max_view_angle)
                if gp is not None:
                    camera = CameraPose(gp.rvec, gp.tvec, gp.reprojection_error)
                    log(f"camera pose from the ground board in frame {k} (t={t} s, {gp.n_markers} markers, "
                        f"reprojection error {gp.reprojection_error:.3f} px): camera at "
                        f"{np.round(camera.position, 3).tolist()} m")
            bp = solve_board_pose(found, board, intrinsics, min_markers=min_markers, max_view_angle=max_view_angle)
            if bp is not None and bp.reprojection_error <= max_reprojection_error and camera is None \
                    and ground_board is None:
                camera = CameraPose(bp.rvec, bp.tvec)
                log(f"ground frame: the robot's frame in frame {k} (t={t} s)")
            row = _pose_row(t, bp, found, board, intrinsics, camera, planar, max_reprojection_error)
            if row is None:
                n_rejected += 1
                row = (t, math.nan, math.nan, math.nan, math.nan, math.nan, 0, math.nan)
            rows.append(row)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    if ground_board is not None and camera is None:
        raise ValueError(f"the ground board (ids {ground_board.ids.tolist()}) is in no frame of {what}; "
                         "the camera's pose is unknown")
    cols = np.array(rows, float).reshape(-1, 8)
    return PoseTrack(cols[:, 0], cols[:, 1], cols[:, 2], cols[:, 3], cols[:, 4], cols[:, 5],
                     cols[:, 6].astype(np.int64), cols[:, 7], n_rejected,
                     {"camera_pose": None if camera is None else camera, "planar": planar})


def _pose_row(t: float, bp: BoardPose | None, found: Detection, board: MarkerBoard, cam: CameraIntrinsics,
              camera: CameraPose | None, planar: bool, max_err: float) -> tuple[float, ...] | None:
    """(t, x, y, heading, z, tilt, n_markers, reprojection error): NaN and
    0 markers without a pose (or before the camera's pose is known), None
    if the pose is rejected for its reprojection error."""
    nan = math.nan
    if bp is None or camera is None:
        return (t, nan, nan, nan, nan, nan, 0, nan)
    if bp.reprojection_error > max_err:
        return None
    R, p = robot_in_ground(bp, camera)
    x, y, z, heading = float(p[0]), float(p[1]), float(p[2]), heading_of(R)
    tilt = float(math.acos(max(-1.0, min(1.0, R[2, 2]))))
    err = bp.reprojection_error
    if planar:
        keep = np.isin(found.ids, bp.ids)
        _, obj, img = match_board(Detection(found.ids[keep], found.corners[keep]), board)
        obj, img = obj.reshape(-1, 3), img.reshape(-1, 2)
        q, err = fit_planar(obj, img, camera, cam, (x, y, heading))
        if err > 0.5 * max_err:  # a poor 6-DoF start (e.g. a flipped single marker): try other headings
            for turn in (math.pi / 2, math.pi, -math.pi / 2):
                q2, err2 = fit_planar(obj, img, camera, cam, (x, y, heading + turn))
                if err2 < err:
                    q, err = q2, err2
        if err > max_err:
            return None
        x, y, heading = float(q[0]), float(q[1]), float(q[2])
    return (t, x, y, heading, z, tilt, bp.n_markers, err)
