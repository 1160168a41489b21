"""ROS messages as sfanav sees them: camera images, poses and their
timestamps, read from and written to the messages of the pure-Python
``rosbags`` library (an optional dependency: ``pip install "sfanav[ros]"``).

Reading: :func:`decode_image` turns a ``sensor_msgs/Image`` (encodings
``rgb8``, ``bgr8``, ``mono8``, ``rgba8``, ``bgra8``, ``mono16`` and their
OpenCV aliases ``8UC1``, ``8UC3``, ``8UC4``, ``16UC1``; the 8-bit Bayer
patterns ``bayer_rggb8``, ``bayer_bggr8``, ``bayer_gbrg8``, ``bayer_grbg8``,
demosaiced) or a ``sensor_msgs/CompressedImage`` (JPEG, PNG, anything
OpenCV decodes) into a uint8 RGB or gray array; :func:`raw_image_shape`
checks a raw image without decoding it; :func:`pose_of` reads x, y and the heading (the
quaternion's yaw) of a ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped``
or ``geometry_msgs/PoseWithCovarianceStamped``; :func:`stamp_of` the header
stamp in nanoseconds.

Writing: :func:`image_message`, :func:`pose_message` and
:func:`odometry_message` build the messages for a ROS 1 or a ROS 2 type
store (:func:`typestore`).

Type names are ROS 2 style (``sensor_msgs/msg/Image``) for both ROS
versions, as ``rosbags`` reports them.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from .images import damage, quiet_codecs

ROS_EXTRA = 'pip install "sfanav[ros]"'


IMAGE = "sensor_msgs/msg/Image"


COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"


ODOMETRY = "nav_msgs/msg/Odometry"


POSE_STAMPED = "geometry_msgs/msg/PoseStamped"


POSE_WITH_COVARIANCE = "geometry_msgs/msg/PoseWithCovarianceStamped"


IMAGE_TYPES = (IMAGE, COMPRESSED_IMAGE)


POSE_TYPES = (ODOMETRY, POSE_STAMPED, POSE_WITH_COVARIANCE)


#: raw encodings: channels, bytes per channel, channel order ("gray", "rgb", "bgr", or a Bayer pattern)
ENCODINGS = {
    "mono8": (1, 1, "gray"), "8UC1": (1, 1, "gray"),
    "mono16": (1, 2, "gray"), "16UC1": (1, 2, "gray"),
    "rgb8": (3, 1, "rgb"), "bgr8": (3, 1, "bgr"), "8UC3": (3, 1, "bgr"),
    "rgba8": (4, 1, "rgb"), "bgra8": (4, 1, "bgr"), "8UC4": (4, 1, "bgr"),
    "bayer_rggb8": (1, 1, "rggb"), "bayer_bggr8": (1, 1, "bggr"),
    "bayer_gbrg8": (1, 1, "gbrg"), "bayer_grbg8": (1, 1, "grbg"),
}


#: OpenCV's demosaicing of each Bayer pattern to RGB, as cv_bridge converts them (OpenCV names a
#: pattern by the second row's second and third pixels, ROS by the first two rows' first two)
BAYER_TO_RGB = {"rggb": "COLOR_BayerBG2RGB", "bggr": "COLOR_BayerRG2RGB", "gbrg": "COLOR_BayerGR2RGB",
                "grbg": "COLOR_BayerGB2RGB"}


def require_rosbags() -> Any:
    """The ``rosbags`` package, or an ImportError that says how to install it."""
    try:
        import rosbags
        import rosbags.highlevel  # noqa: F401
        import rosbags.rosbag1  # noqa: F401
        import rosbags.rosbag2  # noqa: F401
        import rosbags.typesys  # noqa: F401
    except ImportError as exc:
        raise ImportError(f"ROS bags need the optional dependency rosbags: {ROS_EXTRA}") from exc
    return rosbags


def typestore(ros: int) -> Any:
    """The ``rosbags`` type store of ROS 1 (Noetic) or ROS 2 (Humble), made once."""
    if ros not in (1, 2):
        raise ValueError(f"ros must be 1 or 2, got {ros!r}")
    return _typestore(ros)


@functools.lru_cache(maxsize=2)
def _typestore(ros: int) -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)


# ---------------------------------------------------------------- angles

def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """The heading (rad, counter-clockwise about +z, in [-pi, pi]) of an
    orientation quaternion: its yaw in the z-y-x (yaw-pitch-roll)
    convention of ROS. NaN for a zero or non-finite quaternion (an unset
    orientation).

    Examples
    --------
    >>> round(yaw_from_quaternion(0, 0, math.sin(0.5), math.cos(0.5)), 6)
    1.0
    """
    n = x * x + y * y + z * z + w * w
    if not math.isfinite(n) or n < 1e-12:
        return math.nan
    return math.atan2(2.0 * (w * z + x * y) / n, 1.0 - 2.0 * (y * y + z * z) / n)


def quaternion_from_yaw(yaw: float) -> tuple[float, float, float, float]:
    """The quaternion (x, y, z, w) of a rotation by ``yaw`` rad about +z."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


