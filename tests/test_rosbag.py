"""ROS bags: simulated runs written to ROS 1 and ROS 2 bags (raw and
compressed images, odometry at its own rate, ground truth) and imported
again give the dataset the simulator exported; bad bags raise errors that
name the problem; an interrupted import leaves no dataset."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from sfanav import Dataset, sim
from sfanav.data import BagWriter, bag_info, write_estimates
from sfanav.data.ros_messages import decode_image, quaternion_from_yaw, typestore, yaw_from_quaternion

from bagtools import (BAD_IMAGES, PERIOD, STAMP0, good_images, jpeg_bytes, png_bytes, raw_image, stamp_text,
                      write_camera_bag)

T0 = 1000.0  # s: bag times start here (a header stamp of 0 means "unset" in ROS)


def wrapped(a):
    return np.angle(np.exp(1j * np.asarray(a, float)))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The demo garden at 60x8 (RGB and gray) and 32x32 omnidirectional, 20 frames a run."""
    root = tmp_path_factory.mktemp("sim")
    cams = {"panorama": sim.PanoramicCamera(60, 8), "gray": sim.PanoramicCamera(60, 8, rgb=False),
            "omni": sim.OmniCamera(32)}
    return {k: sim.simulate("demo", root / k, 0, max_frames=20, camera=c, progress=False) for k, c in cams.items()}


def write_run(path, ds, *, fmt="raw", encoding=None, odometry=True, ground_truth=True, t0=T0):
    """One run of a dataset as a bag recorded by a robot: /camera/image, /odom, /ground_truth."""
    with BagWriter(path) as bag:
        for i, img in enumerate(ds.images()):
            t = t0 + float(ds.timestamps[i])
            bag.add_image("/camera/image", t, img, fmt=fmt, encoding=encoding)
            if odometry:
                bag.add_odometry("/odom", t, ds.odometry[i])
            if ground_truth:
                bag.add_pose("/ground_truth", t, ds.poses[i])
    return path


