"""Ground truth from markers (sfanav.groundtruth): boards, intrinsics,
calibration, pose estimation on synthetic perspective renderings of a marker
box at known poses, the pose log and its use by Dataset.from_recording."""

import json
import math
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from markerscene import render, render_charuco, render_chessboard

from sfanav.data import Dataset
from sfanav.groundtruth import (
    CalibrationPattern,
    CameraIntrinsics,
    CameraPose,
    MarkerBoard,
    PoseTrack,
    box_board,
    calibrate,
    estimate_poses,
    flat_board,
    open_frames,
)

# The scene: a 1920x1080 camera (f = 1400 px) 2.5 m above the floor looking
# down obliquely; a 18 cm box with 12 cm markers on the robot, 30 cm above
# the floor; robot positions 3-6 m from the camera.
CAM = CameraIntrinsics.from_focal(1400.0, (1920, 1080))
CAMERA = CameraPose.look_at((0.0, -1.0, 2.5), (0.0, 2.5, 0.0))
BOARD = box_board(0.12, 0.18, ids=[1, 2, 3, 4, 5], height=0.3)
HIDDEN = (4, 11)  # frames without the robot


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(7)
    n = 16
    truth = np.c_[rng.uniform(-1.2, 1.2, n), rng.uniform(0.8, 4.5, n), rng.uniform(-np.pi, np.pi, n)]
    times = 0.1 * np.arange(n) + 1.0
    frames = [(float(times[k]), render(CAM, CAMERA, None if k in HIDDEN else BOARD, truth[k], seed=k))
              for k in range(n)]
    return truth, frames


# ---------------------------------------------------------------- boards


