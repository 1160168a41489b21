"""``sfanav navigate``: closed-loop navigation of the simulated robot with a trained model."""

from __future__ import annotations

import argparse

from .. import arguments as arg
from ..common import existing_path, load_localizer, log, mirror_of, wrap
from ..failures import UsageError
from ..registry import command


@command("navigate")
def _add_navigate(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "navigate",
        help="drive the simulated robot of a dataset's world to a target with a trained model",
        description=wrap("Closed-loop navigation in the simulated world of DATASET (its world.json) with a "
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
    p.add_argument("--start", type=arg.xy, required=True, metavar="X,Y[,HEADING]",
                   help="start position in the world (m) and heading (degrees, default 0)")
    goal = p.add_mutually_exclusive_group(required=True)
    goal.add_argument("--target", type=arg.xy, metavar="X,Y", help="target position in the model's map (m)")
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
    import json
    import math
    from pathlib import Path

    import numpy as np

    from ..._files import write_csv_atomic, write_text_atomic
    from ...data.dataset import Dataset
    from ...data.images import read_image
    from ...data.preprocessing import Preprocessing, Preprocessor
    from ...data.sources import load_run
    from ...localization.error_metrics import align
    from ...localization.recipe import CAMERA_ELEVATION
    from ...navigation.mission import check_goal_in_map, image_goal, navigate
    from ...navigation.plots import plot_trajectories
    from ...sim.cameras import PanoramicCamera
    from ...sim.robot import OdometryNoise, Robot
    from ...sim.world import World

    if not (math.isfinite(args.success_radius) and args.success_radius > 0):
        raise UsageError(f"--success-radius must be a positive number of metres, got {args.success_radius}")
    loc = load_localizer(args.model)
    ds = Dataset(existing_path(args.dataset, "dataset"))
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
    conform = Preprocessor(prep, mirror=mirror_of(argparse.Namespace(mirror=None), loc), log=log)
    stored = loc.training_positions_
    if stored is not None and len(stored) == len(explore):  # the run the model was trained on: its own map
        exploration, xy_true = stored, explore.poses[:, :2]  # no need to read its images
        field_from = "the positions its readout was fitted to"
    else:
        X, xy_true = load_run(explore, prep, preprocessor=conform, progress=not args.no_progress)
        exploration, field_from = loc.predict(X), "the model's estimates of its images"
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
        img = read_image(existing_path(args.target_image, "target image"), gray=prep.gray)
        map_goal = image_goal(loc, conform(img[None])[0])
        what = f"the image {args.target_image}"
    try:  # before anything else is said or done: a goal far out would overflow when moved into the world
        check_goal_in_map(map_goal, exploration, "--target" if args.target is not None else f"{what}, placed at")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    odometry_frame = loc.info.get("supervision") == "odometry"
    to_world = None
    if odometry_frame and np.isfinite(xy_true).all():
        to_world = align(exploration, xy_true)  # evaluation only: where success is measured
        log("the model was trained without ground truth: its map is the training run's odometry frame; for "
             f"evaluation only, targets are moved into the world by the rigid fit on the training run "
             f"(rms {to_world.rmse:.3f} m)")
    if world_goal is None:
        world_goal = to_world.apply(map_goal[None])[0] if to_world is not None else map_goal
    start = np.array(args.start[:2], float)
    heading = math.radians(args.start[2]) if len(args.start) == 3 else 0.0
    log(f"navigating from ({start[0]:.2f}, {start[1]:.2f}) to {what}: map ({map_goal[0]:.2f}, {map_goal[1]:.2f}), "
         f"world ({world_goal[0]:.2f}, {world_goal[1]:.2f}); "
         + ("straight at the target" if args.straight else f"along the geodesic field of run {run!r} ({len(exploration)} frames, {field_from})"))
    mission = navigate(loc, world, camera, start, map_goal, exploration=exploration, heading=heading,
                       world_goal=world_goal, robot=robot, geodesic=not args.straight,
                       success_radius=args.success_radius, max_iterations=args.max_stops, seed=args.seed)
    out.mkdir(parents=True, exist_ok=True)
    r = mission.result
    write_csv_atomic(out / "path.csv", ["stop", "x", "y"], ([i, f"{x:.4f}", f"{y:.4f}"] for i, (x, y) in enumerate(r.path)))
    title = ("reached" if r.success else r.reason) + (f", efficiency {mission.efficiency:.2f}" if r.success else "")
    plot_trajectories([r], out / "trajectory.png", world=world, cols=1, titles=[title],
                      optimal=None if mission.optimal_path is None else [mission.optimal_path],
                      title=f"sfanav navigate: {Path(args.model).name}")
    summary = {"model": str(args.model), "dataset": str(args.dataset), "exploration run": run,
               "supervision": loc.info.get("supervision", "ground-truth"), "target": what,
               "geodesic field": not args.straight, **mission.to_dict()}
    write_text_atomic(out / "navigation.json", json.dumps(summary, indent=2) + "\n")
    print(f"{'reached' if r.success else 'did not reach'} the target after {r.iterations} stops, "
          f"{r.travelled:.2f} m travelled (optimal {mission.optimal:.2f} m"
          + (f", efficiency {mission.efficiency:.2f})" if r.success else f"; {r.reason})")
          + f"; ends {np.hypot(*(r.path[-1] - world_goal)):.2f} m from the target")
    print(f"wrote {out / 'navigation.json'}, {out / 'path.csv'}, {out / 'trajectory.png'}")
    return 0
