"""What ``sfanav train --landmarks``, ``sfanav localize`` and ``sfanav
evaluate`` do with landmark models (thesis 5.4,
:class:`sfanav.landmarks.LandmarkLocalizer`): the commands' own modules
parse the arguments and hand over here."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from ..common import existing_path, log
from ..failures import UsageError

if TYPE_CHECKING:
    from pathlib import Path

#: sfanav train options that belong to whole-image models: (dest, value when not given, flag)
WHOLE_IMAGE_OPTIONS = (("step", 5, "--step"), ("window", 1.0, "--window"), ("rows", None, "--rows"),
                       ("signature", None, "--signature"), ("rotation_pooling", None, "--rotation-pooling"),
                       ("loop_closures", "auto", "--loop-closures"), ("closure_weights", "uniform", "--closure-weights"),
                       ("normalize", False, "--normalize"), ("metric_map", "pose-graph", "--metric-map"))


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    """The ``sfanav train`` options of landmark models."""
    g = p.add_argument_group("landmark models (thesis 5.4; omnidirectional images with ArUco markers)")
    g.add_argument("--landmarks", default=None, metavar="IDS",
                   help="train a landmark model instead: one network per ArUco marker (comma-separated ids, e.g. "
                        "136,144) on the marker's views cut from the omnidirectional images and aligned by its polar "
                        "angle (no simulated rotation), and a quadratic readout of their stacked 8 slowest outputs "
                        "with a found-flag per marker. Network: --preset/--config (default landmark-120, 120x120 RGB "
                        "views)")
    g.add_argument("--view-size", type=_pos_int, default=120, metavar="PX",
                   help="side of a marker view in pixels (default 120; the network's input must match)")
    g.add_argument("--margin", type=float, default=50.0, metavar="PX",
                   help="pixels added to every side of a marker's bounding box (default 50)")
    g.add_argument("--dictionary", default="DICT_ARUCO_ORIGINAL", metavar="NAME",
                   help="cv2.aruco dictionary of the markers (default DICT_ARUCO_ORIGINAL)")


def _pos_int(text: str) -> int:
    from .. import arguments

    return arguments.pos_int(text)


def _mirror(text: Any) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
    """--mirror CX,CY,INNER,OUTER as the extractor's centre and ring."""
    if text is None:
        return None, None
    from ...data.preprocessing import Preprocessing, Preprocessor

    cx, cy, r0, r1 = Preprocessor(Preprocessing(8, 8, False), mirror=text).mirror  # validates
    return (cx, cy), (r0, r1)


