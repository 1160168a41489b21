"""``sfanav demo``: the whole pipeline on the built-in simulator, the way a
robot has it: images and wheel odometry, no ground truth.

Generates the ``demo`` garden (8x8 m: a grid exploration run and a test
walk, both with odometry), trains the sfanav default network under
simulated rotation on the exploration run's images, learns the run's
positions from its images and odometry (the pose graph,
:func:`sfanav.odometry.learn_positions`), fits the readout to them, localizes
the test walk from single images and fused with its odometry (EKF, noise
chosen on the training run), and writes the dataset, the models, the
estimates, plots and a report. Ground truth is used only to evaluate, and
for two reference rows: the same network with its readout fitted to ground
truth, and the thesis's configuration (Table 5.1 network, quadratic
regression on 8 outputs). The printed table puts the thesis's section 5.1.1
figures (its simulator experiment) beside the demo's.
"""

from __future__ import annotations

import csv
import json
import shutil
import time
from pathlib import Path
from typing import Any

from .._progress import Log, stderr_log
from ..data.camera_gamma import CameraGamma, predict_corrected
from ..data.corruptions import corrupt
from ..data.preprocessing import Preprocessing, Preprocessor
from ..data.sources import load_run
from ..experiments import ExperimentResult
from ..localization.evaluation import evaluate, evaluation_rows
from ..localization.training import augmented_features, fit_localizer
from ..odometry.streaming import StreamingLocalizer
from ..sfa.network import Network, Rotation

DEMO_NETWORK = "sfanav-default"
"""Network preset of the demo (350x40 RGB input; the garden is rendered at 600x60 and resized)."""

JPEG_TEST = "jpeg-90"
"""The corruption of the demo's JPEG rows: the test walk as a ROS camera's image_transport sends it."""
GAMMA_TEST = "gamma-1.4"
"""The camera gamma of the demo's rows with and without the camera's gamma taken out (``sfanav localize``'s default
and ``--no-camera-gamma``)."""

THESIS_NETWORK = "thesis-5.1"
"""Network preset of the demo's thesis-configuration row (Table 5.1, 350x40 RGB)."""


THESIS_5_1_1: dict[str, Any] = {
    "MAE x (%) (random splits)": 1.83,
    "MAE y (%) (random splits)": 1.68,
    "max eta_phi (outputs 1-8)": 0.17,
    "eta_phi s1": 0.00,
    "eta_phi s8": 0.17,
    "min eta_p (outputs 1-8)": 1.0,
    "best n (random splits)": 8,
}
"""The thesis's section 5.1.1 figures (simulator: 30x30 grid, Table 5.1 network), by row name."""


_OUTPUTS = ("dataset", "demo.rrd", "model.sfa", "model-ground-truth.sfa", "test-estimates.csv", "report.md", "demo.json", "firing_maps.png",
            "trajectory.png", "error_vs_n.png", "eta.png")


def _tiny_network() -> Network:
    return Network({
        "input": {"width": 60, "height": 8, "channels": 3},
        "network": {"precision": "mixed"},
        "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 8}, {"rf": "full", "out": 8}],
    })


def _compact_rows(label: str, m: dict[str, float]) -> list[dict[str, Any]]:
    return [{"metric": f"MED (m) [{label}]", "thesis": None, "sfanav": m["med"]},
            {"metric": f"MAE x (%) [{label}]", "thesis": None, "sfanav": m["mae_x_pct"]},
            {"metric": f"MAE y (%) [{label}]", "thesis": None, "sfanav": m["mae_y_pct"]}]


def _write_recording(path: Path, loc: Any, world: Any, estimates: list[Any], images: Any, xy_true: Any,
                     log: Log) -> Path | None:
    """The test walk as a Rerun recording (``path``, .rrd): its images, the
    single-image estimates, the fused track with 2-sigma ellipses, the
    learned map and the ground truth, all moved into the world frame by the
    evaluation's rigid alignment ``world``. None (and a log line) without
    rerun-sdk."""
    import types

    import numpy as np

    try:
        from ..odometry.live_view import RerunView

        view = RerunView(path)
    except ImportError as exc:
        log(f"no Rerun recording: {exc}")
        return None
    R = world.rotation
    turn = float(np.arctan2(R[1, 0], R[0, 0]))
    view.log_map(world.apply(loc.training_positions_))
    for k, (e, image) in enumerate(zip(estimates, images)):
        pose = np.r_[world.apply(e.pose[None, :2])[0], e.pose[2] + turn]
        cov = np.array(e.covariance, float)
        cov[:2, :2] = R @ cov[:2, :2] @ R.T
        cov[:2, 2] = R @ cov[:2, 2]
        cov[2, :2] = cov[:2, 2]
        view.log(types.SimpleNamespace(stamp_ns=e.stamp_ns, estimate=world.apply(e.estimate[None])[0], pose=pose,
                                       covariance=cov), frame=k, image=image)
        view.log_truth(xy_true[k], stamp_ns=e.stamp_ns, frame=k)
    view.close()
    return path


