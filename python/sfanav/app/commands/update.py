"""``sfanav update``: a trained network with a new run added (its top
layer's slow features re-solved from the stored statistics plus the run's)."""

from __future__ import annotations

import argparse
from typing import Any

from ..common import existing_path, log, new_file, wrap
from ..failures import UsageError
from ..registry import command


@command("update")
def _add_update(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "update",
        help="add a new run to a trained network or localizer without retraining it",
        description=wrap("Add the images of a new run to a network model file saved with its training statistics "
                         "(Network.save(..., include_statistics=True)): the run is streamed through the frozen "
                         "lower layers, its statistics are added to the stored ones as a recording of its own, and "
                         "the top layer's slow features are solved again, exactly as if that stage had been trained "
                         "on all the runs. MODEL is left as it was; NEW is written atomically. A run whose images "
                         "do not match the model (size, channels, pixel scale) is refused. A localizer model file "
                         "(sfanav train --updatable) is updated the same way and its readout refitted on the old "
                         "runs' views it keeps and the new run's: at the run's ground-truth x, y, or, for a run without them, at "
                         "positions in the map's frame learned from the run's odometry and loop closures between "
                         "its images and the map's views (a pose graph on GTSAM). See docs/updates.md."),
        epilog="example:\n  sfanav update net.sfanav --dataset week2 --out net-week2.sfanav",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", metavar="MODEL",
                   help="network model file with training statistics, or updatable localizer model file")
    p.add_argument("--dataset", required=True, metavar="RUN",
                   help="dataset folder holding the new run, or a ROS bag (ROS 1 .bag, ROS 2 folder, .mcap or .db3: "
                        "imported on the fly, as sfanav import would, with the topics below)")
    p.add_argument("--image-topic", default=None, metavar="TOPIC", help="a bag's image topic (default: the only one)")
    p.add_argument("--odom-topic", default=None, metavar="TOPIC", help="a bag's odometry topic")
    p.add_argument("--pose-topic", default=None, metavar="TOPIC", help="a bag's ground-truth pose topic")
    p.add_argument("--run", dest="run_name", default=None, metavar="NAME", help="run of the dataset (default: all)")
    p.add_argument("--camera", default=None, metavar="NAME", help="camera to use if the dataset has several")
    p.add_argument("--out", required=True, metavar="NEW", help="the updated model file")
    p.add_argument("--overwrite", action="store_true", help="replace NEW if it exists")
    p.add_argument("--drop-statistics", action="store_true",
                   help="write NEW without its training statistics (and a localizer without its readout memory: "
                        "smaller; it cannot be updated again)")
    p.add_argument("--mirror", default=None, metavar="CX,CY,INNER,OUTER",
                   help="mirror of omnidirectional images (default: the localizer's)")
    p.add_argument("--kernel", choices=("auto", "keep", "learn"), default="auto",
                   help="a Gaussian-process readout's kernel: keep the fitted one and refit the posterior (fast), "
                        "learn it again as training does, or (auto, default) learn it again once the model has "
                        "seen twice the images it was learned on")
    p.add_argument("--readout", choices=("auto", "keep"), default="auto",
                   help="the readout's kind: chosen again over the map's runs (auto, default: a model whose readout "
                        "was chosen automatically, whenever the kernel is learned again) or refitted as fitted (keep)")
    p.add_argument("--resolve", choices=("top", "all"), default="top",
                   help="re-solve the top stage from the stored statistics (default; exact, a fraction of a "
                        "retrain), or train every layer again on the images the model keeps (sfanav train "
                        "--updatable --keep-images) and the new run, each view paired with the old run's nearest "
                        "view (a retrain's cost; learns what differs between the runs, e.g. light or season)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_update)
    return p


BAG_SUFFIXES = (".bag", ".mcap", ".db3")


def _is_bag(path: "Any") -> bool:
    """A ROS 1 bag, an MCAP or SQLite ROS 2 bag file, or a ROS 2 bag folder."""
    from pathlib import Path

    p = Path(path)
    return p.suffix.lower() in BAG_SUFFIXES or (p.is_dir() and (p / "metadata.yaml").is_file())


def _open_run(args: argparse.Namespace, stack: "Any") -> "Any":
    """The dataset holding the new run: ``--dataset`` as it is, or a bag
    imported into a temporary dataset (removed when ``stack`` closes)."""
    import tempfile
    from pathlib import Path

    from ...data.dataset import Dataset
    from ...data.rosbag import import_bag

    path = existing_path(args.dataset, "dataset or bag")
    if not _is_bag(path):
        return Dataset(path)
    if args.odom_topic is None and args.pose_topic is None:
        raise UsageError(f"{path} is a bag: give --odom-topic, --pose-topic or both (the images need poses)")
    tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="sfanav-update-"))) / "run"
    log(f"importing {path} (as sfanav import would)")
    try:
        return import_bag(path, tmp, image_topic=args.image_topic, odom_topic=args.odom_topic,
                          pose_topic=args.pose_topic, progress=not args.no_progress, log=log)
    except (ValueError, KeyError) as exc:
        raise UsageError(f"{path}: {exc}") from None


