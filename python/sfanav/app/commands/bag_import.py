"""``sfanav import``: a robot's ROS bag (camera images, wheel odometry,
optionally ground truth) as an sfanav dataset."""

from __future__ import annotations

import argparse

from .. import arguments as arg
from ..common import existing_path, log, wrap
from ..failures import UsageError
from ..registry import command


@command("import")
def _add_import(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "import",
        help="a robot's ROS bags (images, odometry, ground truth) as a dataset",
        description=wrap("Import recorded runs from ROS bags as an sfanav dataset, one run per bag: a ROS 1 "
                         ".bag, a ROS 2 bag folder (SQLite or MCAP) or a .db3 / .mcap file, read with the "
                         "pure-Python rosbags "
                         "(pip install \"sfanav[ros]\"; no ROS installation). Images (sensor_msgs/Image rgb8, "
                         "bgr8, mono8, ...; sensor_msgs/CompressedImage JPEG or PNG, kept as they are) are "
                         "written as they come, omnidirectional ones unchanged for the unwarping of train and "
                         "localize. Each image gets the odometry (nav_msgs/Odometry) and the ground truth "
                         "(geometry_msgs/PoseStamped) linearly interpolated at its header stamp, the heading "
                         "from the quaternion's yaw. Images no pose covers (before the first message, after "
                         "the last, or in a gap longer than --max-gap) are an error unless --outside says "
                         "otherwise; gaps are reported, never filled with zeros. An interrupted import leaves "
                         "no dataset a later command takes for complete. --list shows the bag's topics."),
        epilog="example:\n  sfanav import run1.bag --list\n"
               "  sfanav import run1.bag run2.bag --image-topic /camera/image_raw --odom-topic /odom "
               "--run train test --out garden\n"
               "  sfanav import run2 --image-topic /camera/image_raw/compressed --odom-topic /odom \\\n"
               "      --pose-topic /ground_truth --outside drop --out garden-run2",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("bags", nargs="+", metavar="BAG", help="ROS 1 .bag, ROS 2 bag folder, or .db3 / .mcap file")
    p.add_argument("--list", action="store_true", help="print the bag's topics with types and counts, and stop")
    p.add_argument("--out", default=None, metavar="DATASET", help="dataset directory to write (new or empty)")
    p.add_argument("--image-topic", default=None, metavar="TOPIC",
                   help="camera topic (default: the bag's only image topic)")
    p.add_argument("--odom-topic", default=None, metavar="TOPIC",
                   help="wheel odometry topic (nav_msgs/Odometry): the odom_x, odom_y, odom_heading columns")
    p.add_argument("--pose-topic", default=None, metavar="TOPIC",
                   help="ground-truth topic (geometry_msgs/PoseStamped, PoseWithCovarianceStamped or "
                        "nav_msgs/Odometry): the x, y, heading columns")
    p.add_argument("--run", dest="run_name", nargs="+", default=None, metavar="NAME",
                   help="name of each bag's run (default: 0 for one bag, else the bags' names without suffix)")
    p.add_argument("--camera", default="center", metavar="NAME", help="name of the camera (default center)")
    p.add_argument("--condition", default="default", metavar="NAME",
                   help="recording condition, e.g. sunny (default: default)")
    p.add_argument("--time", choices=("header", "bag"), default="header",
                   help="header: the messages' header stamps (default); bag: when the bag recorded them")
    p.add_argument("--outside", choices=("error", "drop", "empty"), default="error",
                   help="images no pose covers: error (default), drop them, or keep them with that pose empty")
    p.add_argument("--max-gap", type=arg.pos_float, default=1.0, metavar="S",
                   help="longest interval between two pose messages interpolated across (default 1 s)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing dataset in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_import)
    return p


def _run_import(args: argparse.Namespace) -> int:
    from ...data.dataset import Dataset
    from ...data.rosbag import bag_info

    bags = [existing_path(b, "bag") for b in args.bags]
    if args.list:
        print("\n\n".join(bag_info(b).describe() for b in bags))
        return 0
    if args.out is None:
        raise UsageError("give --out DATASET (or --list to see the bag's topics)")
    if args.odom_topic is None and args.pose_topic is None:
        raise UsageError("give --odom-topic, --pose-topic or both: the images need poses "
                         "(--list shows the bag's topics)")
    ds = Dataset.from_bag(bags, args.out, image_topic=args.image_topic, odom_topic=args.odom_topic,
                          pose_topic=args.pose_topic, run=args.run_name, camera=args.camera,
                          condition=args.condition, time=args.time, outside=args.outside, max_gap=args.max_gap,
                          overwrite=args.overwrite, progress=not args.no_progress, log=log)
    left = ds.metadata.get("images_left_out", 0)
    runs = [b["run"] for b in ds.metadata.get("bags", [])]
    print(f"wrote {len(ds)} images to {args.out} (run{'s' if len(runs) > 1 else ''} {', '.join(runs)}"
          + (f"; {left} images without a pose left out" if left else "") + ")")
    return 0
