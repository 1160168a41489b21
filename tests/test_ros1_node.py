"""The ROS 1 node (sfanav ros-node) against a real ROS master: roscore on a
free port, the node, ``rosbag play`` of a small recorded bag and
``rosbag record`` of what the node publishes; every image gets an estimate
and a fused pose with its exact stamp, equal to the batch ``localize`` of
the same bag. Skipped when ROS 1 is not installed."""

import csv
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import xmlrpc.client
from pathlib import Path

import numpy as np
import pytest

from sfanav.odometry.ros1_node import covariance_6x6, map_to_odom, yaw_of

import sfanav

# the sfanav the tests import (the installed wheel in CI, the checkout's python/ in development), for the node's
# subprocesses
PYTHON = str(Path(sfanav.__file__).resolve().parents[1])
STAMP0 = 1_733_000_000_123_456_789
PERIOD = 50_000_003  # ns: 20 Hz, odd nanoseconds


def _ros_missing():
    if shutil.which("roscore") is None or shutil.which("rosbag") is None:
        return "roscore / rosbag not installed (Debian: apt-get install ros-core python3-rosbag)"
    r = subprocess.run([sys.executable, "-c", "from sfanav.odometry.ros1_node import import_rospy; import_rospy(); "
                        "import nav_msgs.msg, sensor_msgs.msg, geometry_msgs.msg, tf2_msgs.msg"],
                       env={**os.environ, "PYTHONPATH": PYTHON}, capture_output=True, text=True, timeout=60)
    return None if r.returncode == 0 else f"rospy or the ROS message packages not importable: {r.stderr.strip()[-200:]}"


def test_transforms_and_covariances():
    class Q:
        def __init__(self, yaw, n=1.0):
            self.x, self.y, self.z, self.w = 0.0, 0.0, n * math.sin(yaw / 2), n * math.cos(yaw / 2)

    assert abs(yaw_of(Q(2.5, n=3.0)) - 2.5) < 1e-12
    with pytest.raises(ValueError, match="zero"):
        yaw_of(Q(0.0, n=0.0))
    # map -> odom composed with odom -> base is map -> base
    fused, odo = np.array([5.0, -2.0, 2.9]), np.array([1.0, 3.0, -2.8])
    x, y, yaw = map_to_odom(fused, odo)
    c, s = math.cos(yaw), math.sin(yaw)
    np.testing.assert_allclose([x + c * odo[0] - s * odo[1], y + s * odo[0] + c * odo[1]], fused[:2], atol=1e-12)
    assert abs(np.angle(np.exp(1j * (yaw + odo[2] - fused[2])))) < 1e-12
    C = np.array(covariance_6x6(np.array([[1.0, 0.1, 0.2], [0.1, 2.0, 0.3], [0.2, 0.3, 3.0]]))).reshape(6, 6)
    assert C[0, 0] == 1 and C[1, 5] == 0.3 and C[5, 5] == 3 and C[2, 2] == 1e6 and C[0, 2] == 0


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(cond, what, timeout=30.0):
    t = time.monotonic()
    while time.monotonic() - t < timeout:
        try:
            if cond():
                return
        except (OSError, xmlrpc.client.Fault):
            pass
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {what}")


def _stop(proc, sig=signal.SIGINT, timeout=15):
    if proc.poll() is None:
        os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(5)


