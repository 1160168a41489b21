"""``sfanav ros-node``: the streaming localizer as a ROS 1 node."""

from __future__ import annotations

import argparse

from ..common import load_localizer, wrap
from ..failures import UsageError
from ..registry import command


@command("ros-node")
def _add_ros_node(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "ros-node",
        help="localize live as a ROS 1 node: camera and odometry in, estimates, fused poses and map -> odom out",
        description=wrap("Run the ROS 1 node sfanav over a trained model (a model with EKF noise: trained on a run "
                         "with odometry). It subscribes to a camera topic (sensor_msgs/Image, or CompressedImage "
                         "when the name ends in /compressed) and an odometry topic (nav_msgs/Odometry), and for "
                         "every image publishes the single-image estimate (geometry_msgs/PoseWithCovarianceStamped "
                         "on /sfanav/estimate) and the fused pose (nav_msgs/Odometry on /sfanav/fused) stamped "
                         "with the image's stamp, and broadcasts map -> odom on /tf (REP 105). Topics, frames, the "
                         "reordering window and the filter noise are ROS parameters (_image_topic:=/cam ...); "
                         "ROS remappings pass through. Needs rospy (Debian: apt-get install ros-core "
                         "python3-rospy python3-sensor-msgs python3-nav-msgs python3-geometry-msgs "
                         "python3-tf2-msgs) and a running roscore; see docs/live.md."),
        epilog="example:\n  sfanav ros-node robot.sfa _image_topic:=/camera/image_raw/compressed _odom_topic:=/odom",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", metavar="MODEL", help="model file from sfanav train (with EKF noise)")
    p.add_argument("ros_args", nargs=argparse.REMAINDER, metavar="ROS_ARGS",
                   help="ROS parameters (_name:=value) and remappings (from:=to)")
    p.set_defaults(run=_run_ros_node)
    return p


def _run_ros_node(args: argparse.Namespace) -> int:
    from ...odometry.ros1_node import import_rospy, run_node

    loc = load_localizer(args.model)
    if "ekf_noise" not in loc.info and not any(a.startswith("_measurement_noise:=") for a in args.ros_args):
        raise UsageError(f"{args.model} holds no EKF noise (its training run had no odometry): retrain it on a run "
                         "with odometry, or give the noise (_distance_noise:=, _heading_noise:=, "
                         "_measurement_noise:=)")
    try:
        import_rospy()
    except ImportError as exc:
        raise UsageError(str(exc)) from None
    try:
        return run_node(loc, args.ros_args)
    except ValueError as exc:
        raise UsageError(f"ros-node: {exc}") from None
