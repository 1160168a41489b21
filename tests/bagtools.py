"""Helpers of the ROS bag tests: bags written with ``rosbags`` itself (not
sfanav's :class:`~sfanav.data.BagWriter`), so that they can hold what a
robot's drivers send and sfanav never writes: any encoding, broken image
data, stamps in exact nanoseconds."""

import numpy as np

from sfanav.data.ros_messages import typestore

STAMP0 = 1_733_000_000_123_456_789  # ns: a Unix time with odd nanoseconds, not exact as float seconds
PERIOD = 33_333_333  # ns: a 30 Hz camera


def stamp_text(ns):
    """A stamp in ns as the errors write it: exact seconds (``1733000000.190123455``, ``1000.5``, ``1000.0``)."""
    return f"{ns // 10**9}.{f'{ns % 10**9:09d}'.rstrip('0') or '0'}"


def raw_image(img, encoding=None):
    """The fields of a sensor_msgs/Image of a uint8 RGB or gray array."""
    img = np.asarray(img, np.uint8)
    h, w = img.shape[:2]
    ch = 1 if img.ndim == 2 else img.shape[2]
    return "sensor_msgs/msg/Image", dict(height=h, width=w, encoding=encoding or ("mono8" if ch == 1 else "rgb8"),
                                          is_bigendian=0, step=w * ch, data=img.reshape(-1))


def compressed_image(data, fmt="jpeg"):
    return "sensor_msgs/msg/CompressedImage", dict(format=fmt, data=np.frombuffer(bytes(data), np.uint8))


def jpeg_bytes(img):
    """A uint8 RGB image as a JPEG file's bytes."""
    import cv2

    return cv2.imencode(".jpg", np.ascontiguousarray(np.asarray(img)[..., ::-1]))[1].tobytes()


def png_bytes(img):
    """A uint8 RGB image as a PNG file's bytes."""
    import cv2

    return cv2.imencode(".png", np.ascontiguousarray(np.asarray(img)[..., ::-1]))[1].tobytes()


def write_camera_bag(path, images, *, stamps=None, odom=None, ros=1, odom_x=None, compression=None,
                     storage="mcap"):
    """A bag written with rosbags itself (not sfanav's BagWriter): ``images``
    ((msgtype, fields) each) on /cam, stamped ``stamps`` (ns; default
    STAMP0 + k * PERIOD), and a /odom (PoseStamped) at ``odom`` (ns;
    default at the images' stamps and one period before and after them),
    message k at x = ``odom_x[k]`` (default k * 0.1 m).
    ``ros``: 1 (a .bag) or 2 (a folder with ``storage`` ``"mcap"`` or
    ``"sqlite3"``). ``compression``: ``"bz2"`` or ``"lz4"`` chunks (ROS 1 only)."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    store = typestore(ros)
    T = store.types
    stamps = [STAMP0 + k * PERIOD for k in range(len(images))] if stamps is None else [int(s) for s in stamps]
    ser = store.serialize_ros1 if ros == 1 else store.serialize_cdr

    def header(k, ns):
        t = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        if ros == 1:
            return T["std_msgs/msg/Header"](seq=k, stamp=t, frame_id="camera")
        return T["std_msgs/msg/Header"](stamp=t, frame_id="camera")

    odo_ns = [stamps[0] - PERIOD] + stamps + [stamps[-1] + PERIOD] if odom is None else [int(s) for s in odom]
    writer = Writer1(path) if ros == 1 else Writer2(path, version=9, storage_plugin=StoragePlugin[storage.upper()])
    if compression is not None:
        writer.set_compression(Writer1.CompressionFormat[compression.upper()])
    with writer as w:
        conns = {}
        for topic, typ in (("/cam", images[0][0]), ("/odom", "geometry_msgs/msg/PoseStamped")):
            conns[topic] = w.add_connection(topic, typ, typestore=store)
        events = [(ns, 1, k) for k, ns in enumerate(odo_ns)] + [(ns, 0, k) for k, ns in enumerate(stamps)]
        for ns, kind, k in sorted(events):
            if kind == 1:
                pose = T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=k * 0.1 if odom_x is None else float(odom_x[k]), y=0.0,
                                                          z=0.0),
                    orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
                msg = T["geometry_msgs/msg/PoseStamped"](header=header(k, ns), pose=pose)
                w.write(conns["/odom"], ns, ser(msg, "geometry_msgs/msg/PoseStamped"))
            else:
                typ, fields = images[k]
                w.write(conns["/cam"], ns, ser(T[typ](header=header(k, ns), **fields), typ))
    return path


def truncated(image, nbytes):
    """An image message's fields with its data cut to ``nbytes``."""
    typ, fields = image
    return typ, {**fields, "data": fields["data"][:nbytes]}