@pytest.fixture(scope="module")
def ros(tmp_path_factory):
    reason = _ros_missing()
    if reason is not None:
        if os.environ.get("SFANAV_REQUIRE_ROS"):  # CI (scripts/test.sh) installs ROS: a skip there would hide a failure
            pytest.fail(f"SFANAV_REQUIRE_ROS is set but {reason}")
        pytest.skip(reason)
    root = tmp_path_factory.mktemp("ros")
    port = _free_port()
    env = {**os.environ, "ROS_MASTER_URI": f"http://127.0.0.1:{port}", "ROS_HOME": str(root / "ros_home"),
           "ROS_LOG_DIR": str(root / "ros_log"), "ROS_IP": "127.0.0.1", "PYTHONPATH": PYTHON}
    core = subprocess.Popen(["roscore", "-p", str(port)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    master = xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"])
    try:
        _wait(lambda: master.getSystemState("/test")[0] == 1, "roscore")
        yield {"env": env, "master": master, "root": root}
    finally:
        _stop(core)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The tiny model, its test run as a ROS 1 bag (raw images on /cam, nav_msgs/Odometry on /odom at the images'
    stamps and between them) and the batch localize of that bag."""
    from clitools import tiny_dataset
    from sfanav.app.cli import main
    from sfanav.data.rosbag_writer import BagWriter

    root = tmp_path_factory.mktemp("rosdata")
    ds, cfg = tiny_dataset(root)
    model = root / "tiny.sfa"
    assert main(["train", "--dataset", str(root / "data"), "--config", str(cfg), "--out", str(model),
                 "--no-progress"]) == 0
    test = ds.select(run="test")
    images, odo = list(test.images()), test.odometry
    stamps = [STAMP0 + k * PERIOD for k in range(len(images))]
    bag = root / "run.bag"
    with BagWriter(bag, unit="ns") as w:
        for k, (t, img) in enumerate(zip(stamps, images)):
            w.add_odometry("/odom", t, odo[k])
            w.add_image("/cam", t, img)
            if k + 1 < len(images):  # odometry between images too: twice the camera's rate
                w.add_odometry("/odom", t + PERIOD // 2, odo[k] + (odo[k + 1] - odo[k]) / 2)
    ds_dir, est = root / "imported", root / "batch.csv"
    assert main(["import", str(bag), "--image-topic", "/cam", "--odom-topic", "/odom", "--out", str(ds_dir),
                 "--no-progress"]) == 0
    assert main(["localize", str(model), str(ds_dir), "--odometry", "--out", str(est), "--no-progress"]) == 0
    rows = list(csv.DictReader(open(est)))
    batch = np.array([[float(r[k]) for k in ("x", "y", "fused_x", "fused_y", "fused_heading")] for r in rows])
    return {"model": model, "bag": bag, "stamps": stamps, "batch": batch, "root": root}


def _subscribed(master, topic, node):
    _, _, state = master.getSystemState("/test")
    subs = dict((t, n) for t, n in state[1])
    return node in subs.get(topic, [])


def test_the_node_localizes_a_played_bag_like_the_batch(ros, recorded, tmp_path):
    from rosbags.highlevel import AnyReader

    env, master = ros["env"], ros["master"]
    try:
        import rerun  # noqa: F401
        rrd = tmp_path / "live.rrd"  # the live view too
    except ImportError:
        rrd = None
    node = subprocess.Popen([sys.executable, "-m", "sfanav", "ros-node", str(recorded["model"]),
                             "_image_topic:=/cam", "_odom_topic:=/odom", "_silence:=60",
                             "_camera_gamma:=true"]  # the tiny model has no reference: one line, then as without
                            + ([f"_rerun:={rrd}"] if rrd is not None else []),
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    out = tmp_path / "out.bag"
    rec = subprocess.Popen(["rosbag", "record", "-O", str(out), "/sfanav/estimate", "/sfanav/fused", "/tf",
                            "__name:=recorder"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           start_new_session=True)
    try:
        _wait(lambda: _subscribed(master, "/cam", "/sfanav") and _subscribed(master, "/odom", "/sfanav"),
              "the node's subscriptions", 60)
        _wait(lambda: _subscribed(master, "/sfanav/fused", "/recorder"), "the recorder", 30)
        time.sleep(1.0)  # the node's publishers connect to the recorder
        play = subprocess.run(["rosbag", "play", "-q", str(recorded["bag"])], env=env, capture_output=True,
                              text=True, timeout=120)
        assert play.returncode == 0, play.stderr
        time.sleep(1.5)  # the last messages reach the node and the recorder
    finally:
        _stop(rec)
        _stop(node)
    log = node.stdout.read() + node.stderr.read()  # rospy: info on stdout, warnings on stderr
    assert node.returncode in (0, -signal.SIGINT), log
    assert "40 images localized, 40 fused poses published" in log and "Traceback" not in log, log
    assert "no camera gamma reference" in log, log

    got = {"/sfanav/estimate": {}, "/sfanav/fused": {}, "/tf": {}}
    with AnyReader([out]) as r:
        for c, _, raw in r.messages():
            m = r.deserialize(raw, c.msgtype)
            if c.topic == "/tf":
                for t in m.transforms:
                    got["/tf"][t.header.stamp.sec * 10**9 + t.header.stamp.nanosec] = t
            else:
                got[c.topic][m.header.stamp.sec * 10**9 + m.header.stamp.nanosec] = m
    stamps = recorded["stamps"]
    for topic in got:
        assert sorted(got[topic]) == stamps, topic  # every image, its exact stamp, nothing else
    est = np.array([[got["/sfanav/estimate"][t].pose.pose.position.x, got["/sfanav/estimate"][t].pose.pose.position.y]
                    for t in stamps])
    fused = got["/sfanav/fused"]
    fz = np.array([[fused[t].pose.pose.position.x, fused[t].pose.pose.position.y,
                    2 * math.atan2(fused[t].pose.pose.orientation.z, fused[t].pose.pose.orientation.w)]
                   for t in stamps])
    batch = recorded["batch"]
    np.testing.assert_allclose(est, batch[:, :2], atol=1e-4)
    np.testing.assert_allclose(fz[:, :2], batch[:, 2:4], atol=1e-4)
    np.testing.assert_allclose(np.angle(np.exp(1j * (fz[:, 2] - batch[:, 4]))), 0, atol=1e-4)
    f0 = fused[stamps[0]]
    assert f0.header.frame_id == "map" and f0.child_frame_id == "base_link"
    assert np.all(np.isfinite(f0.pose.covariance)) and f0.pose.covariance[0] > 0
    tf0 = got["/tf"][stamps[0]]
    assert (tf0.header.frame_id, tf0.child_frame_id) == ("map", "odom")
    if rrd is not None:  # the live view: every image, estimate and fused position at its exact stamp
        from test_live_view import _entities

        t = _entities(rrd)
        for e in ("/camera/image", "/world/estimate", "/world/fused", "/world/fused/ellipse"):
            ns = [int(v.value) if hasattr(v, "value") else int(v) for v in t[e].column("stamp").cast("int64").to_pylist()]
            assert sorted(ns) == stamps, e


def test_a_camera_of_another_size_stops_the_node_with_one_line(ros, recorded, tmp_path):
    from sfanav.data.rosbag_writer import BagWriter

    env = ros["env"]
    bag = tmp_path / "wide.bag"
    with BagWriter(bag, unit="ns") as w:
        w.add_image("/cam2", STAMP0, np.zeros((16, 120, 3), np.uint8))
    node = subprocess.Popen([sys.executable, "-m", "sfanav", "ros-node", str(recorded["model"]),
                             "_image_topic:=/cam2", "_odom_topic:=/odom2"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _wait(lambda: _subscribed(ros["master"], "/cam2", "/sfanav"), "the node's subscription", 60)
        time.sleep(0.5)
        subprocess.run(["rosbag", "play", "-q", str(bag)], env=env, capture_output=True, timeout=60)
        node.wait(30)
    finally:
        _stop(node)
    err = node.stderr.read()
    assert node.returncode == 2, err
    last = [ln for ln in err.splitlines() if ln.strip()][-1]
    assert last.startswith("sfanav ros-node: error:") and "120x16" in last and "60x8" in last, err
    assert "Traceback" not in err


def test_the_launch_file_starts_the_node(ros, recorded):
    env = {**ros["env"], "ROS_PACKAGE_PATH": str(Path(__file__).resolve().parents[1] / "ros"),
           "SFANAV_PYTHON": sys.executable}
    launch = subprocess.Popen(["roslaunch", "--wait", "sfanav_ros", "sfanav.launch", f"model:={recorded['model']}",
                               "image_topic:=/cam3", "odom_topic:=/odom3", "silence:=0.5"], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        _wait(lambda: _subscribed(ros["master"], "/cam3", "/sfanav") and _subscribed(ros["master"], "/odom3", "/sfanav"),
              "the launched node's subscriptions", 60)
        time.sleep(1.5)
    finally:
        _stop(launch)
    log = launch.stdout.read()
    assert "/cam3 is silent" in log and "/odom3 is silent" in log and "Traceback" not in log, log


def test_undecodable_messages_and_stamps_that_jump_back_are_logged_not_fatal(ros, recorded, tmp_path):
    from bagtools import raw_image, truncated
    from rosbags.rosbag1 import Writer
    from sfanav.data.ros_messages import typestore

    store = typestore(1)
    T = store.types
    img = np.zeros((8, 60, 3), np.uint8)
    sent = [(STAMP0, raw_image(img)), (STAMP0 + PERIOD, truncated(raw_image(img), 100)),
            (STAMP0 - 5 * PERIOD, raw_image(img))]  # a broken image, then a stamp 0.3 s back
    bag = tmp_path / "broken.bag"
    with Writer(bag) as w:
        conn = w.add_connection("/cam4", "sensor_msgs/msg/Image", typestore=store)
        for k, (ns, (typ, fields)) in enumerate(sent):
            t = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
            msg = T[typ](header=T["std_msgs/msg/Header"](seq=k, stamp=t, frame_id="camera"), **fields)
            w.write(conn, STAMP0 + k * PERIOD, store.serialize_ros1(msg, typ))
    node = subprocess.Popen([sys.executable, "-m", "sfanav", "ros-node", str(recorded["model"]),
                             "_image_topic:=/cam4", "_odom_topic:=/odom4", "_silence:=60"], env=ros["env"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _wait(lambda: _subscribed(ros["master"], "/cam4", "/sfanav"), "the node's subscription", 60)
        time.sleep(0.5)
        subprocess.run(["rosbag", "play", "-q", str(bag)], env=ros["env"], capture_output=True, timeout=60)
        time.sleep(1.0)
        alive = node.poll() is None
    finally:
        _stop(node)
    log = node.stdout.read() + node.stderr.read()
    assert alive and "Traceback" not in log, log
    assert f"/cam4: message at stamp {STAMP0 + PERIOD} ns skipped:" in log, log
    assert f"/cam4: the stamp jumps back from {STAMP0 + PERIOD} ns to {STAMP0 - 5 * PERIOD} ns" in log, log
    assert "dropped {'late': 1}" in log, log