def run_demo(out: str | Path = "sfanav-demo", *, seed: int = 0, overwrite: bool = False, quick: bool = False,
             progress: bool = True, log: Log = stderr_log) -> ExperimentResult:
    """Runs the demo into ``out`` and returns its table (rows with the
    thesis's 5.1.1 values where it has one). ``quick``: a seconds-long smoke
    run on tiny images with a small network (for tests)."""
    import numpy as np

    from .. import sim
    from ..localization import baselines
    from ..localization.error_metrics import align, localization_metrics
    from ..localization.evaluation import coordinate_range
    from ..localization.recipe import CAMERA_ELEVATION, default_network, recipe_for
    from ..odometry.fusion import fuse_images
    from ..pipeline import ROTATION_STEP, describe_closures, train_localizer

    t_start = time.perf_counter()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} exists and is not a directory")
    clash = [name for name in _OUTPUTS if (out / name).exists()]
    if clash and not overwrite:
        raise FileExistsError(f"{out} holds an earlier demo ({', '.join(clash[:3])}, ...); pass --overwrite "
                              "or choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    if overwrite and (out / "dataset").exists():
        shutil.rmtree(out / "dataset")
    timings: dict[str, float] = {}

    # 1. simulate
    t0 = time.perf_counter()
    camera = sim.PanoramicCamera(60, 8) if quick else None
    ds = sim.simulate("demo", out / "dataset", seed, max_frames=80 if quick else None, camera=camera,
                      progress=progress)
    timings["simulate"] = time.perf_counter() - t0
    log(f"simulated {len(ds)} images in {timings['simulate']:.1f} s")

    # 2. train without ground truth: the network on the images, the positions from images and odometry
    t0 = time.perf_counter()
    net = _tiny_network() if quick else default_network()
    recipe = recipe_for(rows="all") if quick else recipe_for()  # the tiny network's 8-row panoramas: every row
    elevation = tuple(ds.metadata["camera"].get("elevation_deg", CAMERA_ELEVATION))
    prep = Preprocessing.for_network(net)
    train, test = ds.select(run="train"), ds.select(run="test")
    X_train, xy_train = load_run(train, prep, log=log)
    X_test, xy_test = load_run(test, prep, log=log)
    odo_train, odo_test = train.odometry, test.odometry
    # the product's training, exactly as sfanav train runs it: no ground truth (only the images and odometry)
    loc = train_localizer(X_train, odometry=odo_train, supervision="odometry", network=net, recipe=recipe,
                          camera_elevation=elevation, prep=prep, progress=progress, log=log,
                          info={"dataset": str(out / "dataset"), "run": "train",
                                "network": "tiny" if quick else DEMO_NETWORK})
    rotation = Rotation(step=ROTATION_STEP)
    timings["train"] = time.perf_counter() - t0
    log(f"trained on {len(X_train)} images and their odometry in {timings['train']:.1f} s (network fit "
        f"{loc.info['fit_seconds']:.1f} s, EKF noise chosen on the training run; pose graph: "
        f"{loc.info['loop closures kept']} loop closures)")
    loc.save(out / "model.sfa")

    # 3. localize the test walk as the robot does: image by image with its odometry (the streaming localizer,
    # what sfanav localize --odometry and the ROS node run): single-image estimates and the fused track
    t0 = time.perf_counter()
    live = StreamingLocalizer(loc, loc.info["ekf_noise"], log=log)
    stamps = ([int(v) for v in test.stamps_ns] if test.stamps_ns is not None
              else [int(round(1e9 * t)) for t in test.timestamps])
    estimates = []
    for k in range(len(X_test)):
        estimates += live.push_image(stamps[k], X_test[k])
        estimates += live.push_odometry(stamps[k], odo_test[k])
    estimates += live.flush()
    if len(estimates) != len(X_test) or any(e.pose is None for e in estimates):
        raise RuntimeError(f"the streaming localizer emitted {len(estimates)} fused poses for {len(X_test)} "
                           f"images (dropped: {dict(live.dropped_)}; {live.init_error_ or ''})")
    xy_est = np.array([e.estimate for e in estimates])
    fused = np.array([e.pose for e in estimates])
    with open(out / "test-estimates.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "x", "y", "fused_x", "fused_y", "fused_heading"])
        for fr, (x, y), (fx, fy, fh) in zip(test.frames, xy_est, fused):
            w.writerow([int(fr), f"{x:.4f}", f"{y:.4f}", f"{fx:.4f}", f"{fy:.4f}", f"{fh:.5f}"])
    timings["localize"] = time.perf_counter() - t0

    # 4. evaluate (ground truth from here on, for evaluation and the reference rows only)
    t0 = time.perf_counter()
    ev = evaluate(loc, X_test, xy_test, train_images=X_train, train_xy=xy_train, out=out,
                  title="sfanav demo (trained without ground truth)", log=log, report=False)
    tag = " [no ground truth]"
    rows = [dict(r, metric=r["metric"][: -len(tag)]) if r.get("baseline") else r  # the peers store ground truth
            for r in evaluation_rows(ev, thesis=THESIS_5_1_1, suffix=tag)]
    world = align(loc.predict(X_train), xy_train)  # the frame alignment evaluate used
    crange = coordinate_range(xy_test)
    m_fused = localization_metrics(world.apply(fused[:, :2]), xy_test, coordinate_range=crange)
    rows += _compact_rows("no ground truth, fused with odometry", m_fused)
    # the test walk as a ROS robot's image_transport sends it: JPEG at quality 90, compressed at the camera's size
    cam = ds.metadata["camera"]
    native, _ = load_run(test, Preprocessing(int(cam["width"]), int(cam["height"]), False), log=log)
    conform = Preprocessor(prep, log=log)
    N_jpeg = corrupt(native, JPEG_TEST, seed=seed)
    X_jpeg = conform(N_jpeg)
    xy_jpeg, fused_jpeg = fuse_images(loc, X_jpeg, odo_test, source=N_jpeg, conform=conform)
    m_jpeg = localization_metrics(world.apply(xy_jpeg), xy_test, coordinate_range=crange)
    rows += _compact_rows(f"no ground truth, {JPEG_TEST} test images", m_jpeg)
    m_fj = localization_metrics(world.apply(fused_jpeg[:, :2]), xy_test, coordinate_range=crange)
    rows += _compact_rows(f"no ground truth, fused with odometry, {JPEG_TEST} test images", m_fj)
    # a camera whose gamma is not the training run's: the single images as sfanav localize reads them (the camera's
    # gamma estimated over the walk and taken out, the default) and as they are (sfanav localize --no-camera-gamma)
    N_gamma = corrupt(native, GAMMA_TEST, seed=seed)
    X_gamma = conform(N_gamma)
    tracker = CameraGamma.for_localizer(loc)
    if tracker is not None:
        xy_gc = predict_corrected(loc, tracker, X_gamma, source=N_gamma, conform=conform)
        m_gc = localization_metrics(world.apply(xy_gc), xy_test, coordinate_range=crange)
        rows += _compact_rows(f"no ground truth, {GAMMA_TEST} test images", m_gc)
    m_g = localization_metrics(world.apply(loc.predict(X_gamma)), xy_test, coordinate_range=crange)
    rows += _compact_rows(f"no ground truth, {GAMMA_TEST} test images, no camera gamma", m_g)
    peers = {"perfect memory": baselines.PerfectMemory(), "Fourier signature": baselines.FourierSignature(
        min(baselines.FourierSignature().n_coefficients, X_train.shape[2] // 2 + 1))}
    for name, peer in peers.items():
        pred = peer.fit(X_train, xy_train).predict(X_jpeg)
        rows.append({"metric": f"MED (m) {name} [{JPEG_TEST} test images]", "thesis": None,
                     "sfanav": localization_metrics(pred, xy_test, coordinate_range=crange)["med"]})
    timings["evaluate"] = time.perf_counter() - t0
    recording = _write_recording(out / "demo.rrd", loc, world, estimates, X_test, xy_test, log)

    # 5. reference rows: the same network on ground truth; the thesis's configuration
    t0 = time.perf_counter()
    augmentation = recipe.robust_kwargs()["readout_augmentation"]
    aug = augmented_features(loc, X_train, augmentation) if augmentation is not None else None
    F_train, G_train = loc.features(X_train), loc.signatures(X_train)
    sup = loc.sibling().fit_features(F_train, xy_train, signatures=G_train, augmented=aug)
    sup.info.update({k: v for k, v in loc.info.items() if k in ("dataset", "run", "network", "prep", "rotation",
                                                                 "fit_seconds")})
    sup.info["supervision"] = "ground-truth"
    sup.save(out / "model-ground-truth.sfa")
    m_sup = localization_metrics(sup.predict(X_test), xy_test, coordinate_range=crange)
    rows += _compact_rows("ground truth", m_sup)
    thesis_net = _tiny_network() if quick else Network.from_preset(THESIS_NETWORK, precision="mixed")
    thesis = fit_localizer(thesis_net, X_train, xy_train, rotation=rotation, n_outputs=8, readout="quadratic",
                           prep=prep, progress=progress)
    m_thesis = localization_metrics(thesis.predict(X_test), xy_test, coordinate_range=crange)
    rows += _compact_rows("thesis configuration, ground truth", m_thesis)
    rows.append({"metric": "MED ratio no ground truth / ground truth", "thesis": None,
                 "sfanav": ev.metrics["med"] / m_sup["med"] if m_sup["med"] > 0 else float("inf")})
    timings["reference rows"] = time.perf_counter() - t0
    wall = time.perf_counter() - t_start
    rows.append({"metric": "wall time (s)", "thesis": None, "sfanav": round(wall, 1)})
    notes = (
        f"Demo garden (8x8 m, seed {seed}): {len(X_train)} training images (grid run) with odometry, "
        f"{len(X_test)} test images (random walk), {prep.describe()}.\n"
        f"Rows '[no ground truth]' (the product: what a robot has): network {'tiny (quick)' if quick else DEMO_NETWORK} "
        f"trained on the images under simulated rotation ({rotation.step} px); the training run's positions learned "
        f"from its images and odometry by the pose graph ({describe_closures(loc.info)}, "
        f"odometry heading drift "
        f"{loc.info['odometry heading drift (deg per m)']:.3f} deg/m corrected); readout "
        f"{loc.describe_readout()} fitted to them. Its estimates are in the training run's odometry frame; for "
        "evaluation only they are moved into the world frame by the rigid transform (no scale) fitted on the "
        "training run. 'fused with odometry': the CTRV EKF over the test walk's odometry, noise chosen on the "
        "training run: the noise whose fused track of its held-out estimates (blocked cross-validation of the "
        "readout) is nearest the learned positions (no ground truth).\n"
        "Reference rows: '[ground truth]' the same network with the readout fitted to ground truth; '[thesis "
        f"configuration, ground truth]' the {'tiny' if quick else 'Table 5.1'} network with the thesis's quadratic "
        "regression on 8 outputs. Perfect memory and the Fourier signature store the training run's ground-truth "
        "positions.\n"
        "Plain rows: readout fitted on the training run, error on the test walk (honest). '(random splits)': the "
        "thesis 5.1.1 protocol, 50/50 splits of the test walk, 100 repeats (optimistic). The thesis column is its "
        "5.1.1 simulator experiment (a 30x30 grid, Table 5.1 network), for orientation, not a like-for-like target.\n"
        f"Wall time {wall:.0f} s: " + ", ".join(f"{k} {v:.0f} s" for k, v in timings.items()) + "."
    )
    result = ExperimentResult("demo", rows, [str(p) for _, p in ev.plots], notes)
    from ..localization.evaluation import write_evaluation_report

    ev.report = write_evaluation_report(ev, out / "report.md", title="sfanav demo", text=notes.split("\n"))
    result.write_json(out / "demo.json")
    (out / "timings.json").write_text(json.dumps({k: round(v, 2) for k, v in timings.items()} | {"wall": round(wall, 2)}, indent=2) + "\n")
    log(f"wrote {out / 'dataset'}, {out / 'model.sfa'} (no ground truth), {out / 'model-ground-truth.sfa'}, "
        f"{out / 'test-estimates.csv'}, {ev.report}, {len(ev.plots)} plots"
        + (f" and the Rerun recording {recording} (rerun {recording})" if recording else "")
        + f"; wall time {wall:.0f} s")
    return result
