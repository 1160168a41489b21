"""``sfanav groundtruth`` and ``sfanav calibrate``: ground truth for a real
recording from a marker box on the robot filmed by a calibrated external
camera, and that camera's calibration."""

from __future__ import annotations

import argparse
from typing import Any

from .. import arguments as arg
from ..common import existing_path, log, new_file, wrap
from ..failures import UsageError
from ..registry import command

BOARD_HELP = "box:BOX_SIZE:ID,ID,...[:HEIGHT]"


def _board(text: str, marker_size: float | None, dictionary: str | None) -> Any:
    """A board file, or a box given on the command line (with --marker-size)."""
    from ...groundtruth import MarkerBoard, box_board
    from ...groundtruth.board import DEFAULT_DICTIONARY, FACES

    if text.startswith("box:"):
        parts = text.split(":")
        if len(parts) not in (3, 4):
            raise UsageError(f"--board {text!r}: expected a JSON file or {BOARD_HELP}")
        try:
            box = float(parts[1])
            ids = [int(v) for v in parts[2].split(",") if v.strip()]
            height = float(parts[3]) if len(parts) == 4 else 0.0
        except ValueError:
            raise UsageError(f"--board {text!r}: expected {BOARD_HELP} (metres, integer ids)") from None
        if marker_size is None:
            raise UsageError(f"--board {text!r} needs --marker-size (the printed markers' side, m)")
        if not 1 <= len(ids) <= len(FACES):
            raise UsageError(f"--board {text!r}: give 1 to {len(FACES)} marker ids (faces {', '.join(FACES)})")
        return box_board(marker_size, box, ids, height=height, faces=FACES[:len(ids)],
                         dictionary=dictionary or DEFAULT_DICTIONARY)
    if dictionary is not None:
        raise UsageError("--dictionary applies to a box given on the command line; a board file names its own")
    board = MarkerBoard.from_json(existing_path(text, "board file"))
    return board.with_marker_size(marker_size) if marker_size is not None else board


@command("groundtruth")
def _add_groundtruth(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "groundtruth",
        help="robot poses from a marker box filmed by a calibrated external camera (a pose log)",
        description=wrap("Ground truth for a real recording (thesis 4.2.1): detects the ArUco markers of a box "
                         "on the robot in every frame of a calibrated external camera's video or image folder, "
                         "estimates the robot's pose by PnP (on a flat floor: x, y and heading with the robot "
                         "level, far less noise than the free 6-DoF pose) and writes a timestamped pose log "
                         "(timestamp, x, y, z, heading, tilt, n_markers, reprojection_error) that "
                         "sfanav.Dataset.from_recording interpolates to the robot's image times. Frames without "
                         "a pose are gaps (left out of the log), never zeros. The ground frame comes from "
                         "--camera-pose (the camera's pose over the floor, JSON), from --ground-board (markers "
                         "lying on the floor, seen in the recording), or else is the robot's first detected "
                         "pose."),
        epilog="board: a JSON file (sfanav.groundtruth.MarkerBoard.to_json; docs/groundtruth.md shows one),\n"
               f"or a box given here, {BOARD_HELP}: a cube of side BOX_SIZE m\n"
               "whose front, left, back, right and top faces carry the markers ID,... in that order,\n"
               "its bottom HEIGHT m above the floor (default 0), with --marker-size\n\n"
               "example:\n  sfanav calibrate calib-images --pattern chessboard:9x6:0.025 --out camera.yaml\n"
               "  sfanav groundtruth run.mp4 --camera camera.yaml --board box:0.18:1,2,3,4,5:0.3 \\\n"
               "      --marker-size 0.12 --camera-pose camera-pose.json --out poses.csv",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", metavar="VIDEO|FOLDER|CSV",
                   help="the external camera's video, a folder of images named by their timestamps (s), or a CSV "
                        "with columns timestamp,image")
    p.add_argument("--camera", required=True, metavar="INTRINSICS",
                   help="the camera's calibration (OpenCV YAML / JSON, e.g. from sfanav calibrate)")
    p.add_argument("--board", required=True, metavar="BOARD", help=f"the markers on the robot: JSON file or {BOARD_HELP}")
    p.add_argument("--marker-size", type=float, default=None, metavar="M",
                   help="side of the printed markers' black squares, m (rescales a board file's markers)")
    p.add_argument("--dictionary", default=None, metavar="NAME",
                   help="cv2.aruco dictionary of a box given on the command line (default DICT_ARUCO_ORIGINAL)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--camera-pose", default=None, metavar="JSON",
                       help="the camera's pose in the ground frame (sfanav.groundtruth.CameraPose JSON)")
    where.add_argument("--ground-board", default=None, metavar="BOARD",
                       help="markers lying on the floor (a board JSON in ground coordinates): the camera's pose "
                            "from the first frame that shows them")
    p.add_argument("--out", required=True, metavar="CSV", help="pose log to write")
    p.add_argument("--six-dof", action="store_true",
                   help="keep the free 6-DoF pose (uneven ground) instead of the planar fit")
    p.add_argument("--min-markers", type=arg.pos_int, default=1, metavar="N",
                   help="fewest board markers a frame needs for a pose (default 1)")
    p.add_argument("--max-reprojection-error", type=float, default=2.0, metavar="PX",
                   help="poses with a larger RMS reprojection error are gaps (default 2 px)")
    p.add_argument("--fps", type=float, default=None, metavar="HZ",
                   help="a video's frame rate for its timestamps (default: the video's own)")
    p.add_argument("--timestamps", choices=("index", "msec"), default="index",
                   help="a video's timestamps: frame index / fps (default) or the position the decoder reports")
    p.add_argument("--overwrite", action="store_true", help="replace an existing pose log")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_groundtruth)
    return p


