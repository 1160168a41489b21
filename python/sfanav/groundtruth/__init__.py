"""Ground truth for real recordings from markers filmed by an external
camera (thesis 4.2.1): a box with ArUco markers on the robot, a calibrated
camera watching it, one pose per frame.

* :mod:`~sfanav.groundtruth.board`: :class:`MarkerBoard` (markers at known
  3-D positions; JSON), :func:`box_board`, :func:`flat_board`;
* :mod:`~sfanav.groundtruth.intrinsics`: :class:`CameraIntrinsics` (K,
  distortion, image size; OpenCV YAML / JSON);
* :mod:`~sfanav.groundtruth.calibration`: :func:`calibrate` from chessboard
  or ChArUco images;
* :mod:`~sfanav.groundtruth.extrinsics`: :class:`CameraPose`, the camera's
  pose relative to the ground;
* :mod:`~sfanav.groundtruth.markers` and :mod:`~sfanav.groundtruth.corners`:
  marker detection, edge-refined corners, the board's pose (PnP);
* :mod:`~sfanav.groundtruth.frames`: videos, image folders and image lists
  as timestamped frames;
* :mod:`~sfanav.groundtruth.estimation`: :func:`estimate_poses`, the
  robot's track; :mod:`~sfanav.groundtruth.posetrack`: :class:`PoseTrack`
  and the pose log CSV that :meth:`sfanav.data.Dataset.from_recording` reads.

Example
-------
>>> from sfanav.groundtruth import CameraIntrinsics, CameraPose, MarkerBoard, estimate_poses
>>> track = estimate_poses("run.mp4", CameraIntrinsics.from_file("camera.yaml"),
...                        MarkerBoard.from_json("board.json"),
...                        camera_pose=CameraPose.from_json("camera_pose.json"))   # doctest: +SKIP
>>> track.to_csv("poses.csv")                                                     # doctest: +SKIP
"""

from __future__ import annotations

from .board import MarkerBoard, box_board, flat_board
from .calibration import CalibrationPattern, CalibrationResult, calibrate
from .corners import refine_corners
from .estimation import estimate_poses, fit_planar
from .extrinsics import CameraPose
from .frames import FrameSource, open_frames
from .intrinsics import CameraIntrinsics
from .markers import BoardPose, Detection, MarkerDetector, solve_board_pose
from .posetrack import PoseTrack

__all__ = [
    "BoardPose",
    "CalibrationPattern",
    "CalibrationResult",
    "CameraIntrinsics",
    "CameraPose",
    "Detection",
    "FrameSource",
    "MarkerBoard",
    "MarkerDetector",
    "PoseTrack",
    "box_board",
    "calibrate",
    "estimate_poses",
    "fit_planar",
    "flat_board",
    "open_frames",
    "refine_corners",
    "solve_board_pose",
]