def test_box_board_puts_markers_on_the_faces_facing_outwards():
    b = box_board(0.1, (0.2, 0.3, 0.15), ids=[7, 8, 9, 10, 11], height=0.25, center=(0.05, 0.0))
    assert b.ids.tolist() == [7, 8, 9, 10, 11]
    np.testing.assert_allclose(b.marker_sizes, 0.1)
    centres = b.corners.mean(axis=1)
    np.testing.assert_allclose(centres, [[0.15, 0, 0.325], [0.05, 0.15, 0.325], [-0.05, 0, 0.325],
                                         [0.05, -0.15, 0.325], [0.05, 0, 0.4]], atol=1e-12)
    normals = np.cross(b.corners[:, 3] - b.corners[:, 0], b.corners[:, 1] - b.corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    np.testing.assert_allclose(normals, [[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1]], atol=1e-12)
    # side markers stand upright: the first corner (top-left) is above the last (bottom-left)
    assert (b.corners[:4, 0, 2] > b.corners[:4, 3, 2]).all()
    with pytest.raises(ValueError, match="does not fit"):
        box_board(0.25, 0.2, ids=[1, 2, 3, 4, 5])
    with pytest.raises(ValueError, match="one id per face"):
        box_board(0.1, 0.2, ids=[1, 2])


def test_with_marker_size_rescales_each_marker_about_its_centre():
    b = BOARD.with_marker_size(0.1)
    np.testing.assert_allclose(b.marker_sizes, 0.1)
    np.testing.assert_allclose(b.corners.mean(axis=1), BOARD.corners.mean(axis=1), atol=1e-12)


def test_board_json_round_trip(tmp_path):
    p = tmp_path / "board.json"
    BOARD.to_json(p)
    doc = json.loads(p.read_text())
    assert doc["version"] == 1 and doc["dictionary"] == "DICT_ARUCO_ORIGINAL" and len(doc["markers"]) == 5
    assert MarkerBoard.from_json(p) == BOARD
    assert [f.name for f in tmp_path.iterdir()] == ["board.json"]  # no temporary file left


@settings(max_examples=25, deadline=None)
@given(size=st.floats(0.02, 0.3), box=st.tuples(*[st.floats(0.3, 1.0)] * 3), height=st.floats(0, 1),
       ids=st.lists(st.integers(0, 1023), min_size=5, max_size=5, unique=True),
       dictionary=st.sampled_from(["DICT_ARUCO_ORIGINAL", "DICT_6X6_1000", "DICT_APRILTAG_36h11"]))
def test_board_json_round_trip_property(size, box, height, ids, dictionary):
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    ids = [i % d.bytesList.shape[0] for i in ids]
    if len(set(ids)) < 5:
        return
    b = box_board(size, box, ids, height=height, dictionary=dictionary)
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "b.json"
        b.to_json(p)
        back = MarkerBoard.from_json(p)
    assert back.ids.tolist() == b.ids.tolist() and back.dictionary == dictionary
    np.testing.assert_allclose(back.corners, b.corners, atol=1e-9)


def _board_doc(**changes):
    doc = BOARD.to_dict()
    doc.update(changes)
    return doc


@pytest.mark.parametrize("doc, field", [
    (_board_doc(version=2), "'version'"),
    ({k: v for k, v in _board_doc().items() if k != "version"}, "'version'"),
    (_board_doc(version="1"), "'version'"),
    (_board_doc(dictionary="DICT_NOPE"), "'dictionary'"),
    (_board_doc(markers=[]), "'markers'"),
    (_board_doc(markers=[{"id": 1, "corners": [[0, 0, 0]]}]), r"'markers\[0\].corners'"),
    (_board_doc(markers=[{"id": "a", "corners": BOARD.corners[0].tolist()}]), r"'markers\[0\].id'"),
    (_board_doc(markers=[{"id": 1, "corners": BOARD.corners[0].tolist()},
                         {"id": 1, "corners": BOARD.corners[1].tolist()}]), "distinct"),
    (_board_doc(markers=[{"id": 5000, "corners": BOARD.corners[0].tolist()}]), r"markers\[0\].id"),
    (_board_doc(markers=[{"id": 1, "corners": [[0, 0, 0], [1, 0, 0], [1, 0.1, 0], [0, 0.1, 0]]}]),
     r"markers\[0\].corners.*not a square"),
    (_board_doc(units="mm"), "'units'"),
    ([1, 2], "JSON object"),
])
def test_bad_board_json_names_the_field(tmp_path, doc, field):
    p = tmp_path / "board.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=field):
        MarkerBoard.from_json(p)


def test_board_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no marker board file"):
        MarkerBoard.from_json(tmp_path / "missing.json")
    (tmp_path / "x.json").write_text("{not json")
    with pytest.raises(ValueError, match="is not JSON"):
        MarkerBoard.from_json(tmp_path / "x.json")


# ---------------------------------------------------------------- intrinsics


@pytest.mark.parametrize("dist", [[0.1, -0.2, 0.001, 0.002, 0.05], []])
@pytest.mark.parametrize("name", ["cam.yaml", "cam.xml", "cam.json"])
def test_intrinsics_round_trip(tmp_path, name, dist):
    cam = CameraIntrinsics(np.array([[1402.5, 0, 955.2], [0, 1399.0, 540.7], [0, 0, 1]]), dist, (1920, 1080))
    cam.to_file(tmp_path / name)
    assert CameraIntrinsics.from_file(tmp_path / name) == cam


def test_intrinsics_read_opencv_sample_yaml(tmp_path):
    p = tmp_path / "out_camera_data.yml"
    p.write_text("%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
                 "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
                 "   data: [ 600., 0., 319.5, 0., 600., 239.5, 0., 0., 1. ]\n"
                 "distortion_coefficients: !!opencv-matrix\n   rows: 5\n   cols: 1\n   dt: d\n"
                 "   data: [ 0.01, 0., 0., 0., 0. ]\n")
    cam = CameraIntrinsics.from_file(p)
    assert cam.fx == 600 and cam.image_size == (640, 480) and cam.dist[0] == 0.01


def test_intrinsics_errors(tmp_path):
    with pytest.raises(ValueError, match="focal lengths fx, fy must be > 0"):
        CameraIntrinsics(np.array([[0.0, 0, 320], [0, 600, 240], [0, 0, 1]]), [], (640, 480))
    with pytest.raises(ValueError, match="focal lengths"):
        CameraIntrinsics(np.array([[600, 0, 320], [0, -600, 240], [0, 0, 1]]), [], (640, 480))
    with pytest.raises(ValueError, match="principal point"):
        CameraIntrinsics(np.array([[600, 0, 900], [0, 600, 240], [0, 0, 1]]), [], (640, 480))
    with pytest.raises(ValueError, match="distortion_coefficients must have"):
        CameraIntrinsics.from_focal(600, (640, 480), dist=[0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="image_width"):
        CameraIntrinsics.from_focal(600, (640, 0))
    with pytest.raises(FileNotFoundError, match="no camera intrinsics file"):
        CameraIntrinsics.from_file(tmp_path / "nope.yaml")
    p = tmp_path / "cam.json"
    p.write_text(json.dumps({"camera_matrix": [[600, 0, 320], [0, 600, 240], [0, 0, 1]], "image_width": 640}))
    with pytest.raises(ValueError, match="'image_height' is missing"):
        CameraIntrinsics.from_file(p)
    p.write_text(json.dumps({"camera_matrix": [[-5, 0, 320], [0, 600, 240], [0, 0, 1]], "image_width": 640,
                             "image_height": 480}))
    with pytest.raises(ValueError, match=r"cam.json: camera_matrix: focal lengths"):
        CameraIntrinsics.from_file(p)
    p = tmp_path / "cam.yaml"
    p.write_text("%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n")
    with pytest.raises(ValueError, match="'camera_matrix' is missing"):
        CameraIntrinsics.from_file(p)
    p.write_text("this: [is not: opencv")
    with pytest.raises(ValueError, match="not an OpenCV YAML/XML file"):
        CameraIntrinsics.from_file(p)
    with pytest.raises(ValueError, match="must end in"):
        CAM.to_file(tmp_path / "cam.txt")


# ---------------------------------------------------------------- camera pose


def test_camera_pose_json_and_look_at(tmp_path):
    assert np.allclose(CAMERA.position, (0, -1, 2.5))
    # the optical axis passes through the target
    R = CAMERA.rotation
    assert np.allclose(R @ np.array([0, 2.5, 0]) + CAMERA.tvec, [0, 0, np.linalg.norm([3.5, 2.5])])
    CAMERA.to_json(tmp_path / "pose.json")
    back = CameraPose.from_json(tmp_path / "pose.json")
    np.testing.assert_allclose(back.rvec, CAMERA.rvec)
    np.testing.assert_allclose(back.tvec, CAMERA.tvec)
    (tmp_path / "bad.json").write_text(json.dumps({"format": "sfanav-camera-pose", "version": 1, "rvec": [0, 0]}))
    with pytest.raises(ValueError, match="'tvec' is missing"):
        CameraPose.from_json(tmp_path / "bad.json")
    (tmp_path / "bad.json").write_text(json.dumps({"version": 3, "rvec": [0, 0, 0], "tvec": [0, 0, 0]}))
    with pytest.raises(ValueError, match="'version' is 3"):
        CameraPose.from_json(tmp_path / "bad.json")
    with pytest.raises(FileNotFoundError):
        CameraPose.from_json(tmp_path / "missing.json")


def test_camera_pose_from_a_board_on_the_floor():
    ground = flat_board(0.3, [(-1.0, 1.5), (1.0, 1.5), (-1.0, 3.5), (1.0, 3.5)], ids=[20, 21, 22, 23])
    img = render(CAM, CAMERA, None, ground=ground, seed=3)
    est = CameraPose.from_image(img, CAM, ground)
    assert np.linalg.norm(est.position - CAMERA.position) < 0.005
    assert np.degrees(np.arccos((np.trace(est.rotation.T @ CAMERA.rotation) - 1) / 2)) < 0.05
    with pytest.raises(ValueError, match="ground board .* is not in the image"):
        CameraPose.from_image(render(CAM, CAMERA, None, seed=4), CAM, ground)


# ---------------------------------------------------------------- pose estimation


def _errors(track, truth):
    ok = track.valid
    pos = np.hypot(track.x - truth[:, 0], track.y - truth[:, 1])[ok]
    head = np.degrees(np.abs(_wrap(track.heading - truth[:, 2])))[ok]
    return pos, head


def test_poses_from_a_given_camera_pose_are_accurate_and_gaps_are_nan(scene):
    truth, frames = scene
    dist = np.linalg.norm(CAMERA.position - np.c_[truth[:, :2], np.full(len(truth), 0.39)], axis=1)
    assert 2.0 <= dist.min() and dist.max() <= 6.0
    track = estimate_poses(frames, CAM, BOARD, camera_pose=CAMERA)
    assert len(track) == len(frames)
    np.testing.assert_array_equal(track.timestamp, [t for t, _ in frames])
    hidden = np.isin(np.arange(len(frames)), HIDDEN)
    np.testing.assert_array_equal(track.valid, ~hidden)
    assert np.isnan(track.poses[hidden]).all() and (track.n_markers[hidden] == 0).all()
    assert np.isnan(track.reprojection_error[hidden]).all() and track.n_gaps == len(HIDDEN)
    assert (track.n_markers[~hidden] >= 1).all()
    pos, head = _errors(track, truth)
    print(f"\nplanar (default), 1920x1080: median position error {np.median(pos) * 1000:.3f} mm "
          f"(max {pos.max() * 1000:.3f}), median heading error {np.median(head):.3f} deg (max {head.max():.3f})")
    assert np.median(pos) <= 0.005 and pos.max() <= 0.005
    assert np.median(head) <= 0.5 and head.max() <= 0.5
    # the 6-DoF diagnostics: the robot stands on the floor, level
    assert np.nanmax(np.abs(track.z)) < 0.02 and np.nanmax(track.tilt) < np.radians(1)


def test_edge_refined_corners_beat_opencv_subpix(scene):
    truth, frames = scene
    from markerscene import robot_to_ground

    from sfanav.groundtruth import MarkerDetector

    errors = {}
    for refinement in ("edges", "subpix"):
        det, errs = MarkerDetector(refinement=refinement), []
        for k in range(8):
            if k in HIDDEN:
                continue
            found = det.detect(frames[k][1], CAM)
            R, t = robot_to_ground(*truth[k])
            for mid, corners in zip(found.ids, found.corners):
                X = BOARD.marker_corners(mid) @ R.T + t
                uv = cv2.projectPoints(X, CAMERA.rvec, CAMERA.tvec, CAM.K, CAM.dist)[0].reshape(-1, 2)
                errs.extend(np.linalg.norm(corners - uv, axis=1))
        errors[refinement] = float(np.median(errs))
        track = estimate_poses(frames, CAM, BOARD, camera_pose=CAMERA, planar=False, detector=det)
        errors[refinement + " 6-DoF"] = float(np.median(_errors(track, truth)[0]))
    print(f"\nmedian corner error: edges {errors['edges']:.3f} px, OpenCV subpix {errors['subpix']:.3f} px; "
          f"median 6-DoF position error: edges {errors['edges 6-DoF'] * 1000:.2f} mm, "
          f"OpenCV subpix {errors['subpix 6-DoF'] * 1000:.2f} mm")
    assert errors["edges"] < 0.1 and errors["edges"] < errors["subpix"] / 3
    assert errors["edges 6-DoF"] < errors["subpix 6-DoF"]


def test_free_6dof_poses(scene):
    truth, frames = scene
    track = estimate_poses(frames, CAM, BOARD, camera_pose=CAMERA, planar=False)
    pos, head = _errors(track, truth)
    print(f"\n6-DoF, 1920x1080: median position error {np.median(pos) * 1000:.2f} mm (max {pos.max() * 1000:.2f}), "
          f"median heading error {np.median(head):.3f} deg (max {head.max():.3f})")
    assert np.median(pos) <= 0.005
    assert np.median(head) <= 0.5


def test_poses_in_blurred_noisy_smaller_images():
    cam = CameraIntrinsics.from_focal(1000.0, (1280, 960))
    rng = np.random.default_rng(11)
    truth = np.c_[rng.uniform(-1.2, 1.2, 12), rng.uniform(0.8, 4.5, 12), rng.uniform(-np.pi, np.pi, 12)]
    frames = [(float(k), render(cam, CAMERA, BOARD, truth[k], seed=k, blur=1.0, noise=4.0)) for k in range(12)]
    track = estimate_poses(frames, cam, BOARD, camera_pose=CAMERA)
    pos, head = _errors(track, truth)
    print(f"\nplanar, 1280x960, blur 1 px, noise 4: median position error {np.median(pos) * 1000:.2f} mm "
          f"(max {pos.max() * 1000:.2f}), median heading error {np.median(head):.3f} deg (max {head.max():.3f})")
    assert track.valid.all()
    assert np.median(pos) <= 0.005 and np.median(head) <= 0.5


def test_poses_through_a_distorting_lens():
    ideal = CameraIntrinsics.from_focal(1000.0, (1280, 960))
    lens = CameraIntrinsics(ideal.K, [-0.12, 0.05, 0.0005, -0.0004, 0.0], ideal.image_size)
    # the lens's image: each distorted pixel samples the ideal (pinhole) image where its ray lands
    w, h = lens.image_size
    grid = np.stack(np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32)), -1)
    und = cv2.undistortPoints(grid.reshape(-1, 1, 2), lens.K, lens.dist, P=lens.K).reshape(h, w, 2)
    rng = np.random.default_rng(5)
    truth = np.c_[rng.uniform(-1.2, 1.2, 6), rng.uniform(0.8, 4.5, 6), rng.uniform(-np.pi, np.pi, 6)]
    frames = []
    for k in range(6):
        img = render(ideal, CAMERA, BOARD, truth[k], seed=k)
        frames.append((float(k), cv2.remap(img, und[..., 0], und[..., 1], cv2.INTER_LINEAR)))
    track = estimate_poses(frames, lens, BOARD, camera_pose=CAMERA)
    pos, head = _errors(track, truth)
    print(f"\nplanar, 1280x960, radial distortion k1=-0.12: median position error {np.median(pos) * 1000:.2f} mm, "
          f"median heading error {np.median(head):.3f} deg")
    assert track.valid.all() and np.median(pos) <= 0.005 and np.median(head) <= 0.5
    # ignoring the distortion costs accuracy
    naive = estimate_poses(frames, ideal, BOARD, camera_pose=CAMERA)
    assert np.median(_errors(naive, truth)[0]) > np.median(pos)


