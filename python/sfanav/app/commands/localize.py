"""``sfanav localize`` and ``sfanav evaluate``: a trained model on new images, and its report on a run with ground truth."""

from __future__ import annotations

import argparse

from .. import arguments as arg
from ..common import existing_path, fmt, load_localizer, log, mirror_of, new_file, table, wrap
from ..failures import UsageError
from ..registry import command
from .landmarks import evaluate_landmarks_command, is_landmark_model, localize_landmarks


OUT_FORMATS = ("NAME.csv (frame,x,y), NAME.tum (TUM trajectory: timestamp x y z qx qy qz qw, as evo reads it), "
               "NAME.bag (ROS 1 bag), NAME.mcap or NAME.db3 (ROS 2 bag, MCAP or SQLite)")
"""The files ``localize --out`` writes, told apart by their suffix."""


def _check_out_names(outs: list, landmarks: bool) -> None:
    """Refuses an --out whose suffix names no format localize writes (a
    CSV under a bag's name would mislead whatever opens it)."""
    from ...data.rosbag_writer import BAG_SUFFIXES

    known = (".csv",) if landmarks else (".csv", TUM_SUFFIX) + BAG_SUFFIXES
    for o in outs:
        if o.suffix.lower() not in known:
            raise UsageError(f"--out {o}: localize writes " + (
                "one CSV for a landmark model (NAME.csv)" if landmarks else OUT_FORMATS)
                + f", told apart by the name's suffix; {o.suffix or 'no suffix'} is none of them")


TUM_SUFFIX = ".tum"
"""The suffix of the TUM trajectory files localize writes (--out, --out-ground-truth)."""


def _tum_stamps(src, n: int):  # type: ignore[no-untyped-def]
    """The stamps of a TUM file: (stamps, unit), a dataset's exact int64 ns where it has them."""
    if src.stamps_ns is not None:
        return src.stamps_ns[:n], "ns"
    return src.times(n), "s"


def _check_tum_times(src, what: str) -> None:  # type: ignore[no-untyped-def]
    """Refuses, before any work, a TUM file whose images have no times or
    times that do not increase (several runs of a dataset)."""
    import numpy as np

    if src.timestamps is None and src.fps is None:
        raise UsageError(f"{what} needs the images' times: the input is an image folder without them; localize "
                         "a dataset or a video, or write a CSV")
    t = src.stamps_ns if src.stamps_ns is not None else src.timestamps
    if t is not None and len(t) > 1 and not (np.diff(t) > 0).all():
        i = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise UsageError(f"{what}: a trajectory's times must increase, but image {i + 1} is not later than image "
                         f"{i} (a dataset with several runs? choose one with --run)")