def _run_update(args: argparse.Namespace) -> int:
    import contextlib

    with contextlib.ExitStack() as stack:
        return _update(args, stack)


def _update(args: argparse.Namespace, stack: "Any") -> int:
    import numpy as np

    from ...data.sources import select_run
    from ...localization.localizer import Localizer
    from ...sfa.modelfile import load
    from ...sfa.network import Network
    from ...sfa.updates import NetworkUpdater, statistics_bytes

    model = existing_path(args.model, "model file")
    out = new_file(args.out, args.overwrite, "model file")
    if out.resolve() == model.resolve():
        raise UsageError("--out must differ from MODEL: an update leaves the model it starts from as it was")
    net = load(model)
    if isinstance(net, Localizer):
        return _update_localizer(args, model, out, net, stack)
    if not isinstance(net, Network):
        raise UsageError(f"{model} holds a {type(net).__name__}; sfanav update adds runs to network and localizer "
                         "model files")
    if args.resolve != "top":
        raise UsageError(f"{model} is a network: it re-solves its top stage only (--resolve top); training every "
                         "layer again needs the old images, which an updatable localizer keeps (sfanav train "
                         "--updatable --keep-images)")
    updater = NetworkUpdater(net)  # refuses a model without statistics before the run is read
    ds = select_run(_open_run(args, stack), args.run_name, args.camera)
    h, _, c = net.input_shape
    period = net.period_
    native = ds.images(gray=c == 1, indices=np.arange(1))
    first = np.asarray(next(iter(native)))
    if first.shape[:2] != (h, period):
        raise UsageError(f"the run's images are {first.shape[1]}x{first.shape[0]}, but the model was trained on "
                         f"{period}x{h} panoramas: the run does not match the model")
    images = updater.check_run(np.stack(list(ds.images(gray=c == 1))))
    log(f"adding {len(images)} images of {args.dataset} to {model}")
    updater.partial_fit(images)
    new = updater.network_
    new.save(out, include_statistics=not args.drop_statistics)
    stats = statistics_bytes(new)
    print(f"updated with {len(images)} images; training statistics "
          + ("dropped" if args.drop_statistics else f"kept ({stats} bytes)") + f"; wrote {out}")
    return 0