def test_without_a_camera_pose_the_first_robot_pose_is_the_origin(scene):
    truth, frames = scene
    track = estimate_poses(frames[:8], CAM, BOARD)
    first = int(np.argmax(track.valid))
    assert track.x[first] == pytest.approx(0, abs=1e-6) and track.heading[first] == pytest.approx(0, abs=1e-6)
    # the truth in the first pose's frame
    x0, y0, h0 = truth[first]
    c, s = math.cos(h0), math.sin(h0)
    rel = np.c_[c * (truth[:8, 0] - x0) + s * (truth[:8, 1] - y0), -s * (truth[:8, 0] - x0) + c * (truth[:8, 1] - y0)]
    ok = track.valid
    err = np.hypot(track.x[ok] - rel[ok, 0], track.y[ok] - rel[ok, 1])
    assert np.median(err) < 0.03  # the first pose's small tilt error grows with the distance
    np.testing.assert_allclose(_wrap(track.heading[ok] - (truth[:8, 2][ok] - h0)), 0, atol=np.radians(0.5))


def test_camera_pose_from_a_ground_board_in_the_recording(scene):
    truth, _ = scene
    ground = flat_board(0.3, [(-1.0, 1.5), (1.0, 1.5), (-1.0, 3.5), (1.0, 3.5)], ids=[20, 21, 22, 23])
    frames = [(float(k), render(CAM, CAMERA, BOARD, truth[k], ground=ground, seed=k)) for k in range(5)]
    lines = []
    track = estimate_poses(frames, CAM, BOARD, camera_pose=ground, log=lines.append)
    assert "camera pose from the ground board in frame 0" in lines[0]
    pos, head = _errors(track, truth[:5])
    print(f"\nground board: median position error {np.median(pos) * 1000:.2f} mm")
    assert track.valid.all() and np.median(pos) <= 0.01 and np.median(head) <= 0.5
    with pytest.raises(ValueError, match="share marker ids"):
        estimate_poses(frames, CAM, BOARD, camera_pose=box_board(0.1, 0.2, ids=[1, 6, 7, 8, 9]))
    with pytest.raises(ValueError, match="ground board .* is in no frame"):
        estimate_poses(frames[:1], CAM, BOARD, camera_pose=flat_board(0.3, [(0, 2)], ids=[30]))


