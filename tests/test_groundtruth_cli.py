"""The ``sfanav groundtruth`` and ``sfanav calibrate`` commands on synthetic
perspective renderings of a marker box at known poses and of chessboards."""

import cv2
import numpy as np
import pytest
from markerscene import render, render_chessboard

from sfanav.app.cli import main
from sfanav.data import Dataset
from sfanav.groundtruth import CameraIntrinsics, CameraPose, PoseTrack, box_board

CAM = CameraIntrinsics.from_focal(1400.0, (1920, 1080))
CAMERA = CameraPose.look_at((0.0, -1.0, 2.5), (0.0, 2.5, 0.0))
BOARD = box_board(0.12, 0.18, ids=[1, 2, 3, 4, 5], height=0.3)
HIDDEN = (3,)


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A folder of frames named by their timestamps, the camera's calibration
    and pose, the board file, and the true poses."""
    root = tmp_path_factory.mktemp("gt")
    rng = np.random.default_rng(3)
    n = 7
    truth = np.c_[rng.uniform(-1.0, 1.0, n), rng.uniform(1.0, 4.0, n), rng.uniform(-np.pi, np.pi, n)]
    frames = root / "frames"
    frames.mkdir()
    times = 2.0 + 0.2 * np.arange(n)
    for k in range(n):
        img = render(CAM, CAMERA, None if k in HIDDEN else BOARD, truth[k], seed=k)
        cv2.imwrite(str(frames / f"{times[k]:.1f}.png"), img)
    CAM.to_file(root / "camera.yaml")
    CAMERA.to_json(root / "camera-pose.json")
    BOARD.to_json(root / "board.json")
    return root, truth, times


def _gt(root, out, *extra):
    return main(["groundtruth", str(root / "frames"), "--camera", str(root / "camera.yaml"),
                 "--camera-pose", str(root / "camera-pose.json"), "--out", str(out), "--no-progress", *extra])


def test_groundtruth_writes_an_accurate_pose_log_with_gaps_left_out(recording, tmp_path, capsys):
    root, truth, times = recording
    out = tmp_path / "poses.csv"
    assert _gt(root, out, "--board", str(root / "board.json")) == 0
    assert "wrote 6 poses" in capsys.readouterr().out
    track = PoseTrack.from_csv(out)
    keep = np.setdiff1d(np.arange(len(truth)), HIDDEN)
    np.testing.assert_allclose(track.timestamp, times[keep])
    pos = np.hypot(track.x - truth[keep, 0], track.y - truth[keep, 1])
    head = np.degrees(np.abs(_wrap(track.heading - truth[keep, 2])))
    assert np.median(pos) <= 0.005 and np.median(head) <= 0.5
    assert "nan" not in out.read_text().lower()
    # the box given on the command line is the same board
    out2 = tmp_path / "poses2.csv"
    assert _gt(root, out2, "--board", "box:0.18:1,2,3,4,5:0.3", "--marker-size", "0.12") == 0
    np.testing.assert_allclose(PoseTrack.from_csv(out2).x, track.x, atol=1e-6)
    # and the log feeds Dataset.from_recording
    images = tmp_path / "robot"
    images.mkdir()
    for t in (2.1, 2.5):
        cv2.imwrite(str(images / f"{t:.2f}.png"), np.full((8, 16, 3), 128, np.uint8))
    ds = Dataset.from_recording(images, out)
    np.testing.assert_allclose(ds.poses[:, 0], np.interp([2.1, 2.5], track.timestamp, track.x), atol=1e-6)


def test_groundtruth_without_a_camera_pose_starts_at_the_origin(recording, tmp_path, capsys):
    root, truth, times = recording
    out = tmp_path / "p.csv"
    assert main(["groundtruth", str(root / "frames"), "--camera", str(root / "camera.yaml"), "--board",
                 str(root / "board.json"), "--out", str(out), "--no-progress"]) == 0
    assert "ground frame is the robot's first detected pose" in capsys.readouterr().err
    track = PoseTrack.from_csv(out)
    assert abs(track.x[0]) < 1e-6 and abs(track.y[0]) < 1e-6 and abs(track.heading[0]) < 1e-6
    # distances between poses are those of the truth (the frame is rigidly moved)
    keep = np.setdiff1d(np.arange(len(truth)), HIDDEN)
    d_est = np.hypot(*(np.c_[track.x, track.y][1:] - [track.x[0], track.y[0]]).T)
    d_true = np.hypot(*(truth[keep, :2][1:] - truth[keep[0], :2]).T)
    np.testing.assert_allclose(d_est, d_true, atol=0.03)


@pytest.mark.parametrize("args, message", [
    (["--board", "box:0.18:1,2,3"], "needs --marker-size"),
    (["--board", "box:x:1,2"], "expected box:BOX_SIZE"),
    (["--board", "box:0.18:1,2,3,4,5,6", "--marker-size", "0.1"], "1 to 5 marker ids"),
    (["--board", "nowhere.json"], "board file nowhere.json does not exist"),
    (["--board", "box:0.18:1", "--marker-size", "-1"], "--marker-size must be a positive"),
    (["--board", "box:0.18:1", "--marker-size", "0.3"], "does not fit"),
    (["--board", "box:0.18:1", "--marker-size", "0.1", "--dictionary", "DICT_NOPE"], "DICT_NOPE"),
])
def test_groundtruth_bad_input_is_one_line(recording, tmp_path, capsys, args, message):
    root, _, _ = recording
    out = tmp_path / "p.csv"
    with pytest.raises(SystemExit) as e:
        _gt(root, out, *args)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_groundtruth_refuses_a_wrong_calibration_and_an_existing_log(recording, tmp_path, capsys):
    root, _, _ = recording
    CameraIntrinsics.from_focal(1000.0, (1280, 960)).to_file(tmp_path / "other.yaml")
    with pytest.raises(SystemExit) as e:
        main(["groundtruth", str(root / "frames"), "--camera", str(tmp_path / "other.yaml"), "--board",
              str(root / "board.json"), "--out", str(tmp_path / "p.csv"), "--no-progress"])
    assert e.value.code == 2 and "1280x960" in capsys.readouterr().err
    assert not (tmp_path / "p.csv").exists()
    (tmp_path / "p.csv").write_text("keep me")
    with pytest.raises(SystemExit):
        _gt(root, tmp_path / "p.csv", "--board", str(root / "board.json"))
    assert "--overwrite" in capsys.readouterr().err and (tmp_path / "p.csv").read_text() == "keep me"
    with pytest.raises(SystemExit):
        main(["groundtruth", str(tmp_path / "missing"), "--camera", str(root / "camera.yaml"), "--board",
              str(root / "board.json"), "--out", str(tmp_path / "q.csv")])
    assert "recording" in capsys.readouterr().err


CAL = CameraIntrinsics(np.array([[1000.0, 0, 645.0], [0, 1000.0, 478.0], [0, 0, 1]]), np.zeros(5), (1280, 960))


def test_calibrate_writes_a_calibration_that_groundtruth_reads(tmp_path, capsys):
    rng = np.random.default_rng(1)
    folder = tmp_path / "calib"
    folder.mkdir()
    for k in range(7):
        R = cv2.Rodrigues(np.radians([rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-10, 10)]))[0]
        centre = np.r_[rng.uniform(-0.05, 0.05, 2), rng.uniform(0.5, 0.8)]
        t = centre - R @ np.r_[8 * 0.03 / 2, 5 * 0.03 / 2, 0]
        cv2.imwrite(str(folder / f"v{k}.png"), render_chessboard(CAL, (9, 6), 0.03, cv2.Rodrigues(R)[0].ravel(), t, seed=k))
    out = tmp_path / "cam.yaml"
    assert main(["calibrate", str(folder), "--pattern", "chessboard:9x6:0.03", "--out", str(out), "--no-progress"]) == 0
    assert "from 7 of 7 images" in capsys.readouterr().out
    k = CameraIntrinsics.from_file(out)
    assert abs(k.fx / 1000 - 1) < 0.01 and abs(k.fy / 1000 - 1) < 0.01 and k.image_size == (1280, 960)
    for args, message in [
        (["--pattern", "chessboard:7x4:0.03", "--out", str(tmp_path / "b.yaml")], "only 0 of 7 images"),
        (["--pattern", "chess:9x6", "--out", str(tmp_path / "b.yaml")], "bad calibration pattern"),
        (["--pattern", "chessboard:9x6:0.03", "--out", str(tmp_path / "b.txt")], "ends in .yaml"),
        (["--pattern", "chessboard:9x6:0.03", "--out", str(out)], "--overwrite"),
    ]:
        with pytest.raises(SystemExit) as e:
            main(["calibrate", str(folder), "--no-progress", *args])
        err = capsys.readouterr().err
        assert e.value.code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "b.yaml").exists() and not (tmp_path / "b.txt").exists()