def _update_localizer(args: argparse.Namespace, model: "Any", out: "Any", loc: "Any", stack: "Any") -> int:
    """A localizer model file updated with the run (ground truth needed)."""
    import numpy as np

    from ...data.corruptions import CAMERA
    from ...data.preprocessing import Preprocessing
    from ...data.sources import load_run, select_run
    from ...localization.updates import LocalizerUpdater, drop_readout_memory, readout_memory_bytes
    from ...sfa.updates import UpdatePolicy
    from ..common import mirror_of

    if loc.network is None:
        raise UsageError(f"{model} is a features-only localizer (no network): it cannot read a run's images")
    mem = loc.readout_memory_
    if mem is None:
        raise UsageError(f"{model} keeps no readout memory, so its readout cannot be refitted after an update: "
                         "train it with sfanav train --updatable")
    augmentation = None
    if mem.augmented is not None:
        if loc.info.get("readout_augmentation") != CAMERA.describe():
            raise UsageError(f"{model}'s readout was fitted on corrupted copies of a model this sfanav does not know")
        augmentation = CAMERA
    try:
        # refuses a network without statistics
        updater = LocalizerUpdater(loc, UpdatePolicy(resolve=args.resolve), augmentation=augmentation,
                                   kernel=args.kernel, readout=args.readout)
    except ValueError as exc:
        raise UsageError(f"{model}: {exc}") from None
    ds = select_run(_open_run(args, stack), args.run_name, args.camera)
    _check_source(ds, loc, model)
    xy_ok = bool(np.isfinite(ds.poses[:, :2]).all())
    if not xy_ok and not ds.has_odometry:
        raise UsageError(f"{args.dataset} has neither ground-truth x, y nor odometry for every image: a run joins a "
                         "localizer's map with its positions, or with its odometry and loop closures to the map")
    images, xy = load_run(ds, Preprocessing.of_model(loc), mirror=mirror_of(args, loc), log=log,
                          progress=not args.no_progress)
    joined = None
    frame_of_odometry = loc.info.get("supervision") == "odometry"
    if frame_of_odometry and not ds.has_odometry:
        raise UsageError(f"{model} was trained without ground truth (its map is in its training run's odometry "
                         f"frame): a new run joins it through its odometry, and {args.dataset} has none for every "
                         "image")
    if not xy_ok or frame_of_odometry:  # ground truth is another frame than such a map's: join instead
        joined = _joined_positions(args, model, loc, images, ds.odometry, ds.gyro)
        xy = joined.positions
    log(f"adding {len(images)} images of {args.dataset} to {model} (readout memory: {len(mem)} views)")
    try:
        new = updater.partial_fit(images, xy).localizer_
    except ValueError as exc:
        raise UsageError(f"the run does not match {model}: {exc}") from None
    if joined is not None:
        new.info["updates"][-1]["joined"] = joined.info()
    if args.drop_statistics:
        drop_readout_memory(new)
    sizes = readout_memory_bytes(new)
    new.save(out)  # atomic (a temporary file renamed)
    kept = ("dropped" if args.drop_statistics else
            f"kept ({sizes['readout_memory']} bytes of readout memory, {len(new.readout_memory_)} views; "
            f"{sizes['network_statistics']} bytes of network statistics)")
    how = "chosen again over the map's runs and fitted" if new.selection_ is not None else "refitted"
    print(f"updated with {len(images)} images; readout {new.describe_readout()} {how} on "
          f"{new.info['updates'][-1]['readout_views']} views; update data {kept}; wrote {out}")
    return 0


def _check_source(ds: "Any", loc: "Any", model: "Any") -> None:
    """UsageError if the run's images or camera differ from the training
    run's as the model recorded them (size, channels, row elevations)."""
    import numpy as np

    src = (loc.info or {}).get("source_image")
    first = np.asarray(next(iter(ds.images(indices=np.arange(1)))))
    shape = [int(first.shape[1]), int(first.shape[0]), 1 if first.ndim == 2 else int(first.shape[2])]
    if src is not None and list(src) != shape:
        raise UsageError(f"the run's images are {shape[0]}x{shape[1]} with {shape[2]} channel(s), but {model} was "
                         f"trained on {src[0]}x{src[1]} images with {src[2]}: the run does not match the model")
    elev = (ds.metadata.get("camera") or {}).get("elevation_deg") if isinstance(ds.metadata, dict) else None
    want = (loc.info or {}).get("camera_elevation_deg")
    if want is not None and elev is not None and not np.allclose(np.asarray(elev, float), np.asarray(want, float)):
        raise UsageError(f"the run's camera sees elevations {elev} deg, but {model} was trained on a camera seeing "
                         f"{want} deg: the run does not match the model")


def _joined_positions(args: argparse.Namespace, model: "Any", loc: "Any", images: "Any", odometry: "Any",
                      gyro: "Any" = None) -> "Any":
    """The run joined to the map frame from its odometry and closures to
    the map (sfanav.odometry.map_joining); UsageError if it cannot join."""
    import numpy as np

    from ...odometry.map_joining import join_run

    why = ("its map is in its training run's odometry frame" if loc.info.get("supervision") == "odometry"
           else f"{args.dataset} has no ground-truth x, y")
    log(f"{why}: joining {args.dataset} to {model}'s map through its odometry and loop closures to the map's views "
        "(pose graph, GTSAM)")
    try:
        joined = join_run(loc, images, odometry, gyro=gyro)
        if gyro is not None:
            log("the run has a gyro (gyro_heading): its turns are fused with the odometry's")
    except ImportError as exc:
        raise UsageError(f"joining a run without ground truth needs GTSAM: {exc}") from None
    except ValueError as exc:
        raise UsageError(f"{args.dataset} cannot join {model}'s map: {exc}") from None
    kept = joined.weights >= 0.5
    log(f"joined: {joined.n_kept} of {len(joined.closures)} closures to the map kept (median residual "
        f"{float(np.median(joined.residuals[kept])):.3f} m), {joined.n_compass} compass closures within the run, "
        f"odometry residual {joined.odometry_chi:.2f} sd, {joined.seconds:.1f} s")
    return joined