def train_landmarks(args: argparse.Namespace, out: "Path") -> int:
    """``sfanav train --landmarks IDS``: a landmark model from one run."""
    import time

    import numpy as np

    from ..._checks import check_marker_ids
    from ...data.dataset import Dataset
    from ...data.sources import select_run
    from ...landmarks.model import LandmarkLocalizer, N_OUTPUTS, NETWORK_PRESET
    from ...landmarks.views import ViewExtractor
    from ...sfa.config import read_config_file

    t0 = time.perf_counter()
    for dest, unset, flag in WHOLE_IMAGE_OPTIONS:
        if getattr(args, dest) != unset:
            raise UsageError(f"{flag} applies to whole-image models, not to --landmarks")
    if args.readout not in (None, "quadratic"):
        raise UsageError("--landmarks uses the quadratic readout (the thesis's); --readout auto applies to "
                         "whole-image models")
    if args.supervision == "odometry":
        raise UsageError("--landmarks needs ground-truth positions; --supervision odometry applies to whole-image "
                         "models")
    try:
        ids = check_marker_ids(args.landmarks, "--landmarks")
    except (TypeError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    ds = Dataset(existing_path(args.dataset, "dataset"))
    run = args.run_name
    if run is None and "train" in set(ds.runs.tolist()):
        run = "train"
    train = select_run(ds, run, args.camera)
    xy = train.poses[:, :2].copy()
    if not np.isfinite(xy).all():
        raise UsageError(f"{args.dataset} lacks ground-truth x, y for some training images: --landmarks needs them")
    center, ring = _mirror(args.mirror)
    extractor = ViewExtractor(ids, size=args.view_size, margin=args.margin, dictionary=args.dictionary,
                              center=center, ring=ring)
    if args.config is not None:
        network: Any = read_config_file(existing_path(args.config, "network config"))
    else:
        network = args.preset or NETWORK_PRESET
    if args.precision:
        from ...sfa.config import preset_config

        network = dict(preset_config(network) if isinstance(network, str) else network)
        network["network"] = {**network.get("network", {}), "precision": args.precision}
    loc = LandmarkLocalizer(extractor, network, n_outputs=args.n_outputs or N_OUTPUTS)
    loc.new_network()  # a network that does not fit the views fails here, before the images are read
    log(f"landmark model: markers {', '.join(map(str, ids))} in {len(train)} images of {args.dataset}"
        + (f" (run {run})" if run else "") + f"; {extractor.size}x{extractor.size} views, margin "
        f"{extractor.margin:g} px; network {args.preset or args.config or NETWORK_PRESET}")
    views = extractor.transform(train.images(batch_size=32), progress=not args.no_progress)
    rates = views.detection_rate()
    found = ", ".join(f"{m} in {100 * r:.1f} %" for m, r in zip(ids, rates))
    never = [m for m, r in zip(ids, rates) if r == 0]
    if never:
        raise UsageError(f"marker{'s' if len(never) > 1 else ''} {', '.join(map(str, never))} never found in the "
                         f"{len(train)} training images of {args.dataset} (found: {found}; dictionary "
                         f"{extractor.dictionary})")
    log(f"markers found: {found}")
    loc.fit_views(views, xy, progress=not args.no_progress)
    h, w = train.image(0).shape[:2]
    loc.info.update({"dataset": str(args.dataset), "run": run, "image_size": [int(w), int(h)],
                     "network": str(args.config) if args.config else (args.preset or NETWORK_PRESET),
                     "supervision": "ground-truth"})
    loc.save(out)
    m = loc.train_metrics_
    print(f"trained {len(ids)} marker networks on {len(train)} images in {loc.info['fit_seconds']:.1f} s (total "
          f"{time.perf_counter() - t0:.1f} s); markers found: {found}; training-run fit of the stacked readout: "
          f"MED {m['med']:.3f} m")
    print(f"wrote {out}")
    return 0


def is_landmark_model(model: Any) -> bool:
    from ...landmarks.model import LandmarkLocalizer

    return isinstance(model, LandmarkLocalizer)


def check_image_size(loc: Any, shape: tuple[int, ...], what: str) -> None:
    """A UsageError if images of ``shape`` (H, W, ...) are not the size the
    landmark model was trained on (its views' scale depends on it)."""
    size = (loc.info or {}).get("image_size")
    if size is not None and (shape[1], shape[0]) != tuple(size):
        raise UsageError(f"{what} are {shape[1]}x{shape[0]} px, but the landmark model was trained on "
                         f"{size[0]}x{size[1]} omnidirectional images")


def localize_landmarks(args: argparse.Namespace, loc: Any, out: "Path") -> int:
    """``sfanav localize`` with a landmark model: frame, x, y and one
    found-flag column per marker."""
    import numpy as np

    from ..._files import write_csv_atomic
    from ..._progress import progress_bar
    from ...data.sources import open_images
    from ...landmarks.views import MarkerViews
    from ...localization.error_metrics import med

    if args.rotations or args.odometry or args.mirror is not None:
        flag = "--rotations" if args.rotations else "--odometry" if args.odometry else "--mirror"
        raise UsageError(f"{flag} applies to whole-image models; {args.model} is a landmark model")
    src = open_images(args.input, run=args.run_name, camera=args.camera)
    log(f"localizing {src.description} with the landmark model {args.model} (markers "
        f"{', '.join(map(str, loc.ids))})")
    bar = progress_bar(not args.no_progress, src.n, "localize")
    parts = []
    for batch in src.batches(args.batch_size):
        check_image_size(loc, batch.shape[1:], "the images")
        parts.append(loc.extractor.transform(batch))
        if bar is not None:
            bar.update(len(batch))
    if bar is not None:
        bar.close()
    if not parts:
        raise UsageError(f"{args.input} has no images (an empty or unreadable video?)")
    views = MarkerViews.concatenate(parts)
    xy = loc.predict_views(views)
    frames = src.frames if src.frames is not None else np.arange(len(xy))
    write_csv_atomic(out, ["frame", "x", "y"] + [f"found_{m}" for m in loc.ids],
                     ([int(fr), f"{x:.4f}", f"{y:.4f}"] + [int(v) for v in views.found[i]]
                      for i, (fr, (x, y)) in enumerate(zip(frames, xy))))
    found = ", ".join(f"{m} in {100 * r:.1f} %" for m, r in zip(loc.ids, views.detection_rate()))
    msg = f"wrote {len(xy)} positions to {out} (markers found: {found}"
    if src.xy is not None and np.isfinite(src.xy).all():
        msg += f"; MED from the dataset's ground truth: {med(xy, src.xy):.3f} m"
    print(msg + ")")
    return 0


def _read(loc: Any, ds: Any, prep: Any, mirror: Any, progress: bool) -> tuple[Any, Any, Any]:
    """One pass over a run: its marker views, its panoramas for the peers
    (or None without ``prep``) and its positions."""
    import numpy as np

    from ..._progress import progress_bar
    from ...data.preprocessing import Preprocessor
    from ...landmarks.views import MarkerViews

    conform = None if prep is None else Preprocessor(prep, mirror=mirror, log=log)
    parts, panos = [], []
    bar = progress_bar(progress, len(ds), "marker views")
    for batch in ds.images(batch_size=32):
        check_image_size(loc, batch.shape[1:], f"the images of {ds.root}")
        parts.append(loc.extractor.transform(batch))
        if conform is not None:
            panos.append(conform(batch))
        if bar is not None:
            bar.update(len(batch))
    if bar is not None:
        bar.close()
    if not parts:
        raise UsageError(f"no images in {ds.root}")
    return MarkerViews.concatenate(parts), (np.concatenate(panos) if panos else None), ds.poses[:, :2].copy()


def evaluate_landmarks_command(args: argparse.Namespace, loc: Any) -> int:
    """``sfanav evaluate`` with a landmark model."""
    import json
    from pathlib import Path

    import numpy as np

    from ...data.dataset import Dataset
    from ...data.preprocessing import Preprocessing
    from ...data.sources import select_run
    from ...landmarks.evaluation import evaluate_landmarks, landmark_rows
    from ...localization.evaluation import metrics_json
    from ..common import fmt, table

    ds = Dataset(existing_path(args.dataset, "dataset"))
    runs = set(ds.runs.tolist())
    run = args.run_name if args.run_name is not None else ("test" if "test" in runs else None)
    train_run = args.train_run if args.train_run is not None else ("train" if "train" in runs and run != "train" else None)
    peers = not args.no_baselines and train_run is not None
    prep = Preprocessing(600, 60, False) if peers else None  # the peers read 600x60 panoramas of the same frames
    V_te, P_te, xy = _read(loc, select_run(ds, run, args.camera), prep, args.mirror, not args.no_progress)
    if not np.isfinite(xy).all():
        raise UsageError(f"{args.dataset} lacks ground-truth x, y: evaluation needs them")
    V_tr = P_tr = xy_tr = None
    if train_run is not None:
        V_tr, P_tr, xy_tr = _read(loc, select_run(ds, train_run, args.camera), prep, args.mirror,
                                  not args.no_progress)
    out = Path(args.out)
    log(f"evaluating the landmark model {args.model} on {len(xy)} images" + (f" (run {run})" if run else "")
        + (f", training run {train_run}" if train_run else ""))
    ev = evaluate_landmarks(loc, V_te, xy, train_views=V_tr, train_xy=xy_tr,
                            panoramas=(P_tr, P_te) if peers else None, out=out, log=log,
                            title=f"sfanav evaluation: {Path(args.model).name} on {args.dataset}",
                            text=[f"Landmark model `{args.model}`, dataset `{args.dataset}`, evaluated run: "
                                  f"{run or 'all images'}, training run: {train_run or 'none'}."])
    metrics = metrics_json(ev)
    metrics["markers"] = {str(m): {"detection_rate": e["detection rate"], "n": e["n"],
                                   "train_detection_rate": e["train detection rate"],
                                   "med": None if e["metrics"] is None else e["metrics"]["med"]}
                          for m, e in ev.markers.items()}
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2, default=float) + "\n")
    rows = landmark_rows(ev)
    print(table([("metric", "sfanav")] + [(r["metric"], fmt(r["sfanav"])) for r in rows]))
    print(f"wrote {ev.report}, {out / 'metrics.json'} and {len(ev.plots)} plots")
    return 0
