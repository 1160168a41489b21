"""A ROS 1 node over :class:`~sfanav.odometry.streaming.StreamingLocalizer`:
camera and odometry topics in; the single-image estimate, the fused pose
and the ``map -> odom`` transform out, each stamped with its image's stamp.

The node is a thin adapter: it decodes messages, passes their header stamps
(integer nanoseconds) and contents to the streaming localizer and turns
what it emits into messages. Everything it needs from ROS is imported when
the node starts (:func:`import_rospy`), so this module imports without ROS.

Topics (``~`` is the node's private namespace; every name is a parameter)

* subscribes ``~image_topic`` (default ``/camera/image_raw``):
  ``sensor_msgs/Image``, or ``sensor_msgs/CompressedImage`` when the name
  ends in ``/compressed`` or ``~compressed`` is true;
* subscribes ``~odom_topic`` (default ``/odom``): ``nav_msgs/Odometry``;
* publishes ``~estimate_topic`` (default ``/sfanav/estimate``):
  ``geometry_msgs/PoseWithCovarianceStamped`` in ``~map_frame``, the
  single-image estimate (x, y; variance ``measurement_noise**2``; the
  orientation unknown: identity with variance 1e6);
* publishes ``~fused_topic`` (default ``/sfanav/fused``): ``nav_msgs/Odometry``,
  the fused pose in ``~map_frame`` with ``child_frame_id`` ``~base_frame``
  and its covariance (x, y, yaw; z, roll, pitch 1e6);
* broadcasts ``~map_frame -> ~odom_frame`` on ``/tf`` (REP 105: the
  correction that takes the odometry's pose of ``~base_frame`` to the fused
  one) unless ``~publish_tf`` is false.

Other parameters: ``~rerun`` (a Rerun recording ``NAME.rrd``, ``viewer`` or
``rerun+http://HOST:PORT/proxy``: the live view of
:class:`~sfanav.odometry.live_view.RerunView`; default none),
``~window`` (s, the reordering window, default 0),
``~silence`` (s: a topic without messages this long is logged, default 2),
``~resize`` (false: a camera whose panoramas differ in size from the
model's stops the node with one line; true: they are resized),
``~camera_gamma`` (unset: the camera's gamma estimated over the stream and
taken out where the model holds its reference, as ``sfanav localize`` does
by default; true: the same, and one line for a model without it; false:
off), the filter's
``~distance_noise``, ``~heading_noise``, ``~measurement_noise``,
``~turn_noise`` (default: the model's). Running it, the interpreter it
needs and the launch file: ``docs/live.md``.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

DEBIAN_ROS = "/usr/lib/python3/dist-packages"
"""Where Debian's ``python3-rospy`` lives; appended (last) to ``sys.path``
when rospy is not importable otherwise."""


def import_rospy() -> Any:
    """``rospy``, from this interpreter's path or else from Debian's
    packages appended after it (so this interpreter's NumPy stays first).
    ImportError naming what to install when neither has it."""
    try:
        import rospy
    except ImportError:
        if Path(DEBIAN_ROS).is_dir() and DEBIAN_ROS not in sys.path:
            sys.path.append(DEBIAN_ROS)
        try:
            import rospy
        except ImportError as exc:
            raise ImportError("the ROS node needs rospy and the ROS message packages: on Debian, apt-get install "
                              "ros-core python3-rospy python3-sensor-msgs python3-nav-msgs python3-geometry-msgs "
                              f"python3-tf2-msgs ({exc})") from None
    return rospy


def yaw_of(q: Any) -> float:
    """The yaw (rad) of a quaternion with fields x, y, z, w (z-y-x convention),
    normalised first; ValueError for a zero quaternion."""
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 0:
        raise ValueError("the orientation quaternion is zero (unset)")
    x, y, z, w = x / n, y / n, z / n, w / n
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def map_to_odom(fused: Any, odometry: Any) -> np.ndarray:
    """The ``map -> odom`` transform ``(x [m], y [m], yaw [rad])`` that takes
    the odometry pose of the robot (odom frame) to its fused pose (map
    frame): ``T_map_odom = T_map_base T_odom_base^-1`` (REP 105)."""
    f, o = np.asarray(fused, float), np.asarray(odometry, float)
    yaw = float(np.angle(np.exp(1j * (f[2] - o[2]))))
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([f[0] - (c * o[0] - s * o[1]), f[1] - (s * o[0] + c * o[1]), yaw])


def covariance_6x6(cov3: Any, unknown: float = 1e6) -> list[float]:
    """A ROS pose covariance (36 floats, row-major x, y, z, roll, pitch, yaw)
    from a (3, 3) covariance of (x, y, yaw); z, roll and pitch get
    ``unknown``."""
    C = np.diag([0.0, 0.0, unknown, unknown, unknown, 0.0])
    idx = [0, 1, 5]
    C[np.ix_(idx, idx)] = np.asarray(cov3, float)
    return C.ravel().tolist()


class Ros1Node:
    """The node's state and callbacks (see the module docstring); create it
    after ``rospy.init_node`` and call :meth:`spin`."""

    def __init__(self, localizer: Any, *, rospy: Any, log: Any = None) -> None:
        from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import CompressedImage, Image
        from tf2_msgs.msg import TFMessage

        from ..data.preprocessing import Preprocessing
        from .streaming import StreamingLocalizer

        self.rospy = rospy
        self.msg = {"pose": PoseWithCovarianceStamped, "odom": Odometry, "tf": TFMessage, "tfs": TransformStamped}
        p = rospy.get_param
        self.image_topic = p("~image_topic", "/camera/image_raw")
        self.odom_topic = p("~odom_topic", "/odom")
        self.compressed = bool(p("~compressed", self.image_topic.rstrip("/").endswith("/compressed")))
        self.map_frame, self.odom_frame = p("~map_frame", "map"), p("~odom_frame", "odom")
        self.base_frame = p("~base_frame", "base_link")
        self.publish_tf = bool(p("~publish_tf", True))
        self.silence = float(p("~silence", 2.0))
        self.resize = bool(p("~resize", False))
        noise = dict(localizer.info.get("ekf_noise") or {})
        for k in ("distance_noise", "heading_noise", "measurement_noise", "turn_noise"):
            if rospy.has_param("~" + k):
                noise[k] = float(p("~" + k))
        self.prep = Preprocessing.of_model(localizer)
        gamma = p("~camera_gamma", None)  # unset: wherever the model holds the reference
        self.live = StreamingLocalizer(localizer, noise or None, window_ns=int(round(float(p("~window", 0.0)) * 1e9)),
                                       log=lambda m: rospy.loginfo(f"sfanav: {m}"),
                                       on_estimate=self._publish_estimate,
                                       camera_gamma=None if gamma is None else bool(gamma))
        self.r2 = float(self.live.noise["measurement_noise"]) ** 2
        self.view = None
        if p("~rerun", ""):
            from .live_view import RerunView

            try:
                self.view = RerunView(p("~rerun"))
            except (ImportError, ValueError) as exc:
                raise ValueError(f"~rerun: {exc}") from None
            if getattr(localizer, "training_positions_", None) is not None:
                self.view.log_map(localizer.training_positions_)
        self.pub_estimate = rospy.Publisher(p("~estimate_topic", "/sfanav/estimate"), PoseWithCovarianceStamped,
                                            queue_size=100)
        self.pub_fused = rospy.Publisher(p("~fused_topic", "/sfanav/fused"), Odometry, queue_size=100)
        self.pub_tf = rospy.Publisher("/tf", TFMessage, queue_size=100) if self.publish_tf else None
        self.lock = threading.Lock()
        self.fatal: str | None = None
        self.heard = {"image": None, "odometry": None}  # monotonic time of the last message
        self.silent = {"image": False, "odometry": False}
        self.last_stamp = {"image": None, "odometry": None}
        self.n_published = 0
        rospy.Subscriber(self.image_topic, CompressedImage if self.compressed else Image, self._on_image,
                         queue_size=1000, buff_size=2**24)
        rospy.Subscriber(self.odom_topic, Odometry, self._on_odometry, queue_size=1000)
        self.started = time.monotonic()
        rospy.loginfo(f"sfanav: localizing {self.image_topic} ({'compressed' if self.compressed else 'raw'}) with "
                      f"{self.odom_topic}; publishing estimates, fused poses" + (" and map -> odom" if self.pub_tf else ""))

    # -------------------------------------------------------------- callbacks
    def _stamp(self, msg: Any, what: str, topic: str) -> int:
        ns = int(msg.header.stamp.to_nsec())
        last = self.last_stamp[what]
        if last is not None and ns < last:
            self.rospy.logwarn(f"sfanav: {topic}: the stamp jumps back from {last} ns to {ns} ns "
                               f"({(last - ns) / 1e9:.3f} s; a replayed bag restarted? the message is dropped "
                               "unless within ~window)")
        self.last_stamp[what] = ns if last is None else max(last, ns)
        self.heard[what] = time.monotonic()
        self.silent[what] = False
        return ns

    def _on_image(self, msg: Any) -> None:
        from ..data.ros_messages import decode_compressed

        ns = self._stamp(msg, "image", self.image_topic)
        try:
            if self.compressed:
                img = decode_compressed(np.frombuffer(msg.data, np.uint8), str(msg.format))
            else:
                img = decode_raw(msg)
        except ValueError as exc:
            self.rospy.logwarn(f"sfanav: {self.image_topic}: message at stamp {ns} ns skipped: {exc}")
            return
        if not self.resize and img.shape[:2] != (self.prep.height, self.prep.width) and img.shape[1] >= 2 * img.shape[0]:
            self.fatal = (f"the camera's panoramas on {self.image_topic} are {img.shape[1]}x{img.shape[0]}, the "
                          f"model's {self.prep.width}x{self.prep.height}: use a model trained on this camera, or "
                          "set ~resize true")
            self.rospy.signal_shutdown(self.fatal)
            return
        with self.lock:
            if self.view is not None:
                self.view.log_image(img, stamp_ns=ns)
            try:
                out = self.live.push_image(ns, img)
            except ValueError as exc:
                self.rospy.logwarn(f"sfanav: {self.image_topic}: message at stamp {ns} ns skipped: {exc}")
                return
            self._publish(out)

    def _on_odometry(self, msg: Any) -> None:
        ns = self._stamp(msg, "odometry", self.odom_topic)
        try:
            pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, yaw_of(msg.pose.pose.orientation))
            with self.lock:
                self._publish(self.live.push_odometry(ns, pose))
        except ValueError as exc:
            self.rospy.logwarn(f"sfanav: {self.odom_topic}: message at stamp {ns} ns skipped: {exc}")

    # ------------------------------------------------------------- publishing
    def _publish_estimate(self, stamp_ns: int, estimate: np.ndarray) -> None:
        """The single-image estimate, published as soon as it is computed
        (the streaming localizer's ``on_estimate``): no wait for the odometry
        or, at the start, for the filter's first images."""
        m = self.msg["pose"]()
        m.header.stamp = self.rospy.Time(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)
        m.header.frame_id = self.map_frame
        m.pose.pose.position.x, m.pose.pose.position.y = float(estimate[0]), float(estimate[1])
        m.pose.pose.orientation.w = 1.0
        m.pose.covariance = covariance_6x6(np.diag([self.r2, self.r2, 1e6]))
        self.pub_estimate.publish(m)

    def _publish(self, estimates: list) -> None:
        for e in estimates:
            stamp = self.rospy.Time(e.stamp_ns // 1_000_000_000, e.stamp_ns % 1_000_000_000)
            if self.view is not None:
                self.view.log(e)
            if e.pose is None:
                continue
            o = self.msg["odom"]()
            o.header.stamp, o.header.frame_id, o.child_frame_id = stamp, self.map_frame, self.base_frame
            o.pose.pose.position.x, o.pose.pose.position.y = float(e.pose[0]), float(e.pose[1])
            o.pose.pose.orientation.z, o.pose.pose.orientation.w = math.sin(e.pose[2] / 2), math.cos(e.pose[2] / 2)
            o.pose.covariance = covariance_6x6(e.covariance)
            o.twist.covariance = (np.eye(6) * 1e6).ravel().tolist()  # the twist is not estimated
            self.pub_fused.publish(o)
            self.n_published += 1
            if self.pub_tf is not None:
                x, y, yaw = map_to_odom(e.pose, e.odometry)
                t = self.msg["tfs"]()
                t.header.stamp, t.header.frame_id, t.child_frame_id = stamp, self.map_frame, self.odom_frame
                t.transform.translation.x, t.transform.translation.y = float(x), float(y)
                t.transform.rotation.z, t.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)
                self.pub_tf.publish(self.msg["tf"](transforms=[t]))

    def _check_silence(self) -> None:
        now = time.monotonic()
        for what, topic in (("image", self.image_topic), ("odometry", self.odom_topic)):
            last = self.heard[what]
            quiet = now - (last if last is not None else self.started)
            if quiet > self.silence and not self.silent[what]:
                self.silent[what] = True
                self.rospy.logwarn(f"sfanav: {topic} is silent: no message for {quiet:.1f} s"
                                   + ("" if last is not None else " since the node started"))

    def spin(self) -> None:
        """Runs until ROS shuts down; ValueError with the reason when the node stopped itself."""
        while not self.rospy.is_shutdown():
            self._check_silence()
            time.sleep(0.2)
        if self.view is not None:
            self.view.close()
        if self.fatal is not None:
            raise ValueError(self.fatal)
        d = dict(self.live.dropped_)
        self.rospy.loginfo(f"sfanav: {self.live.n_emitted_} images localized, {self.n_published} fused poses "
                           f"published" + (f", dropped {d}" if d else ""))


def decode_raw(msg: Any) -> np.ndarray:
    """A ROS 1 ``sensor_msgs/Image`` (as rospy delivers it: ``data`` bytes) as
    uint8 RGB or gray, by :func:`sfanav.data.ros_messages.decode_image`'s rules."""
    from types import SimpleNamespace

    from ..data.ros_messages import IMAGE, decode_image

    m = SimpleNamespace(__msgtype__=IMAGE, height=msg.height, width=msg.width, encoding=msg.encoding,
                        is_bigendian=msg.is_bigendian, step=msg.step, data=np.frombuffer(msg.data, np.uint8))
    return decode_image(m)


def run_node(localizer: Any, argv: list[str] | None = None) -> int:
    """Starts the node ``sfanav`` over a fitted :class:`sfanav.Localizer`
    (ROS remappings and ``_param:=value`` in ``argv``) and runs until
    shutdown. Returns 0; ImportError without ROS, ValueError when the camera
    does not match the model (the node stops itself)."""
    rospy = import_rospy()
    loc = localizer
    rospy.init_node("sfanav", argv=["sfanav", *(argv or [])])
    node = Ros1Node(loc, rospy=rospy)
    node.spin()
    return 0