@command("localize")
def _add_localize(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "localize",
        help="estimate x, y for every image of a dataset, an image folder or a video",
        description=wrap("Localize every image of INPUT with a trained model: a dataset directory, a folder of "
                    "images (png, jpg, ...; sorted by name) or a video file. Writes a CSV with columns "
                    "frame,x,y (frame: the dataset's frame id, else the image's index; x, y in metres), or "
                    "a TUM trajectory (--out NAME.tum: timestamp x y z qx qy qz qw per line, seconds with nine "
                    "decimals, z = 0, the identity rotation for single-image estimates, the heading's for the fused "
                    "track; evo_ape / evo_rpe read it; --out-ground-truth NAME.tum writes the dataset's truth "
                    "beside it), or "
                    "a ROS bag (--out NAME.bag for ROS 1, NAME.mcap or NAME.db3 for ROS 2 with MCAP or SQLite "
                    "storage) that replays in rviz, Foxglove "
                    "or PlotJuggler: geometry_msgs/PoseStamped on /sfanav/estimate and, with --odometry, the "
                    "fused track as nav_msgs/Odometry on /sfanav/fused, stamped with the images' times (exactly "
                    "the header stamps of a dataset sfanav import made). "
                    "Images are converted as the model was trained: panoramas of another size are resized, "
                    "omnidirectional (mirror) images unwarped with --mirror or an estimated mirror, and "
                    "a message says which."),
        epilog="example:\n  sfanav localize garden.sfa garden --run test --out test.csv\n"
               "  sfanav localize robot.sfa run2 --odometry --out estimates.bag --out estimates.csv\n"
               "  sfanav localize garden.sfa garden --run test --out est.tum --out-ground-truth gt.tum\n"
               "  evo_ape tum gt.tum est.tum -a",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", metavar="MODEL", help="model file from sfanav train")
    p.add_argument("input", metavar="INPUT", help="dataset directory, image folder or video file")
    p.add_argument("--out", required=True, action="append", metavar="CSV|TUM|BAG",
                   help=f"file to write, by its name: {OUT_FORMATS} (a bag needs pip install \"sfanav[ros]\"); "
                        "give --out twice for two")
    p.add_argument("--out-ground-truth", default=None, metavar="NAME.tum",
                   help="also write the dataset's ground truth as a TUM file with the same stamps (for evo: "
                        "evo_ape tum NAME.tum EST.tum -a); its rotations match the TUM estimate's: the true "
                        "heading beside a fused track, the identity beside single-image estimates")
    p.add_argument("--tum-track", choices=("estimates", "fused"), default=None,
                   help="what --out NAME.tum holds: the single-image estimates (identity rotations) or the fused "
                        "track (with its heading; needs --odometry). Default: fused with --odometry, else estimates")
    p.add_argument("--frame-id", default="map", metavar="FRAME",
                   help="frame_id of the poses in a bag (default map)")
    p.add_argument("--run", dest="run_name", default=None, metavar="RUN", help="only this run of a dataset (default: all images)")
    p.add_argument("--camera", default=None, metavar="NAME", help="camera of a multi-camera dataset")
    p.add_argument("--mirror", default=None, metavar="CX,CY,INNER,OUTER",
                   help="mirror center and radii of omnidirectional images, pixels (default: estimated)")
    p.add_argument("--rotations", action="store_true",
                   help="average the estimates over all simulated rotations of each image (slower, smoother)")
    p.add_argument("--odometry", action="store_true",
                   help="fuse the estimates with the run's odometry (EKF, CTRV; a dataset with odom_x, odom_y, "
                        "odom_heading): adds columns fused_x, fused_y, fused_heading; the noise comes from the "
                        "model's training run, the start pose from the first estimates")
    p.add_argument("--camera-gamma", action=argparse.BooleanOptionalAction, default=None,
                   help="take the camera's gamma out of the images, estimated over the recording so far against "
                        "the training views where the images are placed (the median over the last 200 images, "
                        "from the 20th on; ratios within 0.82..1.22 are taken as 1, so a camera like the training "
                        "run's is left exactly as it is; a batch is localized again while a factor applies): a "
                        "camera or image pipeline whose gamma differs from the training run's "
                        "(docs/robustness.md, 'The camera's gamma from the stream'). Default: on wherever the "
                        "model holds the training run's reference (a model trained with a photometric "
                        "normalisation, the sfanav default, since 2026-12-07); --camera-gamma: required, an error "
                        "for a model without it; --no-camera-gamma: off")
    p.add_argument("--rerun", default=None, metavar="NAME.rrd|viewer",
                   help="also log the images, estimates, fused track with covariance ellipses, the learned map and "
                        "the ground truth to a Rerun recording (NAME.rrd), a spawned viewer (viewer) or a running "
                        "one (rerun+http://HOST:PORT/proxy); needs pip install rerun-sdk")
    p.add_argument("--batch-size", type=arg.pos_int, default=64, metavar="N", help="images per batch (default 64)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing CSV")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_localize)
    return p