# ---------------------------------------------------------------- reading

def stamp_of(msg: Any) -> int:
    """The header stamp of a message, in nanoseconds."""
    st = msg.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def pose_of(msg: Any) -> tuple[float, float, float]:
    """x (m), y (m) and heading (rad; NaN if the orientation is unset) of a
    ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or
    ``geometry_msgs/PoseWithCovarianceStamped``.

    Raises
    ------
    TypeError
        For a message of another type.
    """
    typ = getattr(msg, "__msgtype__", type(msg).__name__)
    if typ == POSE_STAMPED:
        pose = msg.pose
    elif typ in (ODOMETRY, POSE_WITH_COVARIANCE):
        pose = msg.pose.pose
    else:
        raise TypeError(f"a {typ} holds no pose; expected one of {', '.join(POSE_TYPES)}")
    p, q = pose.position, pose.orientation
    return float(p.x), float(p.y), yaw_from_quaternion(float(q.x), float(q.y), float(q.z), float(q.w))


def field_problem(msg: Any) -> str | None:
    """Why a deserialized message lacks what sfanav reads of its type (None
    if nothing is amiss): a bag carries its own definition of each type,
    and a damaged or foreign one can drop or retype a field (a
    ``Quaternion`` without ``z``, a ``stamp`` whose ``sec`` is text). Read
    here: the header stamp of the image and pose types, the pose of the
    pose types, an image's size, encoding or format and data."""
    try:
        typ = msg.__msgtype__
        if typ in IMAGE_TYPES or typ in POSE_TYPES:
            stamp_of(msg)
        if typ in POSE_TYPES:
            pose_of(msg)
        elif typ == IMAGE:
            str(msg.encoding), int(msg.height), int(msg.width), int(msg.step), bool(msg.is_bigendian)
            np.asarray(msg.data).reshape(-1).view(np.uint8)
        elif typ == COMPRESSED_IMAGE:
            str(msg.format)
            np.asarray(msg.data).reshape(-1).view(np.uint8)
    except (AttributeError, TypeError, ValueError, OverflowError) as exc:
        return " ".join(str(exc).split()) or type(exc).__name__
    return None


def _to_rgb(img: np.ndarray, order: str) -> np.ndarray:
    """uint8 (H, W) gray or (H, W, 3|4) in ``order`` ("rgb" or "bgr") as gray or RGB."""
    if img.ndim == 2:
        return img
    if img.shape[2] == 4:
        img = img[:, :, :3]
    if order == "bgr":
        img = img[:, :, ::-1]
    return np.ascontiguousarray(img)