def _run_groundtruth(args: argparse.Namespace) -> int:
    import math

    from ...groundtruth import CameraIntrinsics, CameraPose, MarkerBoard, estimate_poses, open_frames

    if args.marker_size is not None and not (math.isfinite(args.marker_size) and args.marker_size > 0):
        raise UsageError(f"--marker-size must be a positive number of metres, got {args.marker_size}")
    if not (math.isfinite(args.max_reprojection_error) and args.max_reprojection_error > 0):
        raise UsageError(f"--max-reprojection-error must be a positive number of pixels, got {args.max_reprojection_error}")
    out = new_file(args.out, args.overwrite, "pose log")
    intrinsics = CameraIntrinsics.from_file(existing_path(args.camera, "camera calibration"))
    board = _board(args.board, args.marker_size, args.dictionary)
    camera_pose: Any = None
    if args.camera_pose is not None:
        camera_pose = CameraPose.from_json(existing_path(args.camera_pose, "camera pose"))
    elif args.ground_board is not None:
        camera_pose = MarkerBoard.from_json(existing_path(args.ground_board, "ground board"))
    else:
        log("no --camera-pose or --ground-board: the ground frame is the robot's first detected pose")
    frames = open_frames(existing_path(args.input, "recording"), fps=args.fps, timestamps=args.timestamps)
    log(f"estimating poses in {frames.description} with a board of {len(board.ids)} markers "
        f"(ids {', '.join(str(i) for i in board.ids.tolist())}, {board.dictionary})")
    track = estimate_poses(frames, intrinsics, board, camera_pose=camera_pose, planar=not args.six_dof,
                           min_markers=args.min_markers, max_reprojection_error=args.max_reprojection_error,
                           progress=not args.no_progress, log=log)
    n = track.to_csv(out, overwrite=True)
    print(track.summary())
    print(f"wrote {n} poses to {out}" + (f" ({track.n_gaps} frames without a pose left out)" if track.n_gaps else ""))
    return 0


@command("calibrate")
def _add_calibrate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from ...groundtruth.calibration import PATTERN_HELP

    p = sub.add_parser(
        "calibrate",
        help="calibrate a camera from chessboard or ChArUco images (for sfanav groundtruth)",
        description=wrap("Calibrate a camera (focal lengths, principal point, lens distortion) from a folder of "
                         "images of a chessboard or a ChArUco board with OpenCV's calibration, and write the "
                         "result as OpenCV YAML (or JSON for a .json name) for sfanav groundtruth --camera. "
                         "Prints the RMS reprojection error and how many images showed the pattern; use 10-20 "
                         "images with the board at different angles, filling the frame's corners too."),
        epilog="patterns:\n  chessboard:COLSxROWS:SQUARE            COLSxROWS inner corners, squares of side SQUARE m\n"
               "  charuco:COLSxROWS:SQUARE:MARKER[:DICT] COLSxROWS squares of side SQUARE m, markers of side\n"
               "                                         MARKER m from the cv2.aruco dictionary DICT\n"
               "                                         (default DICT_4X4_50)\n\n"
               "example:\n  sfanav calibrate calib-images --pattern chessboard:9x6:0.025 --out camera.yaml",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("images", metavar="FOLDER", help="folder of calibration images (one size)")
    p.add_argument("--pattern", required=True, metavar="PATTERN", help=f"the target: {PATTERN_HELP}")
    p.add_argument("--out", required=True, metavar="FILE", help="calibration to write (.yaml or .json)")
    p.add_argument("--min-views", type=arg.pos_int, default=5, metavar="N",
                   help="fewest images that must show the pattern (default 5)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing calibration file")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_calibrate)
    return p


def _run_calibrate(args: argparse.Namespace) -> int:
    from ...groundtruth import CalibrationPattern, calibrate

    from pathlib import Path

    if Path(args.out).suffix.lower() not in (".yaml", ".yml", ".xml", ".json"):
        raise UsageError(f"--out {args.out}: a calibration file ends in .yaml, .yml, .xml or .json")
    out = new_file(args.out, args.overwrite, "calibration file")
    pattern = CalibrationPattern.parse(args.pattern)
    folder = existing_path(args.images, "image folder")
    if not folder.is_dir():
        raise UsageError(f"{folder} is not a folder of calibration images")
    res = calibrate(folder, pattern, min_views=args.min_views, progress=not args.no_progress)
    res.intrinsics.to_file(out, overwrite=True)
    k = res.intrinsics
    print(f"calibrated from {len(res.used)} of {res.n_images} images: fx {k.fx:.2f}, fy {k.fy:.2f} px, "
          f"principal point ({k.K[0, 2]:.1f}, {k.K[1, 2]:.1f}), image {k.image_size[0]}x{k.image_size[1]}, "
          f"RMS reprojection error {res.rms:.3f} px")
    print(f"wrote {out}")
    return 0
