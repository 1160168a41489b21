"""The ``sfanav`` command.

Subcommands:

* ``sfanav simulate --preset NAME --out DIR [--seed N]``: a dataset from the
  built-in garden simulator.
* ``sfanav train --dataset DIR --preset NAME|--config FILE --out MODEL``:
  train a network under simulated rotation and the regression to metres.
* ``sfanav localize MODEL INPUT --out CSV``: positions of a dataset, an image
  folder or a video, one CSV row ``frame,x,y`` per image.
* ``sfanav evaluate MODEL DATASET --out DIR``: metrics, baselines, plots and a
  Markdown report.
* ``sfanav navigate MODEL DATASET --start X,Y --target X,Y --out DIR``: drive
  the simulated robot of a dataset's world to a target with a trained model.
* ``sfanav demo``: simulate, train, localize and evaluate the demo garden.
* ``sfanav experiment NAME`` / ``--list``: rerun a thesis experiment.

Errors in the input (unknown preset, bad size, an existing output directory,
a missing dataset, a bad network config or model file, a request beyond the
machine's memory, ...) end with a one-line message on stderr and exit status
2, never a traceback (set ``SFANAV_DEBUG=1`` to see the traceback); an exception
of another kind is a bug and shows its traceback. SIGINT and SIGTERM stop a command with
status 130 and 143, leaving no output that a later command takes for complete.
Results go to stdout, progress and notes to stderr.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from . import arguments as arg
from .failures import Terminated, UsageError, is_input_error, on_sigterm, one_line

if TYPE_CHECKING:
    from pathlib import Path


EXIT_USAGE = 2


# subcommand name -> function that adds its parser (with a ``run`` default)
_COMMANDS: dict[str, Callable[[argparse._SubParsersAction], argparse.ArgumentParser]] = {}


def command(name: str) -> Callable:
    """Registers a subcommand: the decorated function adds its parser to the
    subparsers and sets the parser's ``run`` default to the function that
    executes it (returning the exit status)."""

    def deco(add_parser: Callable[[argparse._SubParsersAction], argparse.ArgumentParser]) -> Callable:
        _COMMANDS[name] = add_parser
        return add_parser

    return deco


@command("simulate")
def _add_simulate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from ..sim import presets

    p = sub.add_parser(
        "simulate",
        help="generate a dataset with the built-in garden simulator",
        description="Generate a dataset (PNG images, frames.csv, metadata.json, world.json) from one of the "
                    "simulator presets of the thesis's scenes.",
        epilog="presets:\n" + "\n".join("  " + ln for ln in presets.describe().splitlines()),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--preset", required=True, metavar="NAME", help="scene preset (listed below)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (new or empty)")
    p.add_argument("--seed", type=arg.nonneg_int, default=0, help="seed of world, trajectories and noise (default 0)")
    p.add_argument("--max-frames", type=arg.pos_int, default=None, metavar="N",
                   help="keep only the first N frames of every run (quick looks)")
    p.add_argument("--camera", choices=("panorama", "omni"), default=None,
                   help="replace the preset's camera by a panoramic or an omnidirectional one")
    p.add_argument("--size", type=arg.size, default=None, metavar="WxH",
                   help="image size (panorama WIDTHxHEIGHT, omni SIZE); default the preset's")
    p.add_argument("--gray", action="store_true", help="gray images instead of RGB")
    p.add_argument("--overwrite", action="store_true", help="replace an existing dataset in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_simulate)
    return p


def _run_simulate(args: argparse.Namespace) -> int:
    from ..sim import OmniCamera, PanoramicCamera, presets

    if args.preset not in presets.PRESETS:
        raise UsageError(f"unknown preset {args.preset!r}; available: {', '.join(presets.PRESETS)}")
    p = presets.get(args.preset)
    camera = None
    if args.camera or args.size or args.gray:
        base = p.camera()
        kind = args.camera or base.kind
        if kind == "omni":
            size = args.size[0] if args.size else (base.size if isinstance(base, OmniCamera) else 500)
            if args.size and args.size[0] != args.size[1]:
                raise UsageError(f"an omni image is square: give --size N or NxN, got {args.size[0]}x{args.size[1]}")
            camera = OmniCamera(size, rgb=not args.gray)
        else:
            if args.size:
                w, h = args.size
            elif isinstance(base, PanoramicCamera):
                w, h = base.width, base.height
            else:
                w, h = 600, 60
            el = base.elevation_deg if isinstance(base, PanoramicCamera) else (-30.0, 20.0)
            camera = PanoramicCamera(w, h, el, rgb=not args.gray)
    ds = presets.simulate(args.preset, args.out, args.seed, max_frames=args.max_frames, camera=camera,
                          overwrite=args.overwrite, progress=not args.no_progress)
    print(f"wrote {len(ds)} images to {args.out}")
    return 0


def _log(message: str) -> None:
    """Progress and notes go to stderr; results to stdout."""
    print(message, file=sys.stderr, flush=True)


def _existing_path(text: str, what: str) -> "Path":
    from pathlib import Path

    p = Path(text)
    if not p.exists():
        raise UsageError(f"{what} {text} does not exist")
    return p


def _new_file(text: str, overwrite: bool, what: str = "output") -> "Path":
    from pathlib import Path

    p = Path(text)
    if p.exists() and not overwrite:
        raise UsageError(f"{what} {p} exists; pass --overwrite to replace it")
    if p.exists() and p.is_dir():
        raise UsageError(f"{what} {p} is a directory")
    p.parent.mkdir(parents=True, exist_ok=True)
    return p


def _load_localizer(path: str) -> "Any":
    from .. import load
    from ..localization.localizer import Localizer

    model = load(_existing_path(path, "model file"))
    if not isinstance(model, Localizer):
        raise UsageError(f"{path} holds a {type(model).__name__}, not a localizer (make one with sfanav train)")
    if model.network is None:
        raise UsageError(f"{path} is a features-only localizer (no network): it cannot read images")
    return model


def _mirror_of(args: argparse.Namespace, loc: "Any") -> "Any":
    """--mirror, else the mirror the model was trained with (if it unwarped)."""
    if args.mirror is not None:
        return args.mirror
    m = (loc.info or {}).get("mirror")
    if m is not None:
        _log("using the mirror the model was trained with (--mirror overrides it)")
    return m




def _wrap(text: str) -> str:
    """A help description wrapped to 79 columns (the raw formatter keeps
    the examples in the epilogs as written)."""
    import textwrap

    return textwrap.fill(" ".join(text.split()), 79)


def _table(rows: "list[tuple[str, str]]") -> str:
    w = max(len(a) for a, _ in rows)
    return "\n".join(f"{a:<{w}}  {b}" for a, b in rows)


def _fmt(v: "Any") -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


@command("train")
def _add_train(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "train",
        help="train a localizer (network + regression to metres) on a dataset",
        description=_wrap("Train an SFA network under simulated rotation on one run of a dataset (images in temporal "
                    "order), then the readout from its slowest outputs to the ground-truth x, y (metres). "
                    "Without --preset or --config: the sfanav default (network sfanav-default: Table 5.1 with "
                    "wider layers and 12 outputs, 350x40 RGB; image rows of elevation -10..+20 deg; readout "
                    "a Gaussian process with learned relevance per output, or kernel ridge / kNN if clearly better "
                    "by blocked cross-validation on the training run). With a thesis "
                    "preset: the thesis's configuration (all rows, quadratic regression of 8 outputs). Writes "
                    "one model file (network, readout and the image preprocessing) for sfanav localize / "
                    "evaluate. Images of another size are resized, omnidirectional images unwarped (with "
                    "--mirror or an estimated mirror)."),
        epilog="network presets: thesis-5.1 (350x40 RGB), thesis-5.2 (600x60 RGB), thesis-5.3 (409x40 gray) "
               "(thesis tables), sfanav-default (350x40 RGB). A config file is TOML or JSON in the presets' "
               "format (sfanav.Network.preset_path('thesis-5.1') shows one).\n\n"
               "example:\n  sfanav simulate --preset demo --out garden\n"
               "  sfanav train --dataset garden --out garden.sfa                       # the sfanav default\n"
               "  sfanav train --dataset garden --preset thesis-5.2 --precision mixed --out thesis.sfa",
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
    p.add_argument("--metric-map", choices=("pose-graph", "metric-learning"), default="pose-graph",
                   help="with odometry supervision, how positions are learned: pose-graph (default; the odometry's "
                        "heading drift corrected by loop closures found by the slow features and the panoramas) "
                        "or metric-learning (thesis 5.3.1: a map of the slow features fitted along the "
                        "odometry's straight lines)")
    p.add_argument("--loop-closures", choices=("gt", "bow", "fourier"), default=None,
                   help="loop-closure feedback (thesis 6.2.1): places the run visits again, found from ground truth "
                        "(gt), a bag of visual words (bow; robust to light) or the Fourier signature (fourier; fast, "
                        "but not robust to light), are trained with the earlier image interleaved "
                        "in the current one's simulated rotation, so the network learns to ignore what changed "
                        "between the visits (light, weather). Default: none")
    p.add_argument("--closure-weights", choices=("uniform", "score"), default="uniform",
                   help="with --loop-closures: weight every closure 1 (uniform, the thesis) or by the detector's "
                        "match confidence (score)")
    p.add_argument("--normalize", action="store_true",
                   help="normalize every image to zero mean and unit variance (thesis 5.2)")
    p.add_argument("--mirror", default=None, metavar="CX,CY,INNER,OUTER",
                   help="mirror of omnidirectional images, pixels (default: estimated)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing model file")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(run=_run_train)
    return p


def _network_from_args(args: argparse.Namespace) -> "Any":
    from ..sfa.network import Network, read_config_file

    if args.preset is not None or args.config is None:
        over = {"precision": args.precision} if args.precision else {}
        return Network.from_preset(args.preset or "sfanav-default", **over)
    config = read_config_file(_existing_path(args.config, "network config"))
    if args.precision:
        if not isinstance(config, dict):
            raise UsageError(f"{args.config}: not a network config")
        config.setdefault("network", {})["precision"] = args.precision
    return Network(config)


def _run_train(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from .._checks import check_n_outputs
    from ..data.dataset import Dataset
    from ..data.preprocessing import Preprocessing, Preprocessor
    from ..data.sources import load_run, select_run
    from ..localization.recipe import CAMERA_ELEVATION, recipe_for, supervision_for
    from ..localization.training import fit_localizer
    from ..odometry.fusion import noise_for_localizer
    from ..odometry.self_supervision import fit_localizer_from_odometry
    from ..sfa.network import Rotation

    t0 = time.perf_counter()
    out = _new_file(args.out, args.overwrite, "model file")
    ds = Dataset(_existing_path(args.dataset, "dataset"))
    run = args.run_name
    if run is None and "train" in set(ds.runs.tolist()):
        run = "train"
    train = select_run(ds, run, args.camera)
    net = _network_from_args(args)
    check_n_outputs(args.n_outputs, net.n_outputs_, name="--n-outputs")
    if args.signature == "fourier" and args.readout == "quadratic":
        raise UsageError("--signature fourier needs the auto readout; the quadratic readout reads slow features only")
    recipe = recipe_for(args.preset, config=args.config is not None, readout=args.readout, rows=args.rows,
                        n_outputs=args.n_outputs, rotation_pooling=args.rotation_pooling,
                        signature={None: "auto", "none": None}.get(args.signature, args.signature))
    rows = None
    if recipe.rows == "band":
        elev = (ds.metadata.get("camera") or {}).get("elevation_deg") if isinstance(ds.metadata, dict) else None
        if elev is None:
            elev = CAMERA_ELEVATION
            _log(f"the dataset does not say its rows' elevations: assuming {elev[0]:g}..{elev[1]:g} deg "
                 "(the simulator's) for the horizon band; --rows all uses every row")
        try:
            rows = recipe.image_rows(elev)
        except ValueError as exc:
            raise UsageError(f"horizon band: {exc}") from None
    prep = Preprocessing.for_network(net, window=args.window, normalize=args.normalize)
    odometry = train.odometry
    supervision = supervision_for(args.supervision, has_ground_truth=bool(np.isfinite(train.poses[:, :2]).all()),
                                  has_odometry=bool(np.isfinite(odometry).all()))
    if args.loop_closures is None and args.closure_weights != "uniform":
        raise UsageError("--closure-weights needs --loop-closures")
    if args.loop_closures == "gt" and supervision != "ground-truth":
        raise UsageError("--loop-closures gt needs ground-truth positions, and this run is trained without them; "
                         "use bow or fourier")
    _log(f"training on {len(train)} images of {args.dataset}" + (f" (run {run})" if run else "")
         + f" as {prep.describe()} panoramas; network: {net!r}; rows: {rows.describe() if rows else 'all'}; "
         + f"readout: {recipe.readout}" + (f" with the {recipe.signature} signature" if recipe.signature else "")
         + (" (the sfanav default)" if recipe.name == "sfanav default" else ""))
    preprocessor = Preprocessor(prep, mirror=args.mirror, log=_log)
    images, xy = load_run(train, prep, preprocessor=preprocessor, progress=not args.no_progress)
    closures = None
    if args.loop_closures is not None:  # image detectors without an odometry gate: dead reckoning drifts
        from ..loopclosure import make_detector

        gt = xy if args.loop_closures == "gt" else None
        closures = make_detector(args.loop_closures).detect(images, positions=gt)
        _log(f"loop closures ({args.loop_closures}): {len(closures)} images trained with their earlier visit "
             "interleaved" + (", weighted by match confidence" if args.closure_weights == "score" else ""))
    weights = "score" if closures is not None and args.closure_weights == "score" else None
    fit_kw = dict(loop_closures=closures, closure_weights=weights, rotation=Rotation(step=args.step, window=args.window),
                  n_outputs=recipe.n_outputs,
                  readout=recipe.readout, rows=rows, prep=prep, progress=not args.no_progress,
                  rotation_pooling=recipe.rotation_pooling, signature=recipe.signature,
                  info={"dataset": str(args.dataset), "run": run,
                        "network": args.preset or (str(args.config) if args.config else "sfanav-default"),
                        **recipe.info()})
    if supervision == "odometry":
        _log("fitting the readout to positions learned from the run's odometry (no ground truth); estimates are "
             "metres in the odometry's frame")
        stamps = train.timestamps
        loc = fit_localizer_from_odometry(net, images, odometry, method=args.metric_map,
                                          timestamps=stamps if np.isfinite(stamps).all() else None, **fit_kw)
        if args.metric_map == "pose-graph":
            _log(f"pose graph: {loc.info['loop closures kept']} of {loc.info['loop closures']} loop closures kept, "
                 f"odometry heading drift {loc.info['odometry heading drift (deg per m)']:.3f} deg/m corrected")
        else:
            _log(f"metric map from {loc.info['lines']} straight lines ({loc.info['points on lines']} frames), "
                 f"rms to the odometry on the first {loc.info['rms to odometry on the first line (m)']:.3f} m")
    else:
        loc = fit_localizer(net, images, xy, **fit_kw)
        loc.info["supervision"] = "ground-truth"
    if preprocessor.mirror_used is not None:
        loc.info["mirror"] = list(preprocessor.mirror_used)  # localize and evaluate reuse it
    if np.isfinite(odometry).all():
        try:
            feats = loc.readout_features(loc.features(images),
                                         loc.signatures(images) if loc.n_signature_ else None)
            loc.info["ekf_noise"] = noise_for_localizer(loc, feats, loc.training_positions_, odometry)
            _log("EKF noise for localize --odometry, from the training run's held-out estimates and odometry "
                 "(the fused track nearest the positions the readout was fitted to"
                 + (", learned without ground truth" if supervision == "odometry" else "") + "): "
                 + ", ".join(f"{k} {v:g}" for k, v in loc.info["ekf_noise"].items()))
        except ValueError as exc:
            _log(f"no EKF noise stored (localize --odometry will not be available): {exc}")
    loc.save(out)
    m = loc.train_metrics_
    pool = f" on features pooled over {loc.rotation_pooling_} rotations" if loc.rotation_pooling_ > 1 else ""
    print(f"trained on {len(images)} images in {loc.info['fit_seconds']:.1f} s, readout {loc.describe_readout()}{pool} "
          f"in {loc.info['readout_seconds']:.1f} s (total {time.perf_counter() - t0:.1f} s); "
          f"training-run fit" + (" to the learned positions" if supervision == "odometry" else "")
          + f": MED {m['med']:.3f} m, MAE x {m['mae_x_pct']:.2f} %, y {m['mae_y_pct']:.2f} %")
    print(f"wrote {out}")
    return 0


@command("localize")
def _add_localize(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "localize",
        help="estimate x, y for every image of a dataset, an image folder or a video",
        description=_wrap("Localize every image of INPUT with a trained model: a dataset directory, a folder of "
                    "images (png, jpg, ...; sorted by name) or a video file. Writes a CSV with columns "
                    "frame,x,y (frame: the dataset's frame id, else the image's index; x, y in metres). "
                    "Images are converted as the model was trained: panoramas of another size are resized, "
                    "omnidirectional (mirror) images unwarped with --mirror or an estimated mirror, and "
                    "a message says which."),
        epilog="example:\n  sfanav localize garden.sfa garden --run test --out test.csv",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", metavar="MODEL", help="model file from sfanav train")
    p.add_argument("input", metavar="INPUT", help="dataset directory, image folder or video file")
    p.add_argument("--out", required=True, metavar="CSV", help="CSV file to write (frame,x,y)")
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
    p.add_argument("--batch-size", type=arg.pos_int, default=64, metavar="N", help="images per batch (default 64)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing CSV")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_localize)
    return p


def _run_localize(args: argparse.Namespace) -> int:
    import csv

    import numpy as np

    from .._progress import progress_bar
    from ..data.preprocessing import Preprocessing, Preprocessor
    from ..data.sources import open_images
    from ..localization.error_metrics import med
    from ..odometry.fusion import fuse

    loc = _load_localizer(args.model)
    if args.rotations and loc.rotation_pooling_ > 1:
        raise UsageError(f"{args.model} averages its features over {loc.rotation_pooling_} rotations already "
                          "(rotation pooling): --rotations applies to models without it")
    out = _new_file(args.out, args.overwrite, "CSV")
    src = open_images(args.input, run=args.run_name, camera=args.camera)
    if args.odometry:
        if src.odometry is None or not np.isfinite(src.odometry).all():
            raise UsageError(f"--odometry needs a dataset with odometry (odom_x, odom_y, odom_heading) for every "
                              f"frame; {args.input} has none" + (" for some frames" if src.odometry is not None else ""))
        if "ekf_noise" not in loc.info:
            raise UsageError(f"{args.model} holds no EKF noise (its training run had no odometry): retrain it on a "
                              "run with odometry to use --odometry")
    prep = Preprocessing.of_model(loc)
    conform = Preprocessor(prep, mirror=_mirror_of(args, loc), log=_log)
    _log(f"localizing {src.description} with {args.model} ({prep.describe()} panoramas)")
    bar = progress_bar(not args.no_progress, src.n, "localize")
    preds = []
    for batch in src.batches(args.batch_size):
        preds.append(loc.predict(conform(batch), rotations=args.rotations))
        if bar is not None:
            bar.update(len(batch))
    if bar is not None:
        bar.close()
    if not preds:
        raise UsageError(f"{args.input} has no images (an empty or unreadable video?)")
    xy = np.concatenate(preds)
    frames = src.frames if src.frames is not None else np.arange(len(xy))
    fused = None
    if args.odometry:
        fused = fuse(src.odometry, xy, loc.info["ekf_noise"])
    tmp = out.with_name(out.name + ".part")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "x", "y"] + (["fused_x", "fused_y", "fused_heading"] if fused is not None else []))
        for i, (fr, (x, y)) in enumerate(zip(frames, xy)):
            extra = [f"{v:.4f}" for v in fused[i]] if fused is not None else []
            w.writerow([int(fr), f"{x:.4f}", f"{y:.4f}"] + extra)
    tmp.replace(out)
    msg = f"wrote {len(xy)} positions" + (" and the fused track" if fused is not None else "") + f" to {out}"
    if loc.info.get("supervision") == "odometry":
        msg += " (metres in the training run's odometry frame)"
    elif src.xy is not None and np.isfinite(src.xy).all():
        msg += f" (MED from the dataset's ground truth: {med(xy, src.xy):.3f} m"
        msg += f", fused {med(fused[:, :2], src.xy):.3f} m)" if fused is not None else ")"
    print(msg)
    return 0


@command("evaluate")
def _add_evaluate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "evaluate",
        help="metrics, baselines, plots and a report of a model on a dataset with ground truth",
        description=_wrap("Evaluate a trained model on a run of a dataset with ground truth: MAE per axis (m and % "
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

    from ..data.dataset import Dataset
    from ..data.preprocessing import Preprocessing
    from ..data.sources import load_run, select_run
    from ..localization.evaluation import evaluate, evaluation_rows, metrics_json

    loc = _load_localizer(args.model)
    ds = Dataset(_existing_path(args.dataset, "dataset"))
    runs = set(ds.runs.tolist())
    run = args.run_name if args.run_name is not None else ("test" if "test" in runs else None)
    train_run = args.train_run if args.train_run is not None else ("train" if "train" in runs and run != "train" else None)
    if loc.info.get("supervision") == "odometry" and train_run is None:
        raise UsageError(f"{args.model} was trained without ground truth (it reports in its training run's odometry "
                          "frame): evaluate needs a training run with ground truth (--train-run) to align the frames")
    prep = Preprocessing.of_model(loc)
    test = select_run(ds, run, args.camera)
    mirror = _mirror_of(args, loc)
    images, xy = load_run(test, prep, mirror=mirror, log=_log, progress=not args.no_progress)
    if not np.isfinite(xy).all():
        raise UsageError(f"{args.dataset} lacks ground-truth x, y: evaluation needs them")
    tr_images = tr_xy = None
    if train_run is not None:
        tr = select_run(ds, train_run, args.camera)
        tr_images, tr_xy = load_run(tr, prep, mirror=mirror, log=_log, progress=not args.no_progress)
    out = Path(args.out)
    _log(f"evaluating {args.model} on {len(images)} images" + (f" (run {run})" if run else "")
         + (f", training run {train_run}" if train_run else ""))
    ev = evaluate(loc, images, xy, train_images=tr_images, train_xy=tr_xy, out=out,
                  title=f"sfanav evaluation: {Path(args.model).name} on {args.dataset}",
                  run_baselines=not args.no_baselines, log=_log,
                  text=[f"Model `{args.model}`, dataset `{args.dataset}`, evaluated run: {run or 'all images'}, "
                        f"training run: {train_run or 'none'}."])
    (out / "metrics.json").write_text(json.dumps(metrics_json(ev), indent=2) + "\n")
    rows = evaluation_rows(ev)
    print(_table([("metric", "sfanav")] + [(r["metric"], _fmt(r["sfanav"])) for r in rows]))
    print(f"wrote {ev.report}, {out / 'metrics.json'} and {len(ev.plots)} plots")
    return 0


def _xy_arg(text: str) -> tuple[float, ...]:
    try:
        v = tuple(float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y (metres, comma-separated), got {text!r}") from None
    if len(v) not in (2, 3) or not all(abs(t) < float("inf") for t in v):
        raise argparse.ArgumentTypeError(f"expected X,Y or X,Y,HEADING_DEG (finite numbers), got {text!r}")
    return v


@command("navigate")
def _add_navigate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "navigate",
        help="drive the simulated robot of a dataset's world to a target with a trained model",
        description=_wrap("Closed-loop navigation in the simulated world of DATASET (its world.json) with a "
                    "trained model: the robot's two cameras render the world, the model localizes every image "
                    "in its map, and the robot steers along the geodesic field of the exploration run (the "
                    "positions the model's readout was fitted to, stored in the model file: learned from "
                    "odometry for a model trained without ground truth, so it needs none) until it is within --success-radius of the target. The target is a position "
                    "in the model's map (--target), or an image: a frame of the dataset (--target-frame) or an "
                    "image file (--target-image), where the robot goes where the model places it. Writes "
                    "navigation.json (success, stops, travelled and optimal length, efficiency), path.csv "
                    "(the true path) and trajectory.png under --out."),
        epilog="example:\n  sfanav navigate garden.sfa garden --start=-3,-3 --target 2.5,2 --out nav\n(write --start=X,Y when X is negative)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", metavar="MODEL", help="model file from sfanav train")
    p.add_argument("dataset", metavar="DATASET", help="a simulated dataset (with world.json); its exploration run")
    p.add_argument("--start", type=_xy_arg, required=True, metavar="X,Y[,HEADING]",
                   help="start position in the world (m) and heading (degrees, default 0)")
    goal = p.add_mutually_exclusive_group(required=True)
    goal.add_argument("--target", type=_xy_arg, metavar="X,Y", help="target position in the model's map (m)")
    goal.add_argument("--target-frame", type=arg.nonneg_int, metavar="FRAME",
                      help="target image: this frame id of DATASET")
    goal.add_argument("--target-image", metavar="FILE", help="target image: a panorama file")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--run", dest="run_name", default=None, metavar="RUN",
                   help="the exploration run of DATASET (default: the model's training run, else 'train')")
    p.add_argument("--straight", action="store_true",
                   help="head straight for the target instead of along the exploration run's geodesic field")
    p.add_argument("--max-stops", type=arg.pos_int, default=400, metavar="N", help="stops before giving up (400)")
    p.add_argument("--success-radius", type=float, default=0.5, metavar="M", help="success radius, m (0.5)")
    p.add_argument("--seed", type=arg.nonneg_int, default=0, help="odometry noise seed (default 0)")
    p.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier navigation in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_run_navigate)
    return p


def _run_navigate(args: argparse.Namespace) -> int:
    import csv
    import json
    import math
    from pathlib import Path

    import numpy as np

    from ..data.dataset import Dataset
    from ..data.images import read_image
    from ..data.preprocessing import Preprocessing, Preprocessor
    from ..data.sources import load_run
    from ..localization.error_metrics import align
    from ..localization.recipe import CAMERA_ELEVATION
    from ..navigation.mission import image_goal, navigate
    from ..navigation.plots import plot_trajectories
    from ..sim.cameras import PanoramicCamera
    from ..sim.robot import OdometryNoise, Robot
    from ..sim.world import World

    if not (math.isfinite(args.success_radius) and args.success_radius > 0):
        raise UsageError(f"--success-radius must be a positive number of metres, got {args.success_radius}")
    loc = _load_localizer(args.model)
    ds = Dataset(_existing_path(args.dataset, "dataset"))
    md = ds.metadata if isinstance(ds.metadata, dict) else {}
    if not md.get("world"):
        raise UsageError(f"{args.dataset} has no simulated world (world.json): navigate drives the simulator's "
                          "robot (make one with sfanav simulate)")
    out = Path(args.out)
    names = ("navigation.json", "path.csv", "trajectory.png")
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} exists and is not a directory")
    if any((out / n).exists() for n in names) and not args.overwrite:
        raise UsageError(f"{out} holds an earlier navigation; pass --overwrite or choose another --out")
    world = World.load(ds.root / md["world"])
    prep = Preprocessing.of_model(loc)
    if prep.normalize:
        raise UsageError(f"{args.model} normalizes its images (--normalize): navigate renders raw panoramas; "
                          "train without --normalize")
    cam = md.get("camera") or {}
    camera = PanoramicCamera(prep.width, prep.height,
                             elevation_deg=tuple(cam.get("elevation_deg", CAMERA_ELEVATION)),
                             mount_height=float(cam.get("mount_height", 0.5)), rgb=not prep.gray)
    noise = ((md.get("robot") or {}).get("odometry_noise")) or {}
    robot = Robot.two_cameras(noise=OdometryNoise(**noise))
    run = args.run_name or loc.info.get("run") or "train"
    if run not in set(ds.runs.tolist()):
        raise UsageError(f"{args.dataset} has no run {run!r} (runs: {', '.join(sorted(set(ds.runs.tolist())))}); "
                          "pass --run")
    explore = ds.select(run=run)
    conform = Preprocessor(prep, mirror=_mirror_of(argparse.Namespace(mirror=None), loc), log=_log)
    stored = loc.training_positions_
    if stored is not None and len(stored) == len(explore):  # the run the model was trained on: its own map
        exploration, xy_true = stored, explore.poses[:, :2]  # no need to read its images
        field_from = "the positions its readout was fitted to"
    else:
        X, xy_true = load_run(explore, prep, preprocessor=conform, progress=not args.no_progress)
        exploration, field_from = loc.predict(X), "the model's estimates of its images"
    odometry_frame = loc.info.get("supervision") == "odometry"
    to_world = None
    if odometry_frame and np.isfinite(xy_true).all():
        to_world = align(exploration, xy_true)  # evaluation only: where success is measured
        _log("the model was trained without ground truth: its map is the training run's odometry frame; for "
             f"evaluation only, targets are moved into the world by the rigid fit on the training run "
             f"(rms {to_world.rmse:.3f} m)")
    world_goal = None
    if args.target is not None:
        if len(args.target) != 2:
            raise UsageError("--target is X,Y (no heading)")
        map_goal = np.array(args.target, float)
        what = f"position ({map_goal[0]:.2f}, {map_goal[1]:.2f}) of the map"
    elif args.target_frame is not None:
        hit = np.flatnonzero(ds.frames == args.target_frame)
        if len(hit) == 0:
            raise UsageError(f"{args.dataset} has no frame {args.target_frame}")
        sub = ds.subset(hit[:1])
        Xg, xyg = load_run(sub, prep, preprocessor=conform, progress=False)
        map_goal = image_goal(loc, Xg[0])
        if np.isfinite(xyg).all():
            world_goal = xyg[0]
        what = f"the image of frame {args.target_frame}"
    else:
        img = read_image(_existing_path(args.target_image, "target image"), gray=prep.gray)
        map_goal = image_goal(loc, conform(img[None])[0])
        what = f"the image {args.target_image}"
    if world_goal is None:
        world_goal = to_world.apply(map_goal[None])[0] if to_world is not None else map_goal
    start = np.array(args.start[:2], float)
    heading = math.radians(args.start[2]) if len(args.start) == 3 else 0.0
    _log(f"navigating from ({start[0]:.2f}, {start[1]:.2f}) to {what}: map ({map_goal[0]:.2f}, {map_goal[1]:.2f}), "
         f"world ({world_goal[0]:.2f}, {world_goal[1]:.2f}); "
         + ("straight at the target" if args.straight else f"along the geodesic field of run {run!r} ({len(exploration)} frames, {field_from})"))
    mission = navigate(loc, world, camera, start, map_goal, exploration=exploration, heading=heading,
                       world_goal=world_goal, robot=robot, geodesic=not args.straight,
                       success_radius=args.success_radius, max_iterations=args.max_stops, seed=args.seed)
    out.mkdir(parents=True, exist_ok=True)
    r = mission.result
    tmp = out / "path.csv.part"
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["stop", "x", "y"])
        for i, (x, y) in enumerate(r.path):
            w.writerow([i, f"{x:.4f}", f"{y:.4f}"])
    tmp.replace(out / "path.csv")
    title = ("reached" if r.success else r.reason) + (f", efficiency {mission.efficiency:.2f}" if r.success else "")
    plot_trajectories([r], out / "trajectory.png", world=world, cols=1, titles=[title],
                      optimal=None if mission.optimal_path is None else [mission.optimal_path],
                      title=f"sfanav navigate: {Path(args.model).name}")
    summary = {"model": str(args.model), "dataset": str(args.dataset), "exploration run": run,
               "supervision": loc.info.get("supervision", "ground-truth"), "target": what,
               "geodesic field": not args.straight, **mission.to_dict()}
    tmp = out / "navigation.json.part"
    tmp.write_text(json.dumps(summary, indent=2) + "\n")
    tmp.replace(out / "navigation.json")
    print(f"{'reached' if r.success else 'did not reach'} the target after {r.iterations} stops, "
          f"{r.travelled:.2f} m travelled (optimal {mission.optimal:.2f} m"
          + (f", efficiency {mission.efficiency:.2f})" if r.success else f"; {r.reason})")
          + f"; ends {np.hypot(*(r.path[-1] - world_goal)):.2f} m from the target")
    print(f"wrote {out / 'navigation.json'}, {out / 'path.csv'}, {out / 'trajectory.png'}")
    return 0


@command("demo")
def _add_demo(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from .demo import DEMO_NETWORK

    p = sub.add_parser(
        "demo",
        help="simulate a garden, train without ground truth, localize a test run and report (about 2 minutes)",
        description=_wrap("The whole pipeline on the built-in simulator, as a robot has it (images and wheel "
                    "odometry, no ground truth): generates the 'demo' garden (8x8 m, a grid exploration run "
                    f"and a test walk), trains the {DEMO_NETWORK} network under simulated rotation, learns the "
                    "exploration run's positions from its images and odometry (pose graph), fits the readout "
                    "to them, localizes the test walk from single images and fused with its odometry (EKF), "
                    "and prints MAE, MED and eta beside the thesis's section 5.1.1 figures, the two "
                    "baselines, the same network with its readout on ground truth and the thesis's "
                    "configuration. Writes the dataset, the models, the estimates (CSV), plots and a "
                    "Markdown report under --out. Ground truth is used only to evaluate and for the "
                    "reference rows."),
        epilog="outputs: DIR/dataset, DIR/model.sfa (no ground truth), DIR/model-ground-truth.sfa, "
               "DIR/test-estimates.csv, DIR/report.md, DIR/*.png, DIR/demo.json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", default="sfanav-demo", metavar="DIR", help="output directory (default sfanav-demo)")
    p.add_argument("--seed", type=arg.nonneg_int, default=0, help="seed of the garden and the runs (default 0)")
    p.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier demo in --out")
    p.add_argument("--quick", action="store_true",
                   help="a seconds-long smoke run (tiny images, few frames, a small network); not meaningful")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(run=_run_demo)
    return p


def _run_demo(args: argparse.Namespace) -> int:
    from .demo import run_demo

    result = run_demo(args.out, seed=args.seed, overwrite=args.overwrite, quick=args.quick,
                      progress=not args.no_progress, log=_log)
    print(result.table())
    if result.notes:
        print()
        print(result.notes)
    return 0


@command("experiment")
def _add_experiment(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from .. import experiments

    p = sub.add_parser(
        "experiment",
        help="rerun one of the thesis's experiments on the simulator (--list lists them)",
        description=_wrap("Rerun one of the thesis's experiments on the built-in simulator: simulates the scene, "
                    "trains, evaluates, prints a table of each metric with the thesis's value beside "
                    "sfanav's, and writes the same as JSON ({\"experiment\": NAME, \"rows\": [{\"metric\", "
                    "\"thesis\", \"sfanav\"}, ...]}) plus plots under --out. Localization experiments also "
                    "run the perfect-memory and Fourier-signature baselines on the same images."),
        epilog="experiments:\n" + "\n".join(f"  {n:<8} {experiments.get(n).title}" for n in experiments.names())
               + "\n\nexample:\n  sfanav experiment --list\n  sfanav experiment 5.1.1 --out results",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("name", nargs="?", metavar="NAME", help="experiment name (see --list)")
    p.add_argument("--list", action="store_true", help="list the experiments and exit")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output directory (default sfanav-results/NAME); writes NAME.json and plots")
    p.add_argument("--quick", action="store_true",
                   help="a seconds-long smoke run (tiny images and grids, few frames); numbers not meaningful")
    p.add_argument("--seed", type=arg.nonneg_int, default=0, help="seed of scenes and runs (default 0)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(run=_run_experiment)
    return p


def _run_experiment(args: argparse.Namespace) -> int:
    import time
    from pathlib import Path

    from .. import experiments

    if args.list:
        if args.name:
            raise UsageError("give either NAME or --list")
        names = experiments.names()
        width = max((len(n) for n in names), default=0)
        for n in names:
            print(f"{n:<{width}}  {experiments.get(n).title}")
        return 0
    if not args.name:
        raise UsageError("give an experiment NAME (sfanav experiment --list shows them)")
    exp = experiments.get(args.name)  # ValueError with the known names
    out = Path(args.out) if args.out else Path("sfanav-results") / args.name
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file")
    _log(f"experiment {exp.name}: {exp.title}" + (" (quick smoke run)" if args.quick else ""))
    t0 = time.perf_counter()
    result = experiments.run(exp.name, out, quick=args.quick, seed=args.seed, progress=not args.no_progress)
    print(result.table())
    if result.notes:
        print()
        print(result.notes)
    print(f"\nwrote {out / (exp.name + '.json')} and {len(result.plots)} plots in {time.perf_counter() - t0:.0f} s")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (no usage dump)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="sfanav",
        description="Localization and navigation from a panoramic camera with hierarchical Slow Feature Analysis.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"sfanav {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for add in _COMMANDS.values():
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``sfanav`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, on_sigterm)
    else:  # pragma: no cover - main() called from a worker thread
        previous = None
    try:
        return int(args.run(args) or 0)
    except Exception as exc:
        # anything else is a bug: its traceback is the report
        if not is_input_error(exc):
            raise
        if os.environ.get("SFANAV_DEBUG") and not isinstance(exc, UsageError):
            raise  # the traceback, for bug reports
        parser.exit(EXIT_USAGE, f"sfanav {args.command}: error: {one_line(exc)}\n")
    except KeyboardInterrupt:
        parser.exit(130, "interrupted\n")
    except Terminated:
        parser.exit(143, "terminated\n")
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