def _run_localize(args: argparse.Namespace) -> int:

    import numpy as np

    from pathlib import Path

    from ..._files import write_csv_atomic
    from ..._progress import progress_bar
    from ...data.camera_gamma import CameraGamma, predict_corrected
    from ...data.preprocessing import Preprocessing, Preprocessor
    from ...data.ros_messages import require_rosbags
    from ...data.rosbag_writer import BAG_SUFFIXES, write_estimates
    from ...data.sources import open_images
    from ...data.tum import write_tum
    from ...localization.error_metrics import med
    from ...odometry.streaming import StreamingLocalizer

    loc = load_localizer(args.model, landmarks=True)
    if is_landmark_model(loc):
        if args.out_ground_truth is not None or args.tum_track is not None:
            raise UsageError(f"{args.model} is a landmark model: it writes one CSV (--out FILE.csv); "
                             "--out-ground-truth and --tum-track apply to SFA models")
        if len(args.out) != 1 or Path(args.out[0]).suffix.lower() in BAG_SUFFIXES:
            raise UsageError(f"{args.model} is a landmark model: it writes one CSV (--out FILE.csv), not bags")
        _check_out_names([Path(args.out[0])], landmarks=True)
        return localize_landmarks(args, loc, new_file(args.out[0], args.overwrite, "CSV"))
    if args.rotations and loc.rotation_pooling_ > 1:
        raise UsageError(f"{args.model} averages its features over {loc.rotation_pooling_} rotations already "
                          "(rotation pooling): --rotations applies to models without it")
    _check_out_names([Path(o) for o in args.out], landmarks=False)
    outs = [new_file(o, args.overwrite, "output") for o in args.out]
    if len({o.resolve() for o in outs}) != len(outs):
        raise UsageError("--out names the same file twice")
    bags = [o for o in outs if o.suffix.lower() in BAG_SUFFIXES]
    tums = [o for o in outs if o.suffix.lower() == TUM_SUFFIX]
    gt_out = None
    if args.out_ground_truth is not None:
        if Path(args.out_ground_truth).suffix.lower() != TUM_SUFFIX:
            raise UsageError(f"--out-ground-truth {args.out_ground_truth}: it writes a TUM file (NAME{TUM_SUFFIX}), "
                             f"{Path(args.out_ground_truth).suffix or 'no suffix'} is not one")
        gt_out = new_file(args.out_ground_truth, args.overwrite, "ground-truth file")
        if gt_out.resolve() in {o.resolve() for o in outs}:
            raise UsageError("--out-ground-truth names a file that --out names too")
    if args.tum_track is not None and not tums:
        raise UsageError(f"--tum-track chooses what --out NAME{TUM_SUFFIX} holds; no --out names a TUM file")
    if args.tum_track == "fused" and not args.odometry:
        raise UsageError("--tum-track fused writes the fused track: it needs --odometry")
    track = args.tum_track or ("fused" if args.odometry else "estimates")
    if bags:
        require_rosbags()
    src = open_images(args.input, run=args.run_name, camera=args.camera)
    if bags and src.timestamps is None and src.fps is None:
        raise UsageError(f"a bag needs the images' times: {args.input} is an image folder without them; localize "
                         "a dataset (sfanav import makes one from a bag) or a video, or write a CSV")
    if tums:
        _check_tum_times(src, f"--out {tums[0]}")
    gt_heading = None
    if gt_out is not None:
        _check_tum_times(src, f"--out-ground-truth {gt_out}")
        if src.kind != "dataset" or src.xy is None or not np.isfinite(src.xy).all():
            raise UsageError(f"--out-ground-truth needs a dataset with ground-truth x, y for every image; "
                             f"{args.input} has " + ("none" if src.xy is None or not np.isfinite(src.xy).any()
                                                    else "them for some images only"))
        if track == "fused":  # beside a fused track (poses with headings), the truth with its heading
            gt_heading = _true_heading(args)
            if gt_heading is None:
                log(f"{args.input} has no ground-truth heading for every image: {gt_out} gets the identity rotation")
    if args.odometry:
        if src.odometry is None or not np.isfinite(src.odometry).all():
            raise UsageError(f"--odometry needs a dataset with odometry (odom_x, odom_y, odom_heading) for every "
                              f"frame; {args.input} has none" + (" for some frames" if src.odometry is not None else ""))
        if "ekf_noise" not in loc.info:
            raise UsageError(f"{args.model} holds no EKF noise (its training run had no odometry): retrain it on a "
                              "run with odometry to use --odometry")
    gamma = None if args.camera_gamma is False else CameraGamma.for_localizer(loc)
    if args.camera_gamma:
        if gamma is None:
            raise UsageError(f"--camera-gamma: {args.model} holds no camera gamma reference (trained without a "
                             "photometric normalisation, or before 2026-12-07): retrain it, or leave --camera-gamma out")
    prep = Preprocessing.of_model(loc)
    conform = Preprocessor(prep, mirror=mirror_of(args, loc), log=log)
    log(f"localizing {src.description} with {args.model} ({prep.describe()} panoramas)")
    view = _open_view(args.rerun, args.overwrite) if args.rerun else None
    bar = progress_bar(not args.no_progress, src.n, "localize")
    preds = []
    live = None
    if args.odometry:  # the streaming localizer over the recording: what a live robot runs, the same numbers
        live = StreamingLocalizer(loc, loc.info["ekf_noise"], mirror=mirror_of(args, loc), log=log,
                                  camera_gamma=gamma is not None,
                                  rotations=args.rotations, max_pending=max(100, args.batch_size))
        stamps = _stream_stamps(src)
    i = 0
    for batch in src.batches(args.batch_size):
        n = len(batch)
        if live is None:
            preds.append(predict_corrected(loc, gamma, conform(batch), source=batch, conform=conform,
                                           rotations=args.rotations))
        else:
            preds += live.push_images(stamps[i:i + n], batch)
            for j in range(i, i + n):
                preds += live.push_odometry(stamps[j], src.odometry[j])
        if view is not None:
            _log_batch(view, src, batch, i, preds if live is not None else preds[-1])
        i += n
        if bar is not None:
            bar.update(len(batch))
    if live is not None:
        preds += live.flush()
    if bar is not None:
        bar.close()
    if not preds:
        raise UsageError(f"{args.input} has no images (an empty or unreadable video?)")
    fused = None
    if live is None:
        xy = np.concatenate(preds)
    else:
        xy = np.array([e.estimate for e in preds])
        if live.init_error_ is not None or any(e.pose is None for e in preds):
            raise UsageError("--odometry: no start pose from the first images' estimates: " + (
                live.init_error_ or f"the first {live.start_frames} frames do not move in the odometry"))
        fused = np.array([e.pose for e in preds])
        log(f"fused track: {live.n_reinitializations_} re-initialisation(s) from the single-image estimates, "
            f"{live.n_jumps_} odometry jump(s)")
        if live.novelty_threshold is not None:
            log(f"novelty: {live.n_novel_} of {live.n_images_} images farther from the training run than its own "
                f"images are; their estimates weighed as up to {live.max_measurement_scale_:.1f}x noisier")
    tracker = gamma if live is None else live.camera_gamma
    if tracker is not None:
        log(f"camera gamma: the last {min(tracker.n_images_, tracker.window)} images' log spread is "
            f"{np.exp(-tracker.log_ratio_):.2f}x the training views' where they were placed; the images were taken "
            f"through a power of {tracker.factor_:.2f} (1 before the {tracker.min_images}th image and while the "
            f"ratio is within {np.exp(-tracker.dead_zone):.2f}..{np.exp(tracker.dead_zone):.2f})"
            + (f"; {tracker.n_reverted_} corrected images were farther from the training views than as they came "
               "and were localized as they came" if tracker.n_reverted_ else ""))
    frames = src.frames if src.frames is not None else np.arange(len(xy))
    if view is not None:
        if live is not None:  # the last batch's estimates, emitted at flush
            _log_batch(view, src, None, i, preds)
        if loc.training_positions_ is not None:
            view.log_map(loc.training_positions_)
        view.close()
        log(f"logged {view.n_logged_} estimates to Rerun ({view.target})")
    for out in outs:
        if out in tums:
            stamps, unit = _tum_stamps(src, len(xy))
            if track == "fused":
                write_tum(out, stamps, fused[:, :2], fused[:, 2], unit=unit)
            else:
                write_tum(out, stamps, xy, unit=unit)
            continue
        if out in bags:  # a dataset's exact stamps where it has them: each estimate then carries its image's
            exact = src.stamps_ns is not None
            write_estimates(out, src.stamps_ns[: len(xy)] if exact else src.times(len(xy)), xy, fused,
                            frame_id=args.frame_id, overwrite=True, unit="ns" if exact else "s")
            continue
        write_csv_atomic(out, ["frame", "x", "y"] + (["fused_x", "fused_y", "fused_heading"] if fused is not None else []),
                         ([int(fr), f"{x:.4f}", f"{y:.4f}"] + ([f"{v:.4f}" for v in fused[i]] if fused is not None else [])
                          for i, (fr, (x, y)) in enumerate(zip(frames, xy))))
    if gt_out is not None:
        stamps, unit = _tum_stamps(src, len(xy))
        write_tum(gt_out, stamps, src.xy[: len(xy)], gt_heading, unit=unit)
    written = outs + ([gt_out] if gt_out is not None else [])
    msg = (f"wrote {len(xy)} positions" + (f" and the fused track ({live.n_reinitializations_} re-initialisations)"
                                            if fused is not None else "")
           + (" and the ground truth" if gt_out is not None else "")
           + f" to {' and '.join(str(o) for o in written)}")
    if loc.info.get("supervision") == "odometry":
        msg += " (metres in the training run's odometry frame)"
    elif src.xy is not None and np.isfinite(src.xy).all():
        msg += f" (MED from the dataset's ground truth: {med(xy, src.xy):.3f} m"
        msg += f", fused {med(fused[:, :2], src.xy):.3f} m)" if fused is not None else ")"
    print(msg)
    if src.xy is not None and np.isfinite(src.xy).all() and len(xy) > 1:
        true_h = gt_heading if gt_heading is not None else (
            _true_heading(args) if fused is not None and src.kind == "dataset" else None)
        print(_ape_rpe_line(xy, fused, src.xy, true_h))
    return 0


