"""``sfanav import`` and ``sfanav localize --out NAME.bag``: the README's
"Your own robot" path from bags to a model to estimates that replay, and
the one-line errors of bad bags."""

import csv
import sys

import numpy as np
import pytest

from sfanav import Dataset, sim
from sfanav.app.cli import main
from sfanav.data import BagWriter
from bagtools import BAD_IMAGES, PERIOD, STAMP0, good_images, raw_image, stamp_text, write_camera_bag
from clitools import TINY_TOML, assert_one_line_error, run

T0 = 1000.0


def write_bag(path, ds, *, fmt="raw", odom_rate=None):
    """A robot's recording: images, odometry (at the images' times, or at ``odom_rate`` Hz from the
    images' odometry interpolated), ground truth."""
    with BagWriter(path) as bag:
        t = T0 + ds.timestamps
        for i, img in enumerate(ds.images()):
            bag.add_image("/camera/image_raw" + ("/compressed" if fmt != "raw" else ""), t[i], img, fmt=fmt)
            bag.add_pose("/ground_truth", t[i], ds.poses[i])
        if odom_rate is None:
            for i in range(len(ds)):
                bag.add_odometry("/odom", t[i], ds.odometry[i])
        else:
            tt = np.arange(t[0], t[-1], 1.0 / odom_rate)
            h = np.unwrap(ds.odometry[:, 2])
            for s in tt:
                bag.add_odometry("/odom", s, (np.interp(s, t, ds.odometry[:, 0]), np.interp(s, t, ds.odometry[:, 1]),
                                              np.interp(s, t, h)))
            bag.add_odometry("/odom", t[-1], (ds.odometry[-1, 0], ds.odometry[-1, 1], h[-1]))
    return path


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    root = tmp_path_factory.mktemp("bags")
    ds = sim.simulate("demo", root / "sim", seed=3, max_frames=40, camera=sim.PanoramicCamera(60, 8), progress=False)
    (root / "tiny.toml").write_text(TINY_TOML)
    return {"root": root, "sim": ds, "config": root / "tiny.toml",
            "train": write_bag(root / "run1.bag", ds.select(run="train"), odom_rate=23.0),
            "test": write_bag(root / "run2.mcap", ds.select(run="test"), fmt="jpeg")}


def test_list_prints_topics_types_and_counts(bags, capsys):
    code, out, err = run(capsys, "import", bags["train"], bags["test"], "--list")
    assert code == 0, err
    first, second = out.split("\n\n")
    assert "(ROS 2)" in second.splitlines()[0] and "sensor_msgs/msg/CompressedImage" in second
    lines = first.splitlines()
    assert "(ROS 1)" in lines[0]
    rows = {ln.split()[0]: ln.split()[1:3] for ln in lines[2:]}
    assert rows["/camera/image_raw"] == ["sensor_msgs/msg/Image", "40"]
    assert rows["/ground_truth"] == ["geometry_msgs/msg/PoseStamped", "40"]
    assert rows["/odom"][0] == "nav_msgs/msg/Odometry"