def test_bad_frames_raise_clear_errors(scene):
    _, frames = scene
    small = np.zeros((480, 640), np.uint8)
    with pytest.raises(ValueError, match="frame 0 of frames is 640x480 pixels but the camera was calibrated at 1920x"):
        estimate_poses([(0.0, small)], CAM, BOARD, camera_pose=CAMERA)
    with pytest.raises(ValueError, match="timestamps must increase strictly"):
        estimate_poses([frames[0], (frames[0][0], frames[1][1])], CAM, BOARD, camera_pose=CAMERA)
    with pytest.raises(ValueError, match="max_reprojection_error must be > 0"):
        estimate_poses(frames[:1], CAM, BOARD, max_reprojection_error=0)


# ---------------------------------------------------------------- inputs and the pose log


def test_pose_log_feeds_from_recording(scene, tmp_path):
    truth, frames = scene
    track = estimate_poses(frames, CAM, BOARD, camera_pose=CAMERA)
    log = tmp_path / "poses.csv"
    assert track.to_csv(log) == int(track.valid.sum())
    assert sorted(f.name for f in tmp_path.iterdir()) == ["poses.csv"]
    header = log.read_text().splitlines()[0]
    assert header == "timestamp,x,y,heading,z,tilt,n_markers,reprojection_error"
    assert "nan" not in log.read_text().lower()
    with pytest.raises(FileExistsError):
        track.to_csv(log)
    back = PoseTrack.from_csv(log)
    np.testing.assert_allclose(back.x, track.x[track.valid], atol=1e-6)
    # the robot's own camera: images between the marker frames, named by their timestamps
    images = tmp_path / "images"
    images.mkdir()
    ts = np.array([1.05, 1.25, 1.42, 1.93])
    for t in ts:
        cv2.imwrite(str(images / f"{t:.2f}.png"), np.full((8, 16, 3), 128, np.uint8))
    ds = Dataset.from_recording(images, log)
    ok = track.valid
    np.testing.assert_allclose(ds.poses[:, 0], np.interp(ts, track.timestamp[ok], track.x[ok]), atol=1e-6)
    np.testing.assert_allclose(ds.poses[:, 1], np.interp(ts, track.timestamp[ok], track.y[ok]), atol=1e-6)
    # and the interpolated positions are close to the truth where the robot was filmed on both sides
    near = np.interp(ts, track.timestamp[ok], truth[ok, 0])
    np.testing.assert_allclose(ds.poses[:, 0], near, atol=0.01)