def _open_view(target: str, overwrite: bool):  # type: ignore[no-untyped-def]
    """The Rerun view of --rerun (a one-line error without rerun-sdk or for a bad target)."""
    from pathlib import Path

    from ...odometry.live_view import RerunView

    if Path(target).suffix.lower() == ".rrd":
        new_file(target, overwrite, "Rerun recording")
    try:
        return RerunView(target)
    except (ImportError, ValueError) as exc:
        raise UsageError(f"--rerun: {exc}") from None


def _log_batch(view, src, batch, start: int, estimates) -> None:  # type: ignore[no-untyped-def]
    """Logs a batch's images (frames start..) and ground truth, and the estimates not logged yet: the streaming
    localizer's LiveEstimates (all emitted so far) or a batch's (n, 2) array."""
    import numpy as np

    from ...odometry.streaming import LiveEstimate

    exact = src.stamps_ns is not None
    if batch is not None:
        for k, img in enumerate(batch):
            f = start + k
            view.log_image(img, stamp_ns=int(src.stamps_ns[f]) if exact else None, frame=f)
            if src.xy is not None and np.isfinite(src.xy[f]).all():
                view.log_truth(src.xy[f], stamp_ns=int(src.stamps_ns[f]) if exact else None, frame=f)
    if isinstance(estimates, np.ndarray):
        for k, xy in enumerate(estimates):
            f = start + k
            view.log(LiveEstimate(int(src.stamps_ns[f]) if exact else f, xy, np.full(3, np.nan), None, None, None),
                     frame=f, stamp=exact)
        return
    for f in range(view.n_logged_, len(estimates)):
        view.log(estimates[f], frame=f, stamp=exact)