def test_from_bags_to_a_model_to_estimates_that_replay(bags, tmp_path, capsys):
    """The README's "Your own robot": import, train without ground truth, localize with odometry into a bag."""
    from rosbags.highlevel import AnyReader

    garden = tmp_path / "garden"
    code, out, err = run(capsys, "import", bags["train"], bags["test"], "--odom-topic", "/odom",
                         "--run", "train", "test", "--out", garden, "--no-progress")
    assert code == 0, err
    assert out.strip() == f"wrote 80 images to {garden} (runs train, test)"
    assert "run1.bag: images from /camera/image_raw, the bag's only image topic" in err
    assert "run2.mcap: images from /camera/image_raw/compressed" in err
    ds = Dataset(garden)
    assert len(ds) == 80 and ds.has_odometry and np.isnan(ds.poses).all()
    want = bags["sim"].select(run="train")
    # odometry at 23 Hz, interpolated at the image times: the simulated odometry to within its curvature
    np.testing.assert_allclose(ds.select(run="train").odometry[:, :2], want.odometry[:, :2], atol=0.01)
    model = tmp_path / "robot.sfa"
    code, out, err = run(capsys, "train", "--dataset", garden, "--config", bags["config"], "--supervision",
                         "odometry", "--out", model, "--no-progress")
    assert code == 0, err
    est_bag, est_csv = tmp_path / "estimates.bag", tmp_path / "estimates.csv"
    code, out, err = run(capsys, "localize", model, garden, "--run", "test", "--odometry", "--out", est_bag,
                         "--out", est_csv, "--no-progress")
    assert code == 0, err
    assert f"to {est_bag} and {est_csv}" in out
    with open(est_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 40
    with AnyReader([est_bag]) as r:
        msgs = {}
        for c, ns, raw in r.messages():
            msgs.setdefault(c.topic, []).append((ns, r.deserialize(raw, c.msgtype)))
    assert sorted(msgs) == ["/sfanav/estimate", "/sfanav/fused"]
    stamps = np.round(ds.select(run="test").timestamps * 1e9).astype(np.int64)
    for topic in msgs:
        assert [ns for ns, _ in msgs[topic]] == stamps.tolist()
    est = np.array([(m.pose.position.x, m.pose.position.y) for _, m in msgs["/sfanav/estimate"]])
    fused = np.array([(m.pose.pose.position.x, m.pose.pose.position.y) for _, m in msgs["/sfanav/fused"]])
    np.testing.assert_allclose(est, [(float(r["x"]), float(r["y"])) for r in rows], atol=1e-4)
    np.testing.assert_allclose(fused, [(float(r["fused_x"]), float(r["fused_y"])) for r in rows], atol=1e-4)
    run2 = tmp_path / "run2"  # one bag, with its ground truth
    code, out, err = run(capsys, "import", bags["test"], "--image-topic", "/camera/image_raw/compressed",
                         "--odom-topic", "/odom", "--pose-topic", "/ground_truth", "--run", "test", "--out", run2,
                         "--no-progress")
    assert code == 0 and out.strip() == f"wrote 40 images to {run2} (run test)", err
    assert np.isfinite(Dataset(run2).poses).all()
    # a ROS 2 bag of the estimates alone
    code, out, err = run(capsys, "localize", model, run2, "--out", tmp_path / "estimates.mcap", "--no-progress",
                         "--frame-id", "odom")
    assert code == 0, err
    with AnyReader([tmp_path / "estimates.mcap"]) as r:
        assert {c.topic: c.msgcount for c in r.connections} == {"/sfanav/estimate": 40}
        _, _, raw = next(r.messages())
        assert r.deserialize(raw, "geometry_msgs/msg/PoseStamped").header.frame_id == "odom"


def test_bad_bags_and_arguments_are_one_line_errors(bags, tmp_path, capsys):
    code, _, err = run(capsys, "import", tmp_path / "nothere.bag", "--odom-topic", "/odom", "--out", tmp_path / "a")
    assert_one_line_error(code, err, "bag", "nothere.bag", "does not exist")
    code, _, err = run(capsys, "import", bags["train"], "--odom-topic", "/wheel_odom", "--out", tmp_path / "a")
    assert_one_line_error(code, err, "no topic /wheel_odom", "/odom (nav_msgs/msg/Odometry")
    code, _, err = run(capsys, "import", bags["train"], "--odom-topic", "/camera/image_raw", "--out", tmp_path / "a")
    assert_one_line_error(code, err, "carries sensor_msgs/msg/Image, not odometry")
    code, _, err = run(capsys, "import", bags["train"], "--odom-topic", "/odom")
    assert_one_line_error(code, err, "--out DATASET")
    code, _, err = run(capsys, "import", bags["train"], "--out", tmp_path / "a")
    assert_one_line_error(code, err, "--odom-topic, --pose-topic or both")
    code, _, err = run(capsys, "import", bags["train"], "--odom-topic", "/odom", "--max-gap", "0", "--out",
                       tmp_path / "a")
    assert code == 2 and "finite number > 0" in err
    truncated = tmp_path / "cut.bag"
    truncated.write_bytes(bags["train"].read_bytes()[:50_000])
    code, _, err = run(capsys, "import", truncated, "--odom-topic", "/odom", "--out", tmp_path / "a")
    assert_one_line_error(code, err, "cannot read the bag", "cut.bag", "reindex")
    code, _, err = run(capsys, "import", truncated, "--list")
    assert_one_line_error(code, err, "cannot read the bag")
    code, _, err = run(capsys, "import", bags["train"], "--pose-topic", "/ground_truth", "--out", tmp_path / "a",
                       "--no-progress")
    assert code == 0, err
    code, _, err = run(capsys, "import", bags["train"], "--pose-topic", "/ground_truth", "--out", tmp_path / "a")
    assert_one_line_error(code, err, "is not empty", "--overwrite")


def test_gaps_are_reported_on_stderr(bags, tmp_path, capsys):
    bag = tmp_path / "gap.bag"
    ds = bags["sim"].select(run="test")
    with BagWriter(bag) as w:
        for i, img in enumerate(ds.images()):
            t = T0 + ds.timestamps[i]
            w.add_image("/cam", t, img)
            if not 10 <= i < 20:  # the wheel encoder driver died for a while
                w.add_odometry("/odom", t, ds.odometry[i])
    code, _, err = run(capsys, "import", bag, "--odom-topic", "/odom", "--out", tmp_path / "a")
    assert_one_line_error(code, err, "10 image(s) fall in gaps of the odometry topic /odom", "--max-gap")
    code, out, err = run(capsys, "import", bag, "--odom-topic", "/odom", "--out", tmp_path / "a", "--outside", "drop",
                         "--no-progress")
    assert code == 0
    assert "odometry topic /odom: 1 gap(s) longer than 1.0 s" in err and "left out" in err
    assert "wrote 30 images" in out and "10 images without a pose left out" in out


def test_an_interrupted_import_exits_130_and_leaves_no_dataset(bags, tmp_path, capsys, monkeypatch):
    import sfanav.data.rosbag as rosbag

    real, calls = rosbag.encode_png, []

    def interrupted(img):
        calls.append(1)
        if len(calls) == 7:
            raise KeyboardInterrupt
        return real(img)

    monkeypatch.setattr(rosbag, "encode_png", interrupted)
    code, _, err = run(capsys, "import", bags["train"], "--odom-topic", "/odom", "--out", tmp_path / "ds",
                       "--no-progress")
    assert code == 130 and "interrupted" in err
    assert not (tmp_path / "ds").exists() and list(tmp_path.iterdir()) == []
    code, _, err = run(capsys, "train", "--dataset", tmp_path / "ds", "--config", bags["config"], "--out",
                       tmp_path / "m.sfa", "--no-progress")
    assert_one_line_error(code, err, "ds")


@pytest.fixture(scope="module")
def model(bags):
    """A tiny model trained on the simulated dataset's ground truth."""
    path = bags["root"] / "gt.sfa"
    assert main(["train", "--dataset", str(bags["sim"].root), "--config", str(bags["config"]), "--out", str(path),
                 "--no-progress"]) == 0
    return path


def test_without_rosbags_the_commands_say_what_to_install(bags, model, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags", None)
    code, _, err = run(capsys, "import", bags["train"], "--list")
    assert_one_line_error(code, err, 'pip install "sfanav[ros]"')
    code, _, err = run(capsys, "localize", model, bags["sim"].root, "--out", tmp_path / "e.bag", "--no-progress")
    assert_one_line_error(code, err, 'pip install "sfanav[ros]"')
    assert not (tmp_path / "e.bag").exists()
    code, _, err = run(capsys, "localize", model, bags["sim"].root, "--out", tmp_path / "e.csv", "--no-progress")
    assert code == 0, err  # CSV needs no rosbags


def test_localize_a_video_into_a_bag_stamps_by_its_frame_rate(bags, model, tmp_path, capsys):
    import cv2
    from rosbags.highlevel import AnyReader

    video = tmp_path / "run.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (60, 8))
    for i, img in enumerate(bags["sim"].select(run="test").images()):
        writer.write(cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
        if i == 5:
            break
    writer.release()
    code, _, err = run(capsys, "localize", model, video, "--out", tmp_path / "v.bag", "--no-progress")
    assert code == 0, err
    with AnyReader([tmp_path / "v.bag"]) as r:
        assert [ns for _, ns, _ in r.messages()] == [i * 200_000_000 for i in range(6)]


def test_localize_into_a_bag_needs_image_times(bags, model, tmp_path, capsys):
    folder = tmp_path / "imgs"
    folder.mkdir()
    from sfanav.data import write_image

    for i, img in enumerate(bags["sim"].select(run="test").images()):
        write_image(folder / f"img{i:03d}.png", img)
        if i == 3:
            break
    code, _, err = run(capsys, "localize", model, folder, "--out", tmp_path / "e.bag")
    assert_one_line_error(code, err, "a bag needs the images' times", "image folder")
    code, _, err = run(capsys, "localize", model, folder, "--out", tmp_path / "e.csv", "--out", tmp_path / "e.csv")
    assert_one_line_error(code, err, "same file twice")


@pytest.mark.parametrize("name", ["est.txt", "est", "est.bag2", "est.db"])
def test_localize_refuses_an_out_name_it_writes_no_format_for(bags, model, tmp_path, capsys, name):
    """--out est.db3 once wrote a CSV under a ROS 2 bag's name (exit 0); .db3
    is a bag now, and a name of no format --out knows is refused before any
    image is read, naming the formats."""
    code, _, err = run(capsys, "localize", model, bags["train"], "--out", tmp_path / name, "--no-progress")
    assert_one_line_error(code, err, f"--out {tmp_path / name}: localize writes NAME.csv (frame,x,y), NAME.tum "
                                     "(TUM trajectory: timestamp x y z qx qy qz qw, as evo reads it), NAME.bag "
                                     "(ROS 1 bag), NAME.mcap or NAME.db3 (ROS 2 bag, MCAP or SQLite)")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_localize_into_a_folder_it_cannot_write_fails_before_computing(bags, model, tmp_path, capsys, monkeypatch):
    """A folder that cannot be written (here /sys, which even root cannot
    write into) fails at once, naming the file asked for, not a temporary
    ``.part`` one, and before any image is localized."""
    import tempfile

    from sfanav.localization.localizer import Localizer

    try:
        fd, p = tempfile.mkstemp(dir="/sys")
    except OSError:
        pass
    else:  # pragma: no cover - a machine where /sys is writable
        import os

        os.close(fd)
        os.unlink(p)
        pytest.skip("/sys is writable here")

    def never(*a, **k):
        raise AssertionError("localized before finding that the output cannot be written")

    monkeypatch.setattr(Localizer, "predict", never)
    for out in ("/sys/est.csv", "/sys/est.bag", "/sys/est.db3"):
        code, _, err = run(capsys, "localize", model, bags["sim"].root, "--run", "test", "--out", out,
                           "--no-progress")
        assert_one_line_error(code, err, f"cannot write the output {out}: Permission denied")
        assert ".part" not in err
    with pytest.raises(PermissionError) as exc:  # the library names the bag too, not its temporary folder
        BagWriter("/sys/est.db3")
    assert exc.value.filename == "/sys/est.db3" and ".part" not in str(exc.value)


@pytest.mark.parametrize("case", ["half a jpeg", "half a png", "yuv422", "truncated raw", "jpeg of another size"])
def test_a_bad_image_is_one_line_and_an_existing_dataset_survives(tmp_path, capsys, case):
    images, words = BAD_IMAGES[case]
    bad = write_camera_bag(tmp_path / "bad.bag", images)
    args = ["--image-topic", "/cam", "--odom-topic", "/odom", "--out", tmp_path / "ds", "--no-progress"]
    code, _, err = run(capsys, "import", bad, *args)
    assert_one_line_error(code, err, f"image 2 of /cam in {bad} (t={stamp_text(STAMP0 + 2 * PERIOD)} s)", *words)
    assert not (tmp_path / "ds").exists()
    good = write_camera_bag(tmp_path / "good.bag", [raw_image(i) for i in good_images(3)])
    code, _, err = run(capsys, "import", good, *args)
    assert code == 0, err
    code, _, err = run(capsys, "import", bad, *args, "--overwrite")
    assert_one_line_error(code, err, "image 2 of /cam", *words)
    assert len(Dataset(tmp_path / "ds")) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.bag", "ds", "good.bag"]


@pytest.mark.parametrize("ros", [1, 2])
def test_estimates_carry_their_images_exact_header_stamps(bags, model, tmp_path, capsys, ros):
    """A robot's bag with Unix header stamps (odd nanoseconds, not exact as
    float seconds) -> sfanav import -> localize --out est.bag / est.mcap / est.db3:
    every estimate's header stamp equals its image's, as integers, so
    ROS's exact-time synchronisation pairs them."""
    from rosbags.highlevel import AnyReader

    imgs = list(bags["sim"].select(run="test").images())[:12]
    stamps = [STAMP0 + k * PERIOD for k in range(len(imgs))]
    assert any(round(s / 1e9 * 1e9) != s for s in stamps)
    bag = write_camera_bag(tmp_path / ("robot.bag" if ros == 1 else "robot"), [raw_image(i) for i in imgs], ros=ros)
    ds = tmp_path / "ds"
    code, _, err = run(capsys, "import", bag, "--image-topic", "/cam", "--odom-topic", "/odom", "--out", ds,
                       "--no-progress")
    assert code == 0, err
    assert Dataset(ds).stamps_ns.tolist() == stamps
    for name in ("est.bag", "est.mcap", "est.db3"):  # .db3: a ROS 2 bag in one SQLite file
        code, _, err = run(capsys, "localize", model, ds, "--odometry", "--out", tmp_path / name, "--out",
                           tmp_path / f"{name}.csv", "--no-progress")
        assert code == 0, err
        with AnyReader([tmp_path / name]) as r:
            got = {}
            for c, ns, raw in r.messages():
                m = r.deserialize(raw, c.msgtype)
                got.setdefault(c.topic, []).append((ns, m.header.stamp.sec * 10**9 + m.header.stamp.nanosec))
        assert sorted(got) == ["/sfanav/estimate", "/sfanav/fused"]
        for topic, pairs in got.items():
            assert [h for _, h in pairs] == stamps, topic  # header stamps, exactly
            assert [ns for ns, _ in pairs] == stamps, topic  # and the bag's record times

