"""``sfanav train``: a localizer (network, readout, preprocessing) from one run of a dataset."""

from __future__ import annotations

import argparse
from typing import Any

from .. import arguments as arg
from ..common import existing_path, log, new_file, wrap
from ..failures import UsageError
from ..registry import command
from ..scheduler import connect_scheduler
from .landmarks import add_train_arguments, train_landmarks


@command("train")
def _add_train(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "train",
        help="train a localizer (network + regression to metres) on a dataset",
        description=wrap("Train an SFA network under simulated rotation on one run of a dataset (images in temporal "
                    "order), then the readout from its slowest outputs to the ground-truth x, y (metres). "
                    "Without --preset or --config: the sfanav default (network sfanav-default: Table 5.1 with "
                    "wider layers and 12 outputs, 350x40 RGB; image rows of elevation -10..+20 deg; readout "
                    "a Gaussian process with learned relevance per output, or kernel ridge / kNN if clearly better "
                    "by blocked cross-validation on the training run). With a thesis "
                    "preset: the thesis's configuration (all rows, quadratic regression of 8 outputs). Writes "
                    "one model file (network, readout and the image preprocessing) for sfanav localize / "
                    "evaluate. Images of another size are resized, omnidirectional images unwarped (with "
                    "--mirror or an estimated mirror; --jitter moves the unwarping centre by a random offset per "
                    "training image, thesis 5.2.1, so that the model ignores a robot's tilt on uneven ground)."),
        epilog="network presets: thesis-5.1 (350x40 RGB), thesis-5.2 (600x60 RGB), thesis-5.3 (409x40 gray) "
               "(thesis tables), sfanav-default (350x40 RGB), landmark-120 (120x120 RGB marker views, with --landmarks). A config file is TOML or JSON in the presets' "
               "format (sfanav.Network.preset_path('thesis-5.1') shows one).\n\n"
               "example:\n  sfanav simulate --preset demo --out garden\n"
               "  sfanav train --dataset garden --out garden.sfa                       # the sfanav default\n"
               "  sfanav train --dataset garden --preset thesis-5.2 --precision mixed --out thesis.sfa\n"
               "  sfanav simulate --preset thesis-5.4-landmarks --out marked\n"
               "  sfanav train --dataset marked --landmarks 136,144 --out landmarks.sfa   # thesis 5.4\n"
               "  sfanav simulate --preset thesis-5.2.3-outdoor --out grass                # omnidirectional, tilting\n"
               "  sfanav train --dataset grass --preset thesis-5.3 --normalize --jitter 5 --out grass.sfa",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    net = p.add_mutually_exclusive_group(required=False)
    net.add_argument("--preset", metavar="NAME",
                     help="network preset: thesis-5.1, thesis-5.2 or thesis-5.3 (the thesis's configuration: all "
                          "rows, quadratic regression of 8 outputs), or sfanav-default (the default)")
    net.add_argument("--config", metavar="FILE", help="network config file (TOML or JSON)")
    p.add_argument("--dataset", required=True, metavar="DIR", help="dataset directory (sfanav format)")
    p.add_argument("--out", required=True, metavar="MODEL", help="model file to write (e.g. garden.sfa)")
    p.add_argument("--run", dest="run_name", default=None, metavar="RUN",
                   help="run to train on (default: 'train' if the dataset has one, else all images)")
    p.add_argument("--camera", default=None, metavar="NAME", help="camera to use if the dataset has several")
    p.add_argument("--step", type=arg.pos_int, default=5, metavar="PX",
                   help="simulated rotation step in pixels (default 5, the thesis's)")
    p.add_argument("--window", type=arg.fraction, default=1.0, metavar="FRACTION",
                   help="window of the simulated rotation: a fraction of the panorama (0.6) or a percentage (60%%; default 1.0); "
                        "the network's input width must equal window x panorama width")
    p.add_argument("--precision", choices=("double", "mixed"), default=None,
                   help="statistics precision (default: the config's; mixed is faster, docs/benchmarks.md)")
    p.add_argument("--n-outputs", type=arg.pos_int, default=None, metavar="N",
                   help="slowest outputs read out (default: 8 with the quadratic readout, the thesis's; "
                        "8 or 12 by cross-validation with auto)")
    p.add_argument("--readout", choices=("auto", "quadratic"), default=None,
                   help="auto: a Gaussian process (ARD, marginal likelihood) on the slow features with the panorama's "
                        "Fourier signature (the sfanav default; see --signature), or without a signature a GP, kernel "
                        "ridge or kNN by blocked cross-validation on the training run; quadratic: the thesis's "
                        "regression (default with thesis presets)")
    p.add_argument("--signature", choices=("fourier", "none"), default=None,
                   help="appearance signature read beside the slow features by the auto readout: fourier = the "
                        "rotation-invariant Fourier signature of each panorama (default for the sfanav default; "
                        "stores it for every training place, 7 KB for 350x40 RGB), none = the slow features alone")
    p.add_argument("--rows", choices=("all", "band"), default=None,
                   help="image rows: band = elevation -10..+20 deg only (default for the sfanav default "
                        "network), all = every row (default with --preset thesis-* or --config)")
    p.add_argument("--rotation-pooling", type=arg.pos_int, default=None, metavar="K",
                   help="average the network's outputs over K evenly spaced rotations of each panorama before "
                        "the readout (default: 8 with the auto readout, none with quadratic; 1 = none)")
    p.add_argument("--supervision", choices=("auto", "ground-truth", "odometry"), default="auto",
                   help="what the readout is fitted to: ground-truth x, y, or positions learned from the run's "
                        "images and odometry (no ground truth: estimates in the odometry's frame); "
                        "auto (default): ground truth if the run has it, else odometry")
    p.add_argument("--closures", choices=("relative-pose", "min-warping", "auto", "heading"), default=None,
                   help="with odometry supervision and the pose graph, what its loop closures measure: the whole "
                        "relative pose from the two panoramas (GTSAM) by the warping, by min-warping (a landmark "
                        "distance per image column: better maps on serpentine lanes, worse on dense grids), or "
                        "auto (the default: both, keeping the map its own closures fit better), or the relative "
                        "heading only; docs/relative-pose.md, 'Choosing the method without ground truth'")
    p.add_argument("--metric-map", choices=("pose-graph", "metric-learning"), default="pose-graph",
                   help="with odometry supervision, how positions are learned: pose-graph (default; the odometry's "
                        "heading drift corrected by loop closures found by the slow features and the panoramas) "
                        "or metric-learning (thesis 5.3.1: a map of the slow features fitted along the "
                        "odometry's straight lines)")
    p.add_argument("--loop-closures", choices=("auto", "none", "gt", "bow", "fourier"), default="auto",
                   help="loop-closure feedback (thesis 6.2.1): places the run visits again, found from ground truth "
                        "(gt), a bag of visual words (bow; robust to light) or the Fourier signature (fourier; fast, "
                        "but not robust to light), are trained with the earlier image interleaved "
                        "in the current one's simulated rotation, so the network learns to ignore what changed "
                        "between the visits (light, weather, objects moved). auto (default): with the sfanav default "
                        "network, trained once, and again with bow closures when the network's code changes "
                        "between visits of one place more than their positions explain (docs/loop-closures.md, "
                        "'When feedback is used'); other networks train without feedback; none: never")
    p.add_argument("--closure-weights", choices=("uniform", "score"), default="uniform",
                   help="with --loop-closures: weight every closure 1 (uniform, the thesis) or by the detector's "
                        "match confidence (score)")
    p.add_argument("--robustness", choices=("none", "light", "standard", "full"), default=None,
                   help="guard against what a robot's camera and image transport do to its images (JPEG, noise, "
                        "blur, exposure, white balance; docs/robustness.md): light = photometric normalisation and "
                        "a readout fitted on corrupted copies too; standard = light and a network trained to "
                        "ignore the corruptions (each image interleaved with a corrupted copy, weight 0.25; the "
                        "default for the sfanav default); full = the same at weight 1 (holds under all of them, "
                        "less precise on flawless images); none = neither (the thesis; default with --preset "
                        "thesis-*, --config or --normalize)")
    p.add_argument("--seed", type=arg.nonneg_int, default=0, metavar="N",
                   help="seed of the robustness's corrupted copies (which corruption, how strong, for each image's "
                        "invariance partner and readout copy; default 0). The clean precision of a model trained "
                        "with invariance partners varies with this draw (docs/robustness.md): train at several "
                        "seeds to see how much")
    p.add_argument("--normalize", action="store_true",
                   help="normalize every image to zero mean and unit variance (thesis 5.2)")
    p.add_argument("--mirror", default=None, metavar="CX,CY,INNER,OUTER",
                   help="mirror of omnidirectional images, pixels (default: estimated)")
    p.add_argument("--jitter", type=arg.nonneg_float, default=0.0, metavar="PX",
                   help="centre jitter for omnidirectional images (thesis 5.2.1: 5): the network learns from "
                        "the training images unwarped about the mirror centre moved by a random offset in "
                        "[-PX, PX] in x and y, so that it ignores where the horizon ring lies (a robot tilting on "
                        "uneven ground moves it); the readout is fitted on the images unwarped without jitter, "
                        "as localization unwarps them. Default 0 (none); docs/experiments.md 5.2.3")
    p.add_argument("--jitter-seed", type=arg.nonneg_int, default=0, metavar="N",
                   help="seed of the centre jitter's offsets (default 0)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="train the network on the Dask cluster whose scheduler is at ADDRESS (e.g. "
                        "tcp://10.0.0.5:8786; needs pip install \"sfanav[dask]\" here and on the workers): "
                        "the run's preprocessed frames are cut into one partition per worker, a change of the "
                        "dataset's run column starts a new recording, and everything else (reading, readout) "
                        "runs here. The result equals training without it up to rounding "
                        "(docs/distributed.md)")
    p.add_argument("--updatable", nargs="?", type=arg.pos_int, const=3000, default=None, metavar="N",
                   help="keep what sfanav update needs to add later runs: the network's training statistics and a "
                        "readout memory of at most N evenly spaced training views (default 3000; docs/updates.md "
                        "says what it costs)")
    p.add_argument("--keep-images", action="store_true",
                   help="with --updatable: the readout memory keeps the views' images too (about W x H x C bytes "
                        "each), so that sfanav update --resolve all can train every layer again on the old and new "
                        "runs")
    p.add_argument("--recordings", choices=("auto", "conditions", "runs", "none"), default="auto",
                   help="when the training images are several recordings of the same places (say in different "
                        "light or seasons), the default readout is chosen by holding out one recording at a time "
                        "(its GP against the nearest training views by the panorama's signature; docs/"
                        "localization.md, 'Several recordings'): conditions = the dataset's condition column names "
                        "the recording, runs = its run column; auto (default): conditions when the training images "
                        "hold two or more; none = one recording")
    p.add_argument("--overwrite", action="store_true", help="replace an existing model file")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_train_arguments(p)
    p.set_defaults(run=_run_train)
    return p


def _network_from_args(args: argparse.Namespace) -> "Any":
    from ...sfa.config import read_config_file
    from ...sfa.network import Network

    if args.preset is not None or args.config is None:
        over = {"precision": args.precision} if args.precision else {}
        return Network.from_preset(args.preset or "sfanav-default", **over)
    config = read_config_file(existing_path(args.config, "network config"))
    if args.precision:
        if not isinstance(config, dict):
            raise UsageError(f"{args.config}: not a network config")
        config.setdefault("network", {})["precision"] = args.precision
    return Network(config)


def _recordings(train: Any, how: str) -> Any:
    """The recording of every training image (``--recordings``), or None."""
    if how == "none":
        return None
    labels = train.runs if how == "runs" else train.conditions
    if len(set(labels.tolist())) < 2:
        if how != "auto":
            raise UsageError(f"--recordings {how}: the training images hold one {how[:-1]} only")
        return None
    return labels


def _run_breaks(runs: Any) -> list[int] | None:
    """Frames where the run column changes (None when it never does)."""
    b = [i for i in range(1, len(runs)) if runs[i] != runs[i - 1]]
    return b or None


def _run_times(ds: Any) -> Any:
    """The training run's times (s) for learning positions from odometry,
    which needs them to increase strictly: exact differences of the
    dataset's ``stamp_ns`` from its first image where it has them (float
    Unix seconds cannot tell two stamps 100 ns apart), else its timestamps;
    None if some are unknown. Frames whose stamps do not increase are a
    UsageError naming both frames and their exact stamps (sfanav import
    refuses such bags, so a dataset it made never has them)."""
    import numpy as np

    from ...data.schema import format_stamp_ns

    ns = ds.stamps_ns
    if ns is None:
        t = ds.timestamps
        return t if np.isfinite(t).all() else None
    back = np.flatnonzero(np.diff(ns) <= 0)
    if len(back):
        k = int(back[0])
        a, b = int(ns[k]), int(ns[k + 1])
        fa, fb = int(ds.frames[k]), int(ds.frames[k + 1])
        how = (f"frames {fa} and {fb} have the same stamp t={format_stamp_ns(a)} s ({a} ns)" if a == b else
               f"frame {fb} (t={format_stamp_ns(b)} s) is earlier than frame {fa} (t={format_stamp_ns(a)} s)")
        raise UsageError(f"{ds.root}: {how}; learning positions from odometry needs the frames' times to increase "
                         "strictly" + (f" ({len(back)} such pairs in all)" if len(back) > 1 else ""))
    return (ns - ns[0]) / 1e9


def _run_train(args: argparse.Namespace) -> int:
    import contextlib

    if args.scheduler is not None and args.landmarks is not None:
        raise UsageError("--scheduler trains the panorama network; landmark models (--landmarks) train in this "
                         "process")
    if args.keep_images and args.updatable is None:
        raise UsageError("--keep-images keeps images in the readout memory of an updatable model: add --updatable")
    with contextlib.ExitStack() as stack:
        return _train(args, stack)


def _train(args: argparse.Namespace, stack: Any) -> int:
    import time

    import numpy as np

    from ..._checks import check_n_outputs
    from ...data.dataset import Dataset
    from ...data.preprocessing import Preprocessing, Preprocessor
    from ...data.sources import load_run, select_run
    from ...localization.recipe import CAMERA_ELEVATION, recipe_for, supervision_for
    from ...pipeline import describe_closures, train_localizer
    from ...sfa.network import Rotation

    t0 = time.perf_counter()
    if args.jitter_seed and not args.jitter:
        raise UsageError("--jitter-seed needs --jitter")
    robustness = args.robustness
    if args.normalize:
        if robustness not in (None, "none"):
            raise UsageError(f"--normalize and --robustness {robustness} do not combine: the robustness normalises "
                             "the images itself (log contrast), and its corrupted copies need the 8-bit images")
        robustness = "none"
    out = new_file(args.out, args.overwrite, "model file")
    if args.landmarks is not None:
        return train_landmarks(args, out)
    ds = Dataset(existing_path(args.dataset, "dataset"))
    run = args.run_name
    if run is None and "train" in set(ds.runs.tolist()):
        run = "train"
    train = select_run(ds, run, args.camera)
    net = _network_from_args(args)
    client = None
    if args.scheduler is not None:
        client = connect_scheduler(args.scheduler)
        log(f"training the network on the Dask scheduler at {args.scheduler} "
            f"({len(client.scheduler_info().get('workers', {}))} worker(s))")
        stack.callback(client.close)
    check_n_outputs(args.n_outputs, net.n_outputs_, name="--n-outputs")
    if args.signature == "fourier" and args.readout == "quadratic":
        raise UsageError("--signature fourier needs the auto readout; the quadratic readout reads slow features only")
    recipe = recipe_for(args.preset, config=args.config is not None, readout=args.readout, rows=args.rows,
                        n_outputs=args.n_outputs, rotation_pooling=args.rotation_pooling,
                        signature={None: "auto", "none": None}.get(args.signature, args.signature),
                        robustness=robustness)
    if args.seed and recipe.robustness == "none":
        raise UsageError("--seed draws the robustness's corrupted copies, and this model has none (robustness "
                         "none): give --robustness light, standard or full, or leave --seed out")
    rows, elev = None, None
    if recipe.rows == "band":
        elev = (ds.metadata.get("camera") or {}).get("elevation_deg") if isinstance(ds.metadata, dict) else None
        if elev is None:
            elev = CAMERA_ELEVATION
            log(f"the dataset does not say its rows' elevations: assuming {elev[0]:g}..{elev[1]:g} deg "
                 "(the simulator's) for the horizon band; --rows all uses every row")
        try:
            rows = recipe.image_rows(elev)  # checked before the images are read
        except ValueError as exc:
            raise UsageError(f"horizon band: {exc}") from None
    prep = Preprocessing.for_network(net, window=args.window, normalize=args.normalize)
    odometry = train.odometry
    supervision = supervision_for(args.supervision, has_ground_truth=bool(np.isfinite(train.poses[:, :2]).all()),
                                  has_odometry=bool(np.isfinite(odometry).all()))
    times = _run_times(train) if supervision == "odometry" else None  # checked before any training
    groups = _recordings(train, args.recordings)
    explicit = args.loop_closures not in ("auto", "none")
    if not explicit and args.closure_weights != "uniform":
        raise UsageError("--closure-weights needs --loop-closures gt, bow or fourier")
    if args.closures is not None and args.metric_map != "pose-graph":
        raise UsageError(f"--closures {args.closures} needs --metric-map pose-graph")
    if args.loop_closures == "gt" and supervision != "ground-truth":
        raise UsageError("--loop-closures gt needs ground-truth positions, and this run is trained without them; "
                         "use bow or fourier")
    log(f"training on {len(train)} images of {args.dataset}" + (f" (run {run})" if run else "")
         + f" as {prep.describe()} panoramas; network: {net!r}; rows: {rows.describe() if rows else 'all'}; "
         + f"readout: {recipe.readout}" + (f" with the {recipe.signature} signature" if recipe.signature else "")
         + f"; robustness: {recipe.robustness}" + (" (the sfanav default)" if recipe.name == "sfanav default" else ""))
    preprocessor = Preprocessor(prep, mirror=args.mirror, log=log)
    images, xy = load_run(train, prep, preprocessor=preprocessor, progress=not args.no_progress)
    network_images = None
    if args.jitter and preprocessor.mode == "unwarp":
        jittered = Preprocessor(prep, mirror=preprocessor.mirror_used, log=log, jitter=args.jitter,
                                seed=args.jitter_seed)
        network_images, _ = load_run(train, prep, preprocessor=jittered, progress=not args.no_progress)
        log("the network learns from the jittered panoramas, the readout from the unjittered ones")
    elif args.jitter:
        log(f"centre jitter ({args.jitter:g} px) applies to omnidirectional images only: these images are not "
            "unwarped, so the model is trained without it")
    closures = None
    if explicit:  # image detectors without an odometry gate: dead reckoning drifts
        from ...loopclosure import make_detector

        gt = xy if args.loop_closures == "gt" else None
        closures = make_detector(args.loop_closures).detect(images, positions=gt)
        log(f"loop closures ({args.loop_closures}): {len(closures)} images trained with their earlier visit "
             "interleaved" + (", weighted by match confidence" if args.closure_weights == "score" else ""))
    weights = "score" if closures is not None and args.closure_weights == "score" else None
    network_fit = {}
    if client is not None:
        breaks = _run_breaks(train.runs)
        network_fit = {"client": client, "breaks": breaks}
        if breaks:
            log(f"{len(breaks) + 1} runs: each is its own recording for the network (no derivative pair across "
                "a run change)")
    if supervision == "odometry":
        log("fitting the readout to positions learned from the run's odometry (no ground truth); estimates are "
             "metres in the odometry's frame")
        if train.gyro is not None:
            log("the run has a gyro (gyro_heading): its turns are fused with the odometry's")
    if groups is not None:
        log(f"{len(set(groups.tolist()))} recordings ({args.recordings}): the readout is chosen by holding out one "
            "at a time")
    loc = train_localizer(images, xy=xy, odometry=odometry, timestamps=times, gyro=train.gyro, groups=groups,
                          supervision=supervision, network=net, recipe=recipe, camera_elevation=elev,
                          rotation=Rotation(step=args.step, window=args.window), prep=prep,
                          metric_map=args.metric_map, closures=args.closures, loop_closures=closures,
                          closure_weights=weights, feedback="none" if args.loop_closures == "none" else None,
                          network_images=network_images, network_fit=network_fit, readout_memory=args.updatable,
                          readout_memory_images=args.keep_images, seed=args.seed,
                          info={"dataset": str(args.dataset), "run": run,
                                "network": args.preset or (str(args.config) if args.config else "sfanav-default")},
                          progress=not args.no_progress, log=log)
    if supervision == "odometry" and args.metric_map == "pose-graph":
        log(f"pose graph: {describe_closures(loc.info)}, "
             f"odometry heading drift {loc.info['odometry heading drift (deg per m)']:.3f} deg/m corrected")
    elif supervision == "odometry":
        log(f"metric map from {loc.info['lines']} straight lines ({loc.info['points on lines']} frames), "
             f"rms to the odometry on the first {loc.info['rms to odometry on the first line (m)']:.3f} m")
    if args.updatable is not None:  # what sfanav update checks a new run against
        first = np.asarray(next(iter(train.images(indices=np.arange(1)))))
        loc.info["source_image"] = [int(first.shape[1]), int(first.shape[0]),
                                    1 if first.ndim == 2 else int(first.shape[2])]
        cam_elev = (ds.metadata.get("camera") or {}).get("elevation_deg") if isinstance(ds.metadata, dict) else None
        if cam_elev is not None:
            loc.info["camera_elevation_deg"] = [float(v) for v in cam_elev]
    if preprocessor.mirror_used is not None:
        loc.info["mirror"] = list(preprocessor.mirror_used)  # localize and evaluate reuse it
        if network_images is not None:
            loc.info["centre_jitter_px"] = args.jitter  # the network's training only
            loc.info["centre_jitter_seed"] = args.jitter_seed
    if "ekf_noise" in loc.info:
        log("EKF noise for localize --odometry, from the training run's held-out estimates and odometry "
             "(the fused track nearest the positions the readout was fitted to"
             + (", learned without ground truth" if supervision == "odometry" else "") + "): "
             + ", ".join(f"{k} {v:g}" for k, v in loc.info["ekf_noise"].items()))
    loc.save(out)
    m = loc.train_metrics_
    pool = f" on features pooled over {loc.rotation_pooling_} rotations" if loc.rotation_pooling_ > 1 else ""
    print(f"trained on {len(images)} images in {loc.info['fit_seconds']:.1f} s, readout {loc.describe_readout()}{pool} "
          f"in {loc.info['readout_seconds']:.1f} s (total {time.perf_counter() - t0:.1f} s); "
          f"training-run fit" + (" to the learned positions" if supervision == "odometry" else "")
          + f": MED {m['med']:.3f} m, MAE x {m['mae_x_pct']:.2f} %, y {m['mae_y_pct']:.2f} %")
    print(f"wrote {out}")
    return 0