def _stream_stamps(src):  # type: ignore[no-untyped-def]
    """Integer stamps (ns) ordering a recording's frames for the streaming localizer: the dataset's where they
    increase, else the frame indices (the fused track depends on the order only)."""
    import numpy as np

    s = src.stamps_ns
    if s is not None and len(s) >= src.n and (np.diff(np.asarray(s[: src.n], dtype=np.int64)) > 0).all():
        return [int(v) for v in s[: src.n]]
    return list(range(src.n))


def _true_heading(args: argparse.Namespace):  # type: ignore[no-untyped-def]
    """The ground-truth headings (rad) of the localized images, None if some are unknown."""
    import numpy as np

    from ...data.dataset import Dataset
    from ...data.sources import select_run

    h = select_run(Dataset(args.input), args.run_name, args.camera).poses[:, 2]
    return h if np.isfinite(h).all() else None


def _ape_rpe_line(xy, fused, truth, true_heading) -> str:  # type: ignore[no-untyped-def]
    """evo's APE and RPE (translation, after the rigid alignment on this run) of the estimates (identity
    rotations) and the fused track (with its heading and the true heading where known), as evo computes them on
    the TUM files localize writes."""
    from ...localization.trajectory_metrics import trajectory_errors

    def one(name: str, est, h=None) -> str:  # type: ignore[no-untyped-def]
        try:
            e = trajectory_errors(est, truth, estimate_heading=h, reference_heading=None if h is None else true_heading)
        except ValueError as exc:  # e.g. all estimates at one point: no alignment
            return f"{name}: none ({exc})"
        return (f"{name}: APE rmse {e['ape_rmse']:.3f} m (mean {e['ape_mean']:.3f}, median {e['ape_median']:.3f}, "
                f"max {e['ape_max']:.3f}), RPE rmse {e['rpe_rmse']:.3f} m per frame")

    parts = [one("estimates", xy)] + ([one("fused", fused[:, :2], None if true_heading is None else fused[:, 2])]
                                      if fused is not None else [])
    return ("evo's trajectory errors (translation, each track rigidly aligned to the truth on this run): "
            + "; ".join(parts))