def raw_image_shape(msg: Any) -> tuple[int, ...]:
    """The shape of the uint8 image :func:`decode_image` makes of a
    ``sensor_msgs/Image``, (H, W) or (H, W, 3), checked without decoding:
    its encoding is supported, its size positive, its rows (``step``) long
    enough and its data holds them all.

    Raises
    ------
    ValueError
        For an unsupported encoding, an empty image, or a data size that
        does not match the image's.
    """
    enc = str(msg.encoding)
    if enc not in ENCODINGS:
        raise ValueError(f"image encoding {enc!r} is not supported; supported: {', '.join(ENCODINGS)}")
    ch, bps, order = ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * ch * bps
    size = int(np.asarray(msg.data).size)
    if h < 1 or w < 1:
        raise ValueError(f"image of {w}x{h} pixels is empty")
    if step < row or size < step * h:
        raise ValueError(f"a {w}x{h} {enc} image needs {row} bytes a row and {row * h} in all; "
                         f"the message has step {step} and {size} bytes"
                         + (f", fewer than height x step = {step * h}" if step > row else ""))
    if order in BAYER_TO_RGB and (h < 2 or w < 2):
        raise ValueError(f"a {enc} image needs at least 2x2 pixels to demosaic, got {w}x{h}")
    return (h, w) if ch == 1 and order not in BAYER_TO_RGB else (h, w, 3)


def decode_image(msg: Any) -> np.ndarray:
    """The picture of a ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage``
    as uint8 (H, W, 3) RGB or (H, W) gray, as it is (omnidirectional images
    are not unwarped here). 16-bit images are scaled to 8 bits (/256), an
    alpha channel is dropped, Bayer images are demosaiced (OpenCV's
    bilinear demosaicing, as cv_bridge's).

    Raises
    ------
    ValueError
        For an unsupported encoding, a data size that does not match the
        image's, or compressed data OpenCV cannot decode or that is cut
        short (a truncated JPEG or PNG).
    TypeError
        For a message of another type.

    Examples
    --------
    >>> img = decode_image(msg)                      # doctest: +SKIP
    >>> img.shape, img.dtype                         # doctest: +SKIP
    ((60, 600, 3), dtype('uint8'))
    """
    typ = getattr(msg, "__msgtype__", type(msg).__name__)
    if typ == COMPRESSED_IMAGE:
        return decode_compressed(np.asarray(msg.data, np.uint8), str(msg.format))
    if typ != IMAGE:
        raise TypeError(f"a {typ} is not an image; expected {IMAGE} or {COMPRESSED_IMAGE}")
    raw_image_shape(msg)
    enc = str(msg.encoding)
    ch, bps, order = ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * ch * bps
    data = np.asarray(msg.data, np.uint8).reshape(-1)
    rows = data[: step * h].reshape(h, step)[:, :row]
    if bps == 2:
        dt = np.dtype(">u2" if msg.is_bigendian else "<u2")
        img = (np.ascontiguousarray(rows).view(dt).reshape(h, w) >> 8).astype(np.uint8)
    else:
        img = rows.reshape(h, w, ch) if ch > 1 else rows.reshape(h, w)
    if order in BAYER_TO_RGB:
        import cv2

        return cv2.cvtColor(np.ascontiguousarray(img, np.uint8), getattr(cv2, BAYER_TO_RGB[order]))
    return _to_rgb(np.array(img, np.uint8), order)


def decode_compressed(data: np.ndarray, fmt: str = "") -> np.ndarray:
    """Compressed image bytes (JPEG, PNG, ...) as uint8 RGB or gray."""
    import cv2

    if "compresseddepth" in fmt.lower().replace(" ", ""):
        raise ValueError(f"compressed depth images ({fmt!r}) are not camera images")
    cut = damage(np.ascontiguousarray(data, np.uint8).tobytes())
    if cut is not None:
        raise ValueError(f"cannot decode the compressed image ({fmt or 'no format given'}, {data.size} bytes): {cut}")
    img = None
    if data.size:
        with quiet_codecs():
            img = cv2.imdecode(np.ascontiguousarray(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"cannot decode the compressed image ({fmt or 'no format given'}, {data.size} bytes)")
    if img.dtype != np.uint8:
        img = (img / (256 if img.dtype == np.uint16 else 1)).clip(0, 255).astype(np.uint8)
    return _to_rgb(img, "bgr")


def compressed_suffix(data: np.ndarray) -> str | None:
    """``.png`` or ``.jpg`` if ``data`` starts as a PNG or JPEG file, else None."""
    head = bytes(np.asarray(data[:8], np.uint8))
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return ".png"
    if head.startswith(b"\xff\xd8\xff"):
        return ".jpg"
    return None


# ---------------------------------------------------------------- writing

def _header(store: Any, stamp_ns: int, frame_id: str, seq: int) -> Any:
    T = store.types
    t = T["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000))
    if "seq" in T["std_msgs/msg/Header"].__dataclass_fields__:  # ROS 1
        return T["std_msgs/msg/Header"](seq=int(seq), stamp=t, frame_id=frame_id)
    return T["std_msgs/msg/Header"](stamp=t, frame_id=frame_id)


def _pose(store: Any, x: float, y: float, heading: float) -> Any:
    T = store.types
    qx, qy, qz, qw = quaternion_from_yaw(heading)
    return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw))