def assert_same_run(got, want, t0=T0):
    assert len(got) == len(want)
    np.testing.assert_array_equal(got.frames, np.arange(len(want)))
    np.testing.assert_allclose(got.timestamps - t0, want.timestamps, atol=1e-6)
    np.testing.assert_allclose(got.poses[:, :2], want.poses[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrapped(got.poses[:, 2] - want.poses[:, 2]), 0, atol=1e-9)
    np.testing.assert_allclose(got.odometry[:, :2], want.odometry[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrapped(got.odometry[:, 2] - want.odometry[:, 2]), 0, atol=1e-9)
    assert got.runs.tolist() == want.runs.tolist()
    assert got.cameras.tolist() == want.cameras.tolist()
    assert got.conditions.tolist() == want.conditions.tolist()
    assert got.metadata["image_shapes"] == want.metadata["image_shapes"]
    for a, b in zip(got.images(), want.images()):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("camera, name, fmt, encoding", [
    ("panorama", "run.bag", "raw", None),        # ROS 1, rgb8
    ("panorama", "run.mcap", "png", None),       # ROS 2 MCAP file, compressed PNG
    ("panorama", "run", "raw", "bgr8"),          # ROS 2 bag folder (SQLite), bgr8
    ("gray", "run.bag", "raw", "mono8"),         # ROS 1, mono8
    ("omni", "run.mcap", "raw", None),           # omnidirectional images stay as they are
])
def test_round_trip_through_a_bag_gives_the_direct_export(runs, tmp_path, camera, name, fmt, encoding):
    direct = runs[camera]
    for run in ("train", "test"):
        want = direct.select(run=run)
        bag = write_run(tmp_path / f"{run}-{name}", want, fmt=fmt, encoding=encoding)
        got = Dataset.from_bag(bag, tmp_path / f"ds-{run}", image_topic="/camera/image", odom_topic="/odom",
                               pose_topic="/ground_truth", run=run, log=lambda m: None)
        assert_same_run(got, want)
        again = Dataset(tmp_path / f"ds-{run}")  # what a later command reads
        assert_same_run(again, want)
        assert again.metadata["source"] == "rosbag"
        assert again.metadata["bags"][0]["ros"] == (1 if name.endswith(".bag") else 2)


def test_several_bags_become_the_runs_of_one_dataset(runs, tmp_path):
    direct = runs["panorama"]
    bags = [write_run(tmp_path / "train.bag", direct.select(run="train")),
            write_run(tmp_path / "test.mcap", direct.select(run="test"), fmt="png")]
    got = Dataset.from_bag(bags, tmp_path / "ds", image_topic="/camera/image", odom_topic="/odom",
                           pose_topic="/ground_truth", log=lambda m: None)  # runs named after the bags
    assert sorted(set(got.runs.tolist())) == ["test", "train"]
    np.testing.assert_array_equal(got.frames, np.arange(len(direct)))
    for run in ("train", "test"):
        a, b = got.select(run=run), direct.select(run=run)
        np.testing.assert_allclose(a.poses, b.poses, atol=1e-9)
        np.testing.assert_allclose(a.odometry[:, :2], b.odometry[:, :2], atol=1e-9)
        for x, y in zip(a.images(), b.images()):
            np.testing.assert_array_equal(x, y)
    assert [b["run"] for b in got.metadata["bags"]] == ["train", "test"]
    with pytest.raises(ValueError, match="one run name per bag: 2 bags, 1 run names"):
        Dataset.from_bag(bags, tmp_path / "x", odom_topic="/odom", run=["a"])
    with pytest.raises(ValueError, match="a run name of its own"):
        Dataset.from_bag(bags, tmp_path / "x", odom_topic="/odom", run=["a", "a"])
    with pytest.raises(ValueError, match="one run name per bag"):
        Dataset.from_bag(bags, tmp_path / "x", odom_topic="/odom", run="a")


def test_jpeg_images_are_kept_as_the_robot_sent_them(runs, tmp_path):
    want = runs["panorama"].select(run="train")
    bag = write_run(tmp_path / "run.bag", want, fmt="jpeg")
    got = Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", log=lambda m: None)  # the only image topic
    assert all(p.suffix == ".jpg" for p in got.image_paths)
    assert np.isnan(got.poses).all()  # no ground-truth topic given: unknown, not zeros
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as r:
        conns = [c for c in r.connections if c.topic == "/camera/image"]
        sent = [bytes(r.deserialize(raw, c.msgtype).data) for c, _, raw in r.messages(connections=conns)]
    assert [p.read_bytes() for p in got.image_paths] == sent
    for a, b in zip(got.images(), want.images()):
        assert a.shape == b.shape and np.abs(a.astype(int) - b).mean() < 20


def linear_pose(t):
    """Motion linear in time, the heading turning through +-pi."""
    return 1.0 + 0.5 * t, -0.2 * t, (3.0 + 0.4 * t + np.pi) % (2 * np.pi) - np.pi


def write_rates(path, *, img_t, odo_t, gt_t=None, fmt="raw", image=None):
    img = np.full((8, 60, 3), 90, np.uint8) if image is None else image
    with BagWriter(path) as bag:
        events = [(t, "img") for t in img_t] + [(t, "odo") for t in odo_t] + [(t, "gt") for t in (gt_t or [])]
        for t, kind in sorted(events):
            if kind == "img":
                bag.add_image("/cam", t, img, fmt=fmt)
            elif kind == "odo":
                bag.add_odometry("/odom", t, linear_pose(t - T0))
            else:
                bag.add_pose("/gt", t, linear_pose(t - T0))
    return path


@pytest.mark.parametrize("name", ["rates.bag", "rates.mcap"])
def test_odometry_at_its_own_rate_is_interpolated_at_the_image_times(tmp_path, name):
    img_t = T0 + 0.05 + np.arange(30) / 7.0  # 7 Hz camera
    odo_t = T0 + np.arange(0, 4.5, 0.02)      # 50 Hz odometry
    gt_t = T0 + 0.013 + np.arange(0, 4.4, 0.1)  # 10 Hz ground truth
    bag = write_rates(tmp_path / name, img_t=img_t, odo_t=odo_t, gt_t=list(gt_t))
    ds = Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", pose_topic="/gt", log=lambda m: None)
    assert len(ds) == 30
    want = np.array([linear_pose(t - T0) for t in img_t])
    for got in (ds.odometry, ds.poses):
        np.testing.assert_allclose(got[:, :2], want[:, :2], atol=1e-9)
        np.testing.assert_allclose(wrapped(got[:, 2] - want[:, 2]), 0, atol=1e-9)
    np.testing.assert_allclose(ds.timestamps, img_t, atol=1e-6)


def test_images_no_pose_covers_are_an_error_or_dropped_or_kept_empty(tmp_path):
    img_t = T0 + np.arange(0, 10, 0.5)
    odo_t = list(T0 + np.arange(1.0, 9.0, 0.1))   # starts after the camera, stops before it
    gt_t = list(T0 + np.arange(0, 4.0, 0.2)) + list(T0 + np.arange(7.0, 10.0, 0.2))  # a 3 s gap
    bag = write_rates(tmp_path / "gaps.bag", img_t=img_t, odo_t=odo_t, gt_t=gt_t)
    with pytest.raises(ValueError, match=r"image\(s\) lie outside the time span of the odometry topic /odom.*"
                                         r"outside='drop'"):
        Dataset.from_bag(bag, tmp_path / "a", odom_topic="/odom", log=lambda m: None)
    assert not (tmp_path / "a").exists()
    with pytest.raises(ValueError, match=r"fall in gaps of the ground truth topic /gt longer than max_gap=1.0 s"):
        Dataset.from_bag(bag, tmp_path / "b", pose_topic="/gt", log=lambda m: None)
    notes = []
    ds = Dataset.from_bag(bag, tmp_path / "c", odom_topic="/odom", pose_topic="/gt", outside="drop", log=notes.append)
    t = ds.timestamps - T0
    assert np.all((t >= 1.0) & (t <= 8.9)) and not np.any((t > 3.8) & (t < 7.0))
    gaps = ds.metadata["bags"][0]["poses"]["ground_truth"]["gap_intervals_s"]
    assert gaps == [[pytest.approx(T0 + 3.8), pytest.approx(T0 + 7.0)]]
    assert any("/gt: 1 gap(s) longer than 1.0 s" in n for n in notes)
    ds = Dataset.from_bag(bag, tmp_path / "d", odom_topic="/odom", pose_topic="/gt", outside="empty",
                          log=lambda m: None)
    assert len(ds) == len(img_t)
    t = ds.timestamps - T0
    gap = (t > 3.8) & (t < 7.0)
    assert np.isnan(ds.poses[gap]).all() and np.isfinite(ds.poses[~gap]).all()
    assert np.isnan(ds.odometry[(t < 1.0) | (t > 8.9)]).all()
    # a larger max_gap interpolates across
    assert len(Dataset.from_bag(bag, tmp_path / "e", pose_topic="/gt", max_gap=5.0, log=lambda m: None)) == len(img_t)


def test_stamps_unsorted_or_missing_are_errors(tmp_path):
    img = np.zeros((8, 60), np.uint8)
    with BagWriter(tmp_path / "unsorted.bag") as bag:
        for k, t in enumerate([1.0, 2.0, 1.5, 3.0]):  # header stamps out of order, recorded in order
            bag.add_odometry("/odom", T0 + t, (t, 0, 0), record_time=T0 + k)
            bag.add_image("/cam", T0 + k + 0.5, img)
    with pytest.raises(ValueError, match=r"odometry topic /odom: timestamps must increase strictly; message 2 "
                                         r".*--time bag"):
        Dataset.from_bag(tmp_path / "unsorted.bag", tmp_path / "a", odom_topic="/odom")
    ds = Dataset.from_bag(tmp_path / "unsorted.bag", tmp_path / "b", odom_topic="/odom", time="bag",
                          outside="drop", log=lambda m: None)
    assert len(ds) == 3
    with BagWriter(tmp_path / "zero.mcap") as bag:
        for k in range(3):
            bag.add_odometry("/odom", T0 + k, (k, 0, 0))
            bag.add_image("/cam", 0.0, img, record_time=T0 + k + 0.5)  # a driver that never sets the stamp
    with pytest.raises(ValueError, match=r"message 0 of /cam has no header stamp \(0\); pass time='bag'"):
        Dataset.from_bag(tmp_path / "zero.mcap", tmp_path / "c", odom_topic="/odom")
    with BagWriter(tmp_path / "images.bag") as bag:
        for k in range(3):
            bag.add_odometry("/odom", T0 + k, (k, 0, 0))
        for k, t in enumerate([0.5, 1.5, 1.2]):
            bag.add_image("/cam", T0 + t, img, record_time=T0 + k)
    with pytest.raises(ValueError, match=r"image topic /cam: timestamps must increase strictly; image 2 "
                                         r"\(t=1001.2 s\) is earlier than image 1 \(t=1001.5 s\)"):
        Dataset.from_bag(tmp_path / "images.bag", tmp_path / "d", odom_topic="/odom")


def test_missing_topics_and_wrong_types_are_named(runs, tmp_path):
    bag = write_run(tmp_path / "run.bag", runs["panorama"].select(run="test"), ground_truth=False)
    with pytest.raises(ValueError, match=r"has no topic /ground_truth \(the ground truth topic\); its topics: "
                                         r"/camera/image \(sensor_msgs/msg/Image, 20\), /odom"):
        Dataset.from_bag(bag, tmp_path / "a", odom_topic="/odom", pose_topic="/ground_truth")
    with pytest.raises(TypeError, match="topic /odom .* carries nav_msgs/msg/Odometry, not image"):
        Dataset.from_bag(bag, tmp_path / "a", image_topic="/odom", odom_topic="/odom")
    with pytest.raises(TypeError, match="topic /camera/image .* carries sensor_msgs/msg/Image, not odometry"):
        Dataset.from_bag(bag, tmp_path / "a", odom_topic="/camera/image")
    with pytest.raises(ValueError, match="give the odometry topic"):
        Dataset.from_bag(bag, tmp_path / "a")
    no_images = tmp_path / "odom.bag"
    with BagWriter(no_images) as w:
        w.add_odometry("/odom", T0, (0, 0, 0))
        w.add_odometry("/odom", T0 + 1, (1, 0, 0))
    with pytest.raises(ValueError, match="has no image topic"):
        Dataset.from_bag(no_images, tmp_path / "a", odom_topic="/odom")
    two = tmp_path / "two.bag"
    with BagWriter(two) as w:
        for k in range(2):
            w.add_odometry("/odom", T0 + k, (k, 0, 0))
            w.add_image("/left", T0 + k, np.zeros((4, 8), np.uint8))
            w.add_image("/right", T0 + k, np.zeros((4, 8), np.uint8))
    with pytest.raises(ValueError, match=r"several image topics \(/left, /right\); choose one"):
        Dataset.from_bag(two, tmp_path / "a", odom_topic="/odom")
    assert not (tmp_path / "a").exists()
    with pytest.raises(ValueError, match="outside must be one of"):
        Dataset.from_bag(two, tmp_path / "a", odom_topic="/odom", outside="fill")
    with pytest.raises(ValueError, match="max_gap must be a positive"):
        Dataset.from_bag(two, tmp_path / "a", odom_topic="/odom", max_gap=0)


@pytest.mark.parametrize("name", ["cut.bag", "cut.mcap", "cut"])
def test_truncated_bags_are_reported(runs, tmp_path, name):
    bag = write_run(tmp_path / name, runs["panorama"].select(run="test"), fmt="png")
    f = bag / "cut.db3" if bag.is_dir() else bag
    f.write_bytes(f.read_bytes()[: f.stat().st_size * 2 // 3])
    with pytest.raises(ValueError, match=f"cannot read the bag .*{name}.*truncated"):
        Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom")
    with pytest.raises(ValueError, match="cannot read the bag"):
        bag_info(bag)
    assert not (tmp_path / "ds").exists()


def test_not_a_bag(tmp_path):
    with pytest.raises(FileNotFoundError, match="no bag at"):
        bag_info(tmp_path / "missing.bag")
    (tmp_path / "notes.bag").write_text("hello\n")
    with pytest.raises(ValueError, match="cannot read the bag .*notes.bag"):
        Dataset.from_bag(tmp_path / "notes.bag", tmp_path / "ds", odom_topic="/odom")


def test_an_interrupted_import_leaves_no_dataset(runs, tmp_path, monkeypatch):
    import sfanav.data.rosbag as rosbag

    bag = write_run(tmp_path / "run.bag", runs["panorama"].select(run="train"))
    calls = []

    def interrupted(img):
        calls.append(1)
        if len(calls) == 5:
            raise KeyboardInterrupt
        return real(img)

    real = rosbag.encode_png
    monkeypatch.setattr(rosbag, "encode_png", interrupted)
    with pytest.raises(KeyboardInterrupt):
        Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", log=lambda m: None)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.bag"]  # neither the dataset nor its temporary folder
    (tmp_path / "ds").mkdir()  # an empty folder is filled
    monkeypatch.undo()
    ds = Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", log=lambda m: None)
    assert len(ds) == 20
    calls.clear()
    monkeypatch.setattr(rosbag, "encode_png", interrupted)
    with pytest.raises(KeyboardInterrupt):  # replacing it is interrupted: it stays
        Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", overwrite=True, log=lambda m: None)
    assert len(Dataset(tmp_path / "ds")) == 20
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds", "run.bag"]


def test_an_undecodable_image_is_named_and_leaves_no_dataset(tmp_path):
    """A bag written with rosbags itself: three good PNG images, then a broken JPEG."""
    from rosbags.rosbag1 import Writer

    store = typestore(1)
    T = store.types

    def header(k, t):
        return T["std_msgs/msg/Header"](seq=k, stamp=T["builtin_interfaces/msg/Time"](
            sec=int(t), nanosec=int(round((t % 1) * 1e9))), frame_id="camera")

    import cv2

    png = np.frombuffer(cv2.imencode(".png", np.zeros((8, 60, 3), np.uint8))[1].tobytes(), np.uint8)
    broken = np.frombuffer(b"\xff\xd8\xff not really a jpeg", np.uint8)
    bag = tmp_path / "bad.bag"
    with Writer(bag) as w:
        cam = w.add_connection("/cam", "sensor_msgs/msg/CompressedImage", typestore=store)
        odo = w.add_connection("/odom", "geometry_msgs/msg/PoseStamped", typestore=store)
        for k in range(5):
            t = T0 + k
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(k), y=0.0, z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
            w.write(odo, int(t * 1e9), store.serialize_ros1(T["geometry_msgs/msg/PoseStamped"](
                header=header(k, t), pose=pose), "geometry_msgs/msg/PoseStamped"))
            if k < 4:
                img = T["sensor_msgs/msg/CompressedImage"](header=header(k, t + 0.5),
                                                           format="jpeg" if k == 3 else "png",
                                                           data=broken if k == 3 else png)
                w.write(cam, int((t + 0.5) * 1e9), store.serialize_ros1(img, "sensor_msgs/msg/CompressedImage"))
    with pytest.raises(ValueError, match=r"image 3 of /cam in .*bad.bag \(t=1003.5 s\): cannot decode the compressed "
                                         r"image \(jpeg, 21 bytes\)"):
        Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", log=lambda m: None)
    assert not (tmp_path / "ds" / "metadata.json").exists()


def test_without_rosbags_the_error_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags", None)
    with pytest.raises(ImportError, match=r'pip install "sfanav\[ros\]"'):
        bag_info(tmp_path / "x.bag")
    with pytest.raises(ImportError, match=r'pip install "sfanav\[ros\]"'):
        BagWriter(tmp_path / "x.bag")


def image_msg(encoding, h, w, data, step, bigendian=0):
    store = typestore(2)
    T = store.types
    hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="c")
    return T["sensor_msgs/msg/Image"](header=hdr, height=h, width=w, encoding=encoding, is_bigendian=bigendian,
                                      step=step, data=np.asarray(data, np.uint8).reshape(-1))


def test_raw_encodings_with_padded_rows():
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (5, 7, 3), dtype=np.uint8)
    alpha = np.full((5, 7, 1), 200, np.uint8)
    pad = np.zeros((5, 3), np.uint8)
    cases = {
        "rgb8": (rgb, rgb), "bgr8": (rgb[:, :, ::-1], rgb), "8UC3": (rgb[:, :, ::-1], rgb),
        "rgba8": (np.concatenate([rgb, alpha], 2), rgb), "bgra8": (np.concatenate([rgb[:, :, ::-1], alpha], 2), rgb),
        "mono8": (rgb[:, :, 0], rgb[:, :, 0]),
    }
    for enc, (px, want) in cases.items():
        rows = np.concatenate([px.reshape(5, -1), pad], 1)  # 3 bytes of padding a row
        got = decode_image(image_msg(enc, 5, 7, rows, rows.shape[1]))
        np.testing.assert_array_equal(got, want, err_msg=enc)
    v16 = rng.integers(0, 65536, (5, 7)).astype(np.uint16)
    for big in (0, 1):
        raw = v16.astype(">u2" if big else "<u2").view(np.uint8)
        np.testing.assert_array_equal(decode_image(image_msg("mono16", 5, 7, raw, 14, big)),
                                      (v16 >> 8).astype(np.uint8))
    with pytest.raises(ValueError, match="encoding 'bayer_rggb16' is not supported"):
        decode_image(image_msg("bayer_rggb16", 5, 7, np.zeros(70), 14))
    with pytest.raises(ValueError, match="a 7x5 rgb8 image needs 21 bytes a row"):
        decode_image(image_msg("rgb8", 5, 7, np.zeros(50), 21))


def test_heading_is_the_quaternions_yaw():
    for yaw in np.linspace(-3.1, 3.1, 13):
        assert yaw_from_quaternion(*quaternion_from_yaw(yaw)) == pytest.approx(yaw, abs=1e-12)
        # scaled, and with the robot pitched on a slope: the yaw stays
        x, y, z, w = quaternion_from_yaw(yaw)
        p = 0.2  # pitch about the robot's own y axis: q = q_yaw * q_pitch
        qx, qy, qz, qw = 0.0, math.sin(p / 2), 0.0, math.cos(p / 2)
        q = (w * qx + x * qw + y * qz - z * qy, w * qy - x * qz + y * qw + z * qx,
             w * qz + x * qy - y * qx + z * qw, w * qw - x * qx - y * qy - z * qz)
        assert yaw_from_quaternion(*(3 * c for c in q)) == pytest.approx(yaw, abs=1e-12)
    assert math.isnan(yaw_from_quaternion(0, 0, 0, 0))


def test_bag_writer_is_atomic_and_refuses_to_overwrite(tmp_path):
    with pytest.raises(RuntimeError):
        with BagWriter(tmp_path / "run.bag") as bag:
            bag.add_odometry("/odom", T0, (0, 0, 0))
            raise RuntimeError("robot fell over")
    assert list(tmp_path.iterdir()) == []
    with BagWriter(tmp_path / "run.bag") as bag:
        bag.add_odometry("/odom", T0, (0, 0, 0))
    with pytest.raises(FileExistsError, match="exists; pass overwrite=True"):
        BagWriter(tmp_path / "run.bag")
    with pytest.raises(ValueError, match="NAME.bag .* NAME.mcap"):
        BagWriter(tmp_path / "run.txt")
    with pytest.raises(ValueError, match="finite number of seconds >= 0"):
        with BagWriter(tmp_path / "neg.bag") as bag:
            bag.add_odometry("/odom", -1.0, (0, 0, 0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.bag"]


@pytest.mark.parametrize("name", ["est.bag", "est.mcap"])
def test_estimates_replay_as_pose_stamped_and_odometry(tmp_path, name):
    from rosbags.highlevel import AnyReader

    t = T0 + np.arange(5) * 0.2
    xy = np.c_[np.arange(5.0), -np.arange(5.0)]
    fused = np.c_[xy + 0.1, np.linspace(-3, 3, 5)]
    xy[2] = np.nan  # an image without an estimate
    assert write_estimates(tmp_path / name, t, xy, fused) == 9
    with AnyReader([tmp_path / name]) as r:
        got = {}
        for c, ns, raw in r.messages():
            m = r.deserialize(raw, c.msgtype)
            got.setdefault((c.topic, c.msgtype), []).append((ns, m))
    assert set(got) == {("/sfanav/estimate", "geometry_msgs/msg/PoseStamped"),
                        ("/sfanav/fused", "nav_msgs/msg/Odometry")}
    est = got[("/sfanav/estimate", "geometry_msgs/msg/PoseStamped")]
    assert [ns for ns, _ in est] == [int(round(v * 1e9)) for v in np.delete(t, 2)]
    assert [(m.pose.position.x, m.pose.position.y) for _, m in est] == [tuple(v) for v in np.delete(xy, 2, 0)]
    assert all(m.header.frame_id == "map" for _, m in est)
    fz = got[("/sfanav/fused", "nav_msgs/msg/Odometry")]
    from sfanav.data.ros_messages import pose_of

    np.testing.assert_allclose([pose_of(m) for _, m in fz], fused, atol=1e-12)
    with pytest.raises(ValueError, match="estimates are written to NAME.bag"):
        write_estimates(tmp_path / "est.csv", t, xy)


def test_bag_info_lists_topics_types_and_counts(runs, tmp_path):
    bag = write_run(tmp_path / "run", runs["panorama"].select(run="test"), fmt="jpeg")
    info = bag_info(bag)
    assert info.ros == 2 and info.start == pytest.approx(T0 + runs["panorama"].select(run="test").timestamps[0])
    assert [(t.name, t.msgtype, t.count) for t in info.topics] == [
        ("/camera/image", "sensor_msgs/msg/CompressedImage", 20),
        ("/ground_truth", "geometry_msgs/msg/PoseStamped", 20),
        ("/odom", "nav_msgs/msg/Odometry", 20)]
    text = info.describe()
    assert "sensor_msgs/msg/CompressedImage" in text and str(Path(bag)) in text


# ---------------------------------------------------------------- bad images




@pytest.mark.parametrize("case", list(BAD_IMAGES))
def test_a_bad_image_is_one_error_naming_it_and_leaves_any_dataset_as_it_was(tmp_path, case):
    """Image 2 of 4 is bad: the error names the topic, the message and its
    stamp; no dataset is left, and an existing one that --overwrite would
    replace stays as it was."""
    images, words = BAD_IMAGES[case]
    bag = write_camera_bag(tmp_path / "bad.bag", images)
    with pytest.raises(ValueError) as err:
        Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", log=lambda m: None)
    msg = str(err.value)
    assert msg.startswith(f"image 2 of /cam in {bag} (t={stamp_text(STAMP0 + 2 * PERIOD)} s)"), msg
    for w in words:
        assert w in msg, msg
    assert "\n" not in msg
    assert not (tmp_path / "ds").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.bag"]  # no temporary folder left either
    # over a complete dataset: it stays as it was
    good = write_camera_bag(tmp_path / "good.bag", [raw_image(i) for i in good_images(3)])
    before = Dataset.from_bag(good, tmp_path / "ds", odom_topic="/odom", log=lambda m: None)
    files = sorted((p.relative_to(tmp_path / "ds"), p.read_bytes()) for p in (tmp_path / "ds").rglob("*")
                   if p.is_file())
    with pytest.raises(ValueError, match=r"image 2 of /cam"):
        Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", overwrite=True, log=lambda m: None)
    after = sorted((p.relative_to(tmp_path / "ds"), p.read_bytes()) for p in (tmp_path / "ds").rglob("*")
                   if p.is_file())
    assert after == files
    assert len(Dataset(tmp_path / "ds")) == len(before) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.bag", "ds", "good.bag"]


@pytest.mark.parametrize("case", ["16UC3", "yuv422", "truncated raw", "raw of another size", "gray among colour"])
def test_bad_raw_images_are_found_before_anything_is_written(tmp_path, monkeypatch, case):
    """Raw images are checked in the first pass (encoding, size, data length), with the stamps."""
    import sfanav.data.rosbag as rosbag

    def never(img):
        raise AssertionError("an image was encoded before the bad one was found")

    monkeypatch.setattr(rosbag, "encode_png", never)
    bag = write_camera_bag(tmp_path / "bad.bag", BAD_IMAGES[case][0])
    with pytest.raises(ValueError, match="image 2 of /cam"):
        Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", log=lambda m: None)


def test_bags_with_raw_images_of_different_sizes_are_refused_before_writing(tmp_path):
    a = write_camera_bag(tmp_path / "a.bag", [raw_image(i) for i in good_images(3)])
    b = write_camera_bag(tmp_path / "b.bag", [raw_image(i[:, :30]) for i in good_images(3)],
                         stamps=[STAMP0 + 10**9 + k * PERIOD for k in range(3)])
    with pytest.raises(ValueError, match=r"image 0 of /cam in .*b.bag \(t=1733000001.123456789 s\) has shape "
                                         r"\(8, 30, 3\), unlike \(8, 60, 3\) of the images of .*a.bag"):
        Dataset.from_bag([a, b], tmp_path / "ds", odom_topic="/odom", log=lambda m: None)
    assert not (tmp_path / "ds").exists()


def test_a_bad_image_that_is_left_out_does_not_matter(tmp_path):
    """An image no pose covers is not written (outside='drop'), so it is not decoded either."""
    imgs = good_images(4)
    images = [raw_image(i) for i in imgs[:3]] + [raw_image(imgs[3], "yuv422")]
    stamps = [STAMP0 + k * PERIOD for k in range(3)] + [STAMP0 + 100 * PERIOD]  # far after the odometry
    bag = write_camera_bag(tmp_path / "late.bag", images, stamps=stamps,
                           odom=[STAMP0 + k * PERIOD for k in range(-1, 4)])
    ds = Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", outside="drop", log=lambda m: None)
    assert len(ds) == 3


def test_bayer_images_are_demosaiced(tmp_path):
    """bayer_rggb8 (and the other 8-bit patterns) as cv_bridge reads them:
    a smooth colour image mosaiced and demosaiced comes back close to itself."""
    y, x = np.mgrid[0:16, 0:24]
    rgb = np.dstack([40 + 8 * x, 200 - 6 * y, 60 + 3 * x + 2 * y]).astype(np.uint8)  # strong, distinct channels
    patterns = {"bayer_rggb8": "rggb", "bayer_bggr8": "bggr", "bayer_gbrg8": "gbrg", "bayer_grbg8": "grbg"}
    for enc, pat in patterns.items():
        mosaic = np.zeros((16, 24), np.uint8)
        for k, c in enumerate(pat):
            dy, dx = divmod(k, 2)
            mosaic[dy::2, dx::2] = rgb[dy::2, dx::2, "rgb".index(c)]
        got = decode_image(image_msg(enc, 16, 24, mosaic, 24))
        assert got.shape == (16, 24, 3), enc
        err = np.abs(got[2:-2, 2:-2].astype(int) - rgb[2:-2, 2:-2]).mean(axis=(0, 1))
        assert (err < 6).all(), (enc, err)
    bag = write_camera_bag(tmp_path / "bayer.bag", [raw_image(np.zeros((8, 60), np.uint8), "bayer_rggb8")] * 3)
    ds = Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", log=lambda m: None)
    assert ds.image(0).shape == (8, 60, 3)


def test_cut_jpeg_and_png_files_are_refused_before_opencv_sees_them():
    """OpenCV either fails on a cut file with a message of its own on stderr
    (libpng's) or, in some versions, decodes the part that is there."""
    from sfanav.data.images import truncation
    from sfanav.data.ros_messages import decode_compressed

    img = good_images(1, h=32, w=48)[0]
    for name, data in (("JPEG", jpeg_bytes(img)), ("PNG", png_bytes(img))):
        assert truncation(data) is None
        assert truncation(data + bytes(64)) is None  # padding after the end is allowed
        np.testing.assert_array_equal(decode_compressed(np.frombuffer(data + bytes(64), np.uint8)).shape, img.shape)
        for cut in (len(data) - 1, len(data) - 2, len(data) // 2, 20):
            assert name in truncation(data[:cut]) and "truncated" in truncation(data[:cut]), (name, cut)
            with pytest.raises(ValueError, match=f"cannot decode the compressed image .*: the {name} data ends"):
                decode_compressed(np.frombuffer(data[:cut], np.uint8), name.lower())
    assert truncation(b"neither a JPEG nor a PNG") is None


# ---------------------------------------------------------------- exact stamps


def header_ns(msg):
    return int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)


@pytest.mark.parametrize("ros", [1, 2])
def test_import_keeps_the_images_exact_header_stamps(tmp_path, ros):
    stamps = [STAMP0 + k * PERIOD for k in range(5)]
    bag = write_camera_bag(tmp_path / ("run.bag" if ros == 1 else "run"), [raw_image(i) for i in good_images(5)],
                           ros=ros)
    ds = Dataset.from_bag(bag, tmp_path / "ds", odom_topic="/odom", log=lambda m: None)
    assert ds.stamps_ns.dtype == np.int64 and ds.stamps_ns.tolist() == stamps
    assert Dataset(tmp_path / "ds").stamps_ns.tolist() == stamps
    np.testing.assert_allclose(ds.timestamps, np.array(stamps) / 1e9, rtol=0, atol=1e-6)
    # --time bag: the record times, exactly too
    ds = Dataset.from_bag(bag, tmp_path / "bag-times", odom_topic="/odom", time="bag", log=lambda m: None)
    assert ds.stamps_ns.tolist() == stamps  # write_camera_bag records each message at its stamp


@pytest.mark.parametrize("name", ["est.bag", "est.mcap"])
def test_estimates_stamped_in_integer_nanoseconds_are_exact(tmp_path, name):
    from rosbags.highlevel import AnyReader

    stamps = np.array([STAMP0 + k * PERIOD for k in range(6)], np.int64)
    xy = np.c_[np.arange(6.0), np.zeros(6)]
    fused = np.c_[xy, np.zeros(6)]
    assert write_estimates(tmp_path / name, stamps, xy, fused, unit="ns") == 12
    with AnyReader([tmp_path / name]) as r:
        got = {}
        for c, ns, raw in r.messages():
            m = r.deserialize(raw, c.msgtype)
            got.setdefault(c.topic, []).append((ns, header_ns(m)))
    for topic in ("/sfanav/estimate", "/sfanav/fused"):
        assert got[topic] == [(int(v), int(v)) for v in stamps]
    # float seconds cannot carry them: refused, and nanoseconds passed as seconds are caught
    with pytest.raises(TypeError, match="integer nanoseconds"):
        write_estimates(tmp_path / "f.bag", stamps / 1e9, xy, unit="ns")
    with pytest.raises(ValueError, match="unit='ns'"):
        write_estimates(tmp_path / "f.bag", stamps, xy)
    with pytest.raises(ValueError, match="unit must be 's'"):
        write_estimates(tmp_path / "f.bag", stamps, xy, unit="ms")
    with pytest.raises(ValueError, match="stamp must be at least 0"):
        write_estimates(tmp_path / "f.bag", -stamps, xy, unit="ns")
    assert not (tmp_path / "f.bag").exists()