def good_images(n=4, h=8, w=60):
    """``n`` random uint8 RGB images (the same for the same arguments)."""
    rng = np.random.default_rng(5)
    return [rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for _ in range(n)]


def bad_image_cases():
    """Four images of which image 2 is bad, by name: (image messages, words its error holds)."""
    imgs = good_images()
    jpeg, png = jpeg_bytes(imgs[2]), png_bytes(imgs[2])
    rng = np.random.default_rng(7)
    mono = imgs[2][:, :, 0]
    return {
        "random bytes": ([compressed_image(jpeg_bytes(i)) for i in imgs[:2]] + [compressed_image(rng.bytes(300))]
                         + [compressed_image(jpeg_bytes(imgs[3]))], ["cannot decode the compressed image"]),
        "half a jpeg": ([compressed_image(jpeg_bytes(i)) for i in imgs[:2]] + [compressed_image(jpeg[: len(jpeg) // 2])]
                        + [compressed_image(jpeg_bytes(imgs[3]))], ["cannot decode the compressed image", "truncated"]),
        "half a png": ([compressed_image(png_bytes(i), "png") for i in imgs[:2]]
                       + [compressed_image(png[: len(png) // 2], "png")]
                       + [compressed_image(png_bytes(imgs[3]), "png")],
                       ["cannot decode the compressed image", "truncated"]),
        "16UC3": ([raw_image(i) for i in imgs[:2]]
                  + [("sensor_msgs/msg/Image", dict(height=8, width=60, encoding="16UC3", is_bigendian=0, step=360,
                                                    data=np.zeros(8 * 360, np.uint8)))] + [raw_image(imgs[3])],
                  ["image encoding '16UC3' is not supported", "supported: mono8, 8UC1"]),
        "bayer_grbg16": ([raw_image(i) for i in imgs[:2]] + [raw_image(np.zeros((8, 120), np.uint8), "bayer_grbg16")]
                         + [raw_image(imgs[3])], ["image encoding 'bayer_grbg16' is not supported", "bayer_rggb8"]),
        "yuv422": ([raw_image(i) for i in imgs[:2]] + [raw_image(np.zeros((8, 120), np.uint8), "yuv422")]
                   + [raw_image(imgs[3])], ["image encoding 'yuv422' is not supported"]),
        "unknown encoding": ([raw_image(i) for i in imgs[:2]] + [raw_image(mono, "camera_special")]
                             + [raw_image(imgs[3])], ["image encoding 'camera_special' is not supported"]),
        "truncated raw": ([raw_image(i) for i in imgs[:2]]
                          + [truncated(raw_image(imgs[2]), 5 * 180)]
                          + [raw_image(imgs[3])], ["a 60x8 rgb8 image", "the message has step 180 and 900 bytes"]),
        "raw of another size": ([raw_image(i) for i in imgs[:2]] + [raw_image(imgs[2][:, :30])] + [raw_image(imgs[3])],
                                ["has shape (8, 30, 3), unlike (8, 60, 3)"]),
        "gray among colour": ([raw_image(i) for i in imgs[:2]] + [raw_image(mono)] + [raw_image(imgs[3])],
                              ["has shape (8, 60), unlike (8, 60, 3)"]),
        "jpeg of another size": ([compressed_image(jpeg_bytes(i)) for i in imgs[:2]]
                                 + [compressed_image(jpeg_bytes(imgs[2][:4]))]
                                 + [compressed_image(jpeg_bytes(imgs[3]))],
                                 ["has shape (4, 60, 3), unlike (8, 60, 3)"]),
    }


BAD_IMAGES = bad_image_cases()