def test_pose_log_without_any_pose_is_refused(tmp_path, scene):
    _, frames = scene
    track = estimate_poses([frames[k] for k in HIDDEN], CAM, BOARD, camera_pose=CAMERA)
    assert track.n_gaps == len(HIDDEN) and not np.any(track.x == 0)
    with pytest.raises(ValueError, match="no frame has a pose"):
        track.to_csv(tmp_path / "poses.csv")
    assert not (tmp_path / "poses.csv").exists()


def test_video_and_image_folder_inputs(scene, tmp_path):
    truth, frames = scene
    video = tmp_path / "run.avi"
    w = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"FFV1"), 10, CAM.image_size, False)
    for _, img in frames[:6]:
        w.write(img)
    w.release()
    src = open_frames(video)
    ts = [t for t, _ in src]
    np.testing.assert_allclose(ts, np.arange(6) / 10)
    track = estimate_poses(video, CAM, BOARD, camera_pose=CAMERA)
    np.testing.assert_array_equal(track.valid, ~np.isin(np.arange(6), HIDDEN))
    pos, _ = _errors(track, truth[:6])
    assert np.median(pos) <= 0.005
    folder = tmp_path / "frames"
    folder.mkdir()
    for t, img in frames[:3]:
        cv2.imwrite(str(folder / f"{t:.3f}.png"), img)
    track = estimate_poses(folder, CAM, BOARD, camera_pose=CAMERA)
    np.testing.assert_allclose(track.timestamp, [t for t, _ in frames[:3]])
    (tmp_path / "list.csv").write_text("timestamp,image\n" + "".join(f"{t},frames/{t:.3f}.png\n"
                                                                  for t, _ in frames[:2]))
    assert [t for t, _ in open_frames(tmp_path / "list.csv")] == [t for t, _ in frames[:2]]