JPEG_QUALITY = 95
"""JPEG quality of compressed images written (OpenCV's default; ROS's image_transport publishes 80 to 95)."""


def image_message(store: Any, stamp_ns: int, image: np.ndarray, *, fmt: str = "raw", encoding: str | None = None,
                  frame_id: str = "camera", seq: int = 0, quality: int = JPEG_QUALITY) -> Any:
    """A ``sensor_msgs/Image`` (``fmt="raw"``; ``encoding`` ``rgb8``
    (default for colour), ``bgr8`` or ``mono8`` (default for gray)) or a
    ``sensor_msgs/CompressedImage`` (``fmt="png"`` or ``"jpeg"``, at JPEG
    ``quality`` 1..100) of a uint8 RGB (H, W, 3) or gray (H, W) image."""
    import cv2

    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
        raise ValueError(f"an image must be uint8 (H, W) gray or (H, W, 3) RGB, got {img.dtype} {img.shape}")
    T = store.types
    header = _header(store, stamp_ns, frame_id, seq)
    if fmt == "raw":
        enc = encoding or ("mono8" if img.ndim == 2 else "rgb8")
        if enc not in ("rgb8", "bgr8", "mono8") or (enc == "mono8") != (img.ndim == 2):
            raise ValueError(f"encoding {enc!r} does not fit an image of shape {img.shape} (rgb8, bgr8 or mono8)")
        px = img[:, :, ::-1] if enc == "bgr8" else img
        h, w = img.shape[:2]
        ch = 1 if img.ndim == 2 else 3
        return T[IMAGE](header=header, height=h, width=w, encoding=enc, is_bigendian=0, step=w * ch,
                        data=np.ascontiguousarray(px).reshape(-1))
    if fmt not in ("png", "jpeg"):
        raise ValueError(f"fmt must be 'raw', 'png' or 'jpeg', got {fmt!r}")
    if isinstance(quality, bool) or not isinstance(quality, (int, np.integer)) or not 1 <= quality <= 100:
        raise ValueError(f"JPEG quality must be an integer 1..100, got {quality!r}")
    bgr = img if img.ndim == 2 else img[:, :, ::-1]
    params = [] if fmt == "png" else [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    ok, buf = cv2.imencode(".png" if fmt == "png" else ".jpg", np.ascontiguousarray(bgr), params)
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise ValueError(f"OpenCV could not encode a {fmt} image")
    return T[COMPRESSED_IMAGE](header=header, format=fmt, data=buf.reshape(-1))


def pose_message(store: Any, stamp_ns: int, pose: Any, *, frame_id: str = "map", seq: int = 0) -> Any:
    """A ``geometry_msgs/PoseStamped`` at (x m, y m, heading rad) on the ground (z = 0)."""
    x, y, th = (float(v) for v in pose)
    return store.types[POSE_STAMPED](header=_header(store, stamp_ns, frame_id, seq), pose=_pose(store, x, y, th))


def odometry_message(store: Any, stamp_ns: int, pose: Any, *, frame_id: str = "odom",
                     child_frame_id: str = "base_link", seq: int = 0) -> Any:
    """A ``nav_msgs/Odometry`` at (x m, y m, heading rad); velocities and
    covariances zero (unknown)."""
    x, y, th = (float(v) for v in pose)
    T = store.types
    zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return T[ODOMETRY](
        header=_header(store, stamp_ns, frame_id, seq), child_frame_id=child_frame_id,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=_pose(store, x, y, th), covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)))