@command("evaluate")
def _add_evaluate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "evaluate",
        help="metrics, baselines, plots and a report of a model on a dataset with ground truth",
        description=wrap("Evaluate a trained model on a run of a dataset with ground truth: MAE per axis (m and % "
                    "of the coordinate range), MED, percentiles (regression fitted on the training run: the "
                    "honest protocol) and the thesis 5.1.1 protocol (random 50/50 splits of the evaluated "
                    "run, 100 repeats; optimistic on a continuous walk); eta_p / eta_phi of the outputs; "
                    "error vs number of outputs; the baselines perfect memory (RIDF) and Fourier signature "
                    "fitted on the training run (error, bytes per place, query time). Writes report.md, "
                    "metrics.json and PNG plots (firing maps, trajectory, error vs n, eta) under --out."),
        epilog="example:\n  sfanav evaluate garden.sfa garden --out garden-report",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", metavar="MODEL", help="model file from sfanav train")
    p.add_argument("dataset", metavar="DATASET", help="dataset directory with ground-truth positions")
    p.add_argument("--out", required=True, metavar="DIR", help="directory for report.md, metrics.json and plots")
    p.add_argument("--run", dest="run_name", default=None, metavar="RUN",
                   help="run to evaluate (default: 'test' if the dataset has one, else all images)")
    p.add_argument("--train-run", default=None, metavar="RUN",
                   help="training run for eta, the error curve and the baselines (default: 'train' if present)")
    p.add_argument("--camera", default=None, metavar="NAME", help="camera of a multi-camera dataset")
    p.add_argument("--mirror", default=None, metavar="CX,CY,INNER,OUTER",
                   help="mirror of omnidirectional images, pixels (default: estimated)")
    p.add_argument("--no-baselines", action="store_true", help="skip perfect memory and the Fourier signature")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(run=_run_evaluate)
    return p


def _run_evaluate(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    import numpy as np

    from ...data.dataset import Dataset
    from ...data.preprocessing import Preprocessing
    from ...data.sources import load_run, select_run
    from ...localization.evaluation import evaluate, evaluation_rows, metrics_json

    loc = load_localizer(args.model, landmarks=True)
    if is_landmark_model(loc):
        return evaluate_landmarks_command(args, loc)
    ds = Dataset(existing_path(args.dataset, "dataset"))
    runs = set(ds.runs.tolist())
    run = args.run_name if args.run_name is not None else ("test" if "test" in runs else None)
    train_run = args.train_run if args.train_run is not None else ("train" if "train" in runs and run != "train" else None)
    if loc.info.get("supervision") == "odometry" and train_run is None:
        raise UsageError(f"{args.model} was trained without ground truth (it reports in its training run's odometry "
                          "frame): evaluate needs a training run with ground truth (--train-run) to align the frames")
    prep = Preprocessing.of_model(loc)
    test = select_run(ds, run, args.camera)
    mirror = mirror_of(args, loc)
    images, xy = load_run(test, prep, mirror=mirror, log=log, progress=not args.no_progress)
    if not np.isfinite(xy).all():
        raise UsageError(f"{args.dataset} lacks ground-truth x, y: evaluation needs them")
    tr_images = tr_xy = None
    if train_run is not None:
        tr = select_run(ds, train_run, args.camera)
        tr_images, tr_xy = load_run(tr, prep, mirror=mirror, log=log, progress=not args.no_progress)
    out = Path(args.out)
    log(f"evaluating {args.model} on {len(images)} images" + (f" (run {run})" if run else "")
         + (f", training run {train_run}" if train_run else ""))
    ev = evaluate(loc, images, xy, train_images=tr_images, train_xy=tr_xy, out=out,
                  title=f"sfanav evaluation: {Path(args.model).name} on {args.dataset}",
                  run_baselines=not args.no_baselines, log=log,
                  text=[f"Model `{args.model}`, dataset `{args.dataset}`, evaluated run: {run or 'all images'}, "
                        f"training run: {train_run or 'none'}."])
    (out / "metrics.json").write_text(json.dumps(metrics_json(ev), indent=2) + "\n")
    rows = evaluation_rows(ev)
    print(table([("metric", "sfanav")] + [(r["metric"], fmt(r["sfanav"])) for r in rows]))
    if "ape_rmse" in ev.metrics:
        print(f"trajectory errors as evo defines them: APE rmse {ev.metrics['ape_rmse']:.3f} m (aligned on the run), "
              f"RPE rmse {ev.metrics['rpe_rmse']:.3f} m per frame")
    print(f"wrote {ev.report}, {out / 'metrics.json'} and {len(ev.plots)} plots")
    return 0