def test_input_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        open_frames(tmp_path / "missing.mp4")
    empty = tmp_path / "empty.avi"
    w = cv2.VideoWriter(str(empty), cv2.VideoWriter_fourcc(*"FFV1"), 10, (64, 48), False)
    w.release()
    with pytest.raises(ValueError, match="no frames|not a video"):
        open_frames(empty)
    (tmp_path / "junk.mp4").write_bytes(b"not a video at all")
    with pytest.raises(ValueError, match="no frames|not a video"):
        open_frames(tmp_path / "junk.mp4")
    folder = tmp_path / "imgs"
    folder.mkdir()
    with pytest.raises(ValueError, match="holds no images"):
        open_frames(folder)
    cv2.imwrite(str(folder / "frame_a.png"), np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="not a timestamp"):
        open_frames(folder)
    (tmp_path / "list.csv").write_text("timestamp,image\n0.5,nothere.png\n")
    with pytest.raises(FileNotFoundError, match="nothere.png"):
        open_frames(tmp_path / "list.csv")


# ---------------------------------------------------------------- calibration

CAL = CameraIntrinsics(np.array([[1000.0, 0, 645.0], [0, 1000.0, 478.0], [0, 0, 1]]), np.zeros(5), (1280, 960))


def _views(n, size, seed=0):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        R = cv2.Rodrigues(np.radians([rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-10, 10)]))[0]
        centre = np.r_[rng.uniform(-0.05, 0.05, 2), rng.uniform(0.5, 0.8)]
        yield cv2.Rodrigues(R)[0].ravel(), centre - R @ np.r_[np.asarray(size) / 2, 0]


def test_calibrate_recovers_the_focal_length_from_chessboards(tmp_path):
    imgs = [render_chessboard(CAL, (9, 6), 0.03, r, t, seed=k)
            for k, (r, t) in enumerate(_views(8, (8 * 0.03, 5 * 0.03)))]
    for k, img in enumerate(imgs):
        cv2.imwrite(str(tmp_path / f"view{k:02d}.png"), img)
    res = calibrate(tmp_path, "chessboard:9x6:0.03")
    print(f"chessboard: fx {res.intrinsics.fx:.2f}, fy {res.intrinsics.fy:.2f} (true 1000), rms {res.rms:.3f} px")
    assert res.used == list(range(8)) and res.n_images == 8
    assert abs(res.intrinsics.fx / 1000 - 1) < 0.01 and abs(res.intrinsics.fy / 1000 - 1) < 0.01
    np.testing.assert_allclose(res.intrinsics.K[:2, 2], [645, 478], atol=5)
    assert res.rms < 0.5
    with pytest.raises(ValueError, match="only 0 of 8 images show the chessboard:7x4:0.03"):
        calibrate(tmp_path, "chessboard:7x4:0.03")
    with pytest.raises(ValueError, match="only 2 of 2 images .* at least 5"):
        calibrate(imgs[:2], "chessboard:9x6:0.03")


def test_calibrate_with_charuco():
    pattern = CalibrationPattern.parse("charuco:7x5:0.04:0.03:DICT_4X4_50")
    board = pattern.charuco_board()
    imgs = [render_charuco(CAL, board, r, t, seed=k) for k, (r, t) in enumerate(_views(6, (0.28, 0.2), seed=1))]
    res = calibrate(imgs, pattern)
    print(f"charuco: fx {res.intrinsics.fx:.2f}, fy {res.intrinsics.fy:.2f} (true 1000), rms {res.rms:.3f} px")
    assert abs(res.intrinsics.fx / 1000 - 1) < 0.01 and abs(res.intrinsics.fy / 1000 - 1) < 0.01


@pytest.mark.parametrize("text", ["chessboard:9x6", "chessboard:9by6:0.02", "charuco:7x5:0.04",
                                  "charuco:7x5:0.04:0.05", "grid:9x6:0.02", "chessboard:1x6:0.02",
                                  "chessboard:9x6:-1", "charuco:7x5:0.04:0.03:DICT_NOPE"])
def test_bad_patterns(text):
    with pytest.raises(ValueError):
        CalibrationPattern.parse(text)


def test_calibrate_input_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        calibrate(tmp_path / "missing", "chessboard:9x6:0.03")
    with pytest.raises(ValueError, match="holds no images"):
        calibrate(tmp_path, "chessboard:9x6:0.03")
    with pytest.raises(ValueError, match="unlike image 0"):
        calibrate([np.zeros((40, 60), np.uint8), np.zeros((30, 60), np.uint8)], "chessboard:9x6:0.03")
    assert os.listdir(tmp_path) == []
