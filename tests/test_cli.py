"""The ``sfanav`` command: train, localize, evaluate, demo and experiment on a
tiny simulated dataset with a tiny network, help texts and error paths."""

import importlib.util
import csv
import json

import numpy as np
import pytest
import sfanav
from clitools import TINY_TOML, assert_one_line_error, run, tiny_dataset
from sfanav import sim
from sfanav.app.cli import main
from sfanav.data import write_image


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A 60x8 dataset of the demo garden (train and test runs), a tiny config and a trained model."""
    root = tmp_path_factory.mktemp("cli")
    ds, cfg = tiny_dataset(root)
    model = root / "tiny.sfa"
    code = main(["train", "--dataset", str(root / "data"), "--config", str(cfg), "--out", str(model),
                 "--no-progress"])
    assert code == 0
    return {"root": root, "ds": ds, "config": cfg, "model": model}


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def test_train_writes_a_localizer_with_its_preprocessing(tiny, tmp_path, capsys):
    loc = sfanav.load(tiny["model"])
    assert isinstance(loc, sfanav.Localizer)
    assert loc.info["preprocessing"] == {"width": 60, "height": 8, "gray": False, "normalize": False}
    assert loc.info["run"] == "train" and loc.info["rotation"] == {"step": 5, "window": 1.0}
    assert loc.info["n_train_images"] == 40
    # a preset with overrides from the command line, an explicit run, resizing with a message
    code, out, err = run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"],
                         "--out", tmp_path / "m.sfa", "--run", "test", "--precision", "double", "--step", "3",
                         "--n-outputs", "6", "--normalize", "--no-progress")
    assert code == 0, err
    assert "wrote" in out and "trained on 40 images" in out
    loc = sfanav.load(tmp_path / "m.sfa")
    assert loc.n_outputs == 6 and loc.info["preprocessing"]["normalize"] and loc.info["rotation"]["step"] == 3
    # the same model file again needs --overwrite
    code, _, err = run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"],
                       "--out", tmp_path / "m.sfa", "--no-progress")
    assert_one_line_error(code, err, "--overwrite")


def test_train_seed_draws_the_robustness_copies(tiny, tmp_path, capsys):
    data = tiny["root"] / "data"
    models = {}
    for seed in (0, 3):
        code, _, err = run(capsys, "train", "--dataset", data, "--config", tiny["config"], "--robustness", "light",
                           "--seed", str(seed), "--out", tmp_path / f"m{seed}.sfa", "--no-progress")
        assert code == 0, err
        models[seed] = sfanav.load(tmp_path / f"m{seed}.sfa")
        assert models[seed].info["robustness_seed"] == seed
    test = tiny["ds"].select(run="test")
    X = next(iter(test.images(batch_size=len(test))))
    # the readout's corrupted copies are drawn by the seed: another draw, another readout
    assert not np.allclose(models[0].predict(X), models[3].predict(X))
    # a model without robustness has nothing to draw
    code, _, err = run(capsys, "train", "--dataset", data, "--config", tiny["config"], "--seed", "1",
                       "--out", tmp_path / "none.sfa", "--no-progress")
    assert_one_line_error(code, err, "--seed")
    assert not (tmp_path / "none.sfa").exists()


def test_localize_dataset_folder_and_video(tiny, tmp_path, capsys):
    ds = tiny["ds"]
    test = ds.select(run="test")
    code, out, err = run(capsys, "localize", tiny["model"], tiny["root"] / "data", "--run", "test",
                         "--out", tmp_path / "test.csv", "--no-progress")
    assert code == 0, err
    header, rows = read_csv(tmp_path / "test.csv")
    assert header == ["frame", "x", "y"]
    assert [int(r[0]) for r in rows] == test.frames.tolist()
    xy = np.array([[float(r[1]), float(r[2])] for r in rows])
    assert np.isfinite(xy).all()
    loc = sfanav.load(tiny["model"])
    np.testing.assert_allclose(xy, loc.predict(test.load_images()), atol=1e-3)
    assert "MED" in out

    # an image folder with images of another size: resized, with a message
    folder = tmp_path / "imgs"
    folder.mkdir()
    import cv2

    for i in range(5):
        write_image(folder / f"img{i:02d}.png", cv2.resize(test.image(i), (120, 16), interpolation=cv2.INTER_LINEAR))
    (folder / "notes.txt").write_text("not an image")
    code, out, err = run(capsys, "localize", tiny["model"], folder, "--out", tmp_path / "folder.csv", "--no-progress")
    assert code == 0, err
    assert "resizing 120x16 images to 60x8" in err
    header, rows = read_csv(tmp_path / "folder.csv")
    assert [r[0] for r in rows] == ["0", "1", "2", "3", "4"]

    # a video (MJPG in AVI, which every OpenCV build writes)
    video = tmp_path / "run.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (60, 8))
    assert writer.isOpened()
    for i in range(6):
        writer.write(cv2.cvtColor(test.image(i), cv2.COLOR_RGB2BGR))
    writer.release()
    code, out, err = run(capsys, "localize", tiny["model"], video, "--out", tmp_path / "video.csv", "--no-progress")
    assert code == 0, err
    header, rows = read_csv(tmp_path / "video.csv")
    assert len(rows) == 6 and header == ["frame", "x", "y"]


def test_localize_unwarps_omnidirectional_images(tiny, tmp_path, capsys):
    world = sim.recording.preset_world("demo", 3)
    renderer = sim.Renderer(world)
    omni = sim.OmniCamera(48)
    folder = tmp_path / "omni"
    folder.mkdir()
    for i, pose in enumerate([(0.0, 0.0, 0.0), (1.0, -1.0, 1.0), (-2.0, 1.5, 2.0)]):
        write_image(folder / f"{i}.png", renderer.render(omni, pose))
    code, _, err = run(capsys, "localize", tiny["model"], folder, "--mirror", "23.5,23.5,4,23",
                       "--out", tmp_path / "omni.csv", "--no-progress")
    assert code == 0, err
    assert "unwarping 48x48 omnidirectional images to 60x8 panoramas: given mirror" in err
    _, rows = read_csv(tmp_path / "omni.csv")
    assert len(rows) == 3
    code, _, err = run(capsys, "localize", tiny["model"], folder, "--mirror", "1,2,3",
                       "--out", tmp_path / "bad.csv", "--no-progress")
    assert_one_line_error(code, err, "mirror")


def test_train_on_omni_images_keeps_the_mirror(tiny, tmp_path, capsys):
    sim.simulate("demo", tmp_path / "omni", seed=1, max_frames=40, camera=sim.OmniCamera(64), progress=False)
    code, _, err = run(capsys, "train", "--dataset", tmp_path / "omni", "--config", tiny["config"],
                       "--out", tmp_path / "omni.sfa", "--no-progress")
    assert code == 0, err
    assert "unwarping 64x64 omnidirectional images to 60x8 panoramas: estimated mirror" in err
    mirror = sfanav.load(tmp_path / "omni.sfa").info["mirror"]
    assert len(mirror) == 4 and abs(mirror[0] - 31.5) < 3 and abs(mirror[1] - 31.5) < 3
    code, _, err = run(capsys, "localize", tmp_path / "omni.sfa", tmp_path / "omni", "--run", "test",
                       "--out", tmp_path / "omni.csv", "--no-progress")
    assert code == 0, err
    assert "using the mirror the model was trained with" in err and "given mirror" in err
    assert len(read_csv(tmp_path / "omni.csv")[1]) == 40


def test_evaluate_writes_report_metrics_and_plots(tiny, tmp_path, capsys):
    out = tmp_path / "report"
    code, stdout, err = run(capsys, "evaluate", tiny["model"], tiny["root"] / "data", "--out", out, "--no-progress")
    assert code == 0, err
    for name in ("report.md", "metrics.json", "firing_maps.png", "trajectory.png", "error_vs_n.png", "eta.png"):
        assert (out / name).exists(), name
    m = json.loads((out / "metrics.json").read_text())
    assert {"test_run", "random_splits", "eta_p", "eta_phi", "baselines", "error_vs_n"} <= set(m)
    assert set(m["baselines"]) == {"perfect memory", "Fourier signature"}
    assert m["test_run"]["n"] == 40
    # evo's trajectory errors of the estimates (definitions checked against evo in test_trajectory_metrics);
    # the rigid alignment on the run (least squares) can only lower the RMS error
    assert 0 < m["test_run"]["ape_rmse"] and 0 < m["test_run"]["rpe_rmse"]
    assert m["test_run"]["ape_rmse"] <= m["test_run"]["rmse"] + 1e-12
    assert "APE rmse" in stdout and "RPE rmse" in stdout
    report = (out / "report.md").read_text()
    assert "perfect memory" in report and "random" in report and "![" in report
    for name in ("MAE x (%)", "MED (m)", "max eta_phi (outputs 1-8)", "MED (m) perfect memory",
                 "bytes per place Fourier signature"):
        assert name in stdout
    code, stdout, err = run(capsys, "evaluate", tiny["model"], tiny["root"] / "data", "--out", tmp_path / "r2",
                            "--run", "train", "--no-baselines", "--no-progress")
    assert code == 0, err
    assert "perfect memory" not in stdout


def test_demo_quick(tmp_path, capsys):
    code, out, err = run(capsys, "demo", "--quick", "--out", tmp_path / "demo", "--no-progress")
    assert code == 0, err
    for name in ("dataset", "model.sfa", "model-ground-truth.sfa", "test-estimates.csv", "report.md", "demo.json",
                 "firing_maps.png", "trajectory.png"):
        assert (tmp_path / "demo" / name).exists(), name
    assert "MAE x (%) (random splits) [no ground truth]" in out and "1.83" in out and "wall time" in out
    d = json.loads((tmp_path / "demo" / "demo.json").read_text())
    metrics = {r["metric"] for r in d["rows"]}
    assert metrics >= {"MED (m) [no ground truth]", "max eta_phi (outputs 1-8) [no ground truth]",
                       "MED (m) [no ground truth, fused with odometry]", "MED (m) [ground truth]",
                       "MED (m) [thesis configuration, ground truth]", "MED (m) perfect memory",
                       "MED ratio no ground truth / ground truth", "MED (m) [no ground truth, gamma-1.4 test images]"}
    # the demo's main model was trained without ground truth, the reference one with it
    import sfanav
    assert "camera_gamma" in sfanav.load(tmp_path / "demo" / "model.sfa").info  # a photometric model: the gamma row
    assert "MED (m) [no ground truth, gamma-1.4 test images, no camera gamma]" in metrics

    assert sfanav.load(tmp_path / "demo" / "model.sfa").info["supervision"] == "odometry"
    assert sfanav.load(tmp_path / "demo" / "model-ground-truth.sfa").info["supervision"] == "ground-truth"
    head = (tmp_path / "demo" / "test-estimates.csv").read_text().splitlines()[0]
    assert head == "frame,x,y,fused_x,fused_y,fused_heading"
    # the fused track came from the streaming localizer (image by image): the batch filter over the same
    # estimates, with the same images' novelty, gives the same track
    from sfanav.data import Dataset
    from sfanav.data.preprocessing import Preprocessing, Preprocessor
    from sfanav.data.sources import open_images
    from sfanav.odometry.fusion import fuse

    rows = np.loadtxt(tmp_path / "demo" / "test-estimates.csv", delimiter=",", skiprows=1)
    odo = Dataset(tmp_path / "demo" / "dataset").select(run="test").odometry
    loc = sfanav.load(tmp_path / "demo" / "model.sfa")
    images = np.concatenate(list(open_images(tmp_path / "demo" / "dataset", run="test").batches(64)))
    novelty = loc.novelty(Preprocessor(Preprocessing.of_model(loc))(images))
    batch = fuse(odo, rows[:, 1:3], loc.info["ekf_noise"], novelty=novelty)
    np.testing.assert_allclose(rows[:, 3:5], batch[:, :2], atol=2e-3)
    # the Rerun recording holds the whole walk
    if importlib.util.find_spec("rerun") is not None:
        from test_live_view import _entities

        t = _entities(tmp_path / "demo" / "demo.rrd")
        for e in ("/camera/image", "/world/estimate", "/world/fused", "/world/fused/ellipse", "/world/truth"):
            assert sorted(t[e].column("frame").to_pylist()) == list(range(len(rows))), e
        assert ("/world/map", "static") in t
    code, _, err = run(capsys, "demo", "--quick", "--out", tmp_path / "demo", "--no-progress")
    assert_one_line_error(code, err, "--overwrite")


def test_experiment_list_and_help(capsys):
    code, out, _ = run(capsys, "experiment", "--list")
    assert code == 0
    for name in ("5.1.1", "5.1.2", "5.1.3", "5.2"):
        assert any(line.split()[0] == name for line in out.splitlines())
    code, out, _ = run(capsys, "--help")
    assert code == 0
    for cmd in ("simulate", "train", "localize", "evaluate", "navigate", "demo", "experiment"):
        assert cmd in out
    for cmd, words in {"train": ("--preset", "--config", "--dataset", "--step", "--window", "--precision"),
                       "localize": ("INPUT", "--mirror", "frame,x,y", "video"),
                       "evaluate": ("--train-run", "report.md", "baselines"),
                       "demo": ("--out", "--seed", "5.1.1", "no ground truth"),
                       "navigate": ("--start", "--target", "--target-image", "geodesic", "--start=-3,-3"),
                       "experiment": ("--list", "--quick", "JSON")}.items():
        code, out, _ = run(capsys, cmd, "--help")
        assert code == 0
        for w in words:
            assert w in out, (cmd, w)


def test_error_paths(tiny, tmp_path, capsys):
    data = tiny["root"] / "data"
    # missing dataset
    code, _, err = run(capsys, "train", "--dataset", tmp_path / "nope", "--preset", "thesis-5.1", "--out", tmp_path / "m.sfa")
    assert_one_line_error(code, err, "does not exist")
    # bad configs: unparsable, unknown keys, layers that do not tile, a missing file
    bad = tmp_path / "bad.toml"
    bad.write_text("[input\nwidth = 3")
    code, _, err = run(capsys, "train", "--dataset", data, "--config", bad, "--out", tmp_path / "m.sfa")
    assert_one_line_error(code, err, "cannot parse")
    bad.write_text(TINY_TOML.replace("out = 8", "out = 8\ncolour = 1"))
    code, _, err = run(capsys, "train", "--dataset", data, "--config", bad, "--out", tmp_path / "m.sfa")
    assert_one_line_error(code, err, "unknown keys")
    bad.write_text(TINY_TOML.replace("stride = [3, 4]", "stride = [4, 4]"))
    code, _, err = run(capsys, "train", "--dataset", data, "--config", bad, "--out", tmp_path / "m.sfa", "--no-progress")
    assert_one_line_error(code, err)
    code, _, err = run(capsys, "train", "--dataset", data, "--config", tmp_path / "none.toml", "--out", tmp_path / "m.sfa")
    assert_one_line_error(code, err, "does not exist")
    code, _, err = run(capsys, "train", "--dataset", data, "--preset", "thesis-9", "--out", tmp_path / "m.sfa")
    assert_one_line_error(code, err, "unknown preset")
    code, _, err = run(capsys, "train", "--dataset", data, "--config", tiny["config"], "--out", tmp_path / "m.sfa",
                       "--run", "nope")
    assert_one_line_error(code, err, "no run")
    # unknown experiment, no name
    code, _, err = run(capsys, "experiment", "9.9.9")
    assert_one_line_error(code, err, "unknown experiment", "5.1.1")
    code, _, err = run(capsys, "experiment")
    assert_one_line_error(code, err, "--list")
    # missing model, a file that is no model, a missing input
    code, _, err = run(capsys, "localize", tmp_path / "none.sfa", data, "--out", tmp_path / "x.csv")
    assert_one_line_error(code, err, "does not exist")
    code, _, err = run(capsys, "localize", bad, data, "--out", tmp_path / "x.csv")
    assert_one_line_error(code, err)
    code, _, err = run(capsys, "localize", tiny["model"], tmp_path / "none", "--out", tmp_path / "x.csv")
    assert_one_line_error(code, err, "no such file")
    code, _, err = run(capsys, "localize", tiny["model"], bad, "--out", tmp_path / "x.csv")
    assert_one_line_error(code, err, "not a dataset")
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = run(capsys, "localize", tiny["model"], empty, "--out", tmp_path / "x.csv")
    assert_one_line_error(code, err, "no images")
    code, _, err = run(capsys, "evaluate", tiny["model"], tmp_path / "nope", "--out", tmp_path / "r")
    assert_one_line_error(code, err, "does not exist")
    # a network SFA model is not a localizer
    net_file = tmp_path / "sfa.sfa"
    sfanav.SFA(n_components=1).fit(np.random.default_rng(0).standard_normal((50, 3))).save(net_file)
    code, _, err = run(capsys, "localize", net_file, data, "--out", tmp_path / "x.csv")
    assert_one_line_error(code, err, "not a localizer")
    # bad argument values
    code, _, err = run(capsys, "train", "--dataset", data, "--config", tiny["config"], "--out", tmp_path / "m.sfa",
                       "--window", "0")
    assert_one_line_error(code, err, "--window")


def test_train_with_loop_closures(tiny, tmp_path, capsys):
    code, out, err = run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"],
                         "--out", tmp_path / "lc.sfa", "--loop-closures", "gt", "--closure-weights", "score",
                         "--no-progress")
    assert code == 0, err
    assert "loop closures (gt):" in err  # the 40-frame run has no place seen again 50 frames later
    assert sfanav.load(tmp_path / "lc.sfa").info["loop_closures"] == 0
    code, _, err = run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"],
                       "--out", tmp_path / "w.sfa", "--closure-weights", "score", "--no-progress")
    assert_one_line_error(code, err, "--closure-weights needs --loop-closures")
    code, _, err = run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"],
                       "--out", tmp_path / "o.sfa", "--loop-closures", "gt", "--supervision", "odometry",
                       "--no-progress")
    assert_one_line_error(code, err, "--loop-closures gt needs ground-truth positions")
    code, _, err = run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"],
                       "--out", tmp_path / "s.sfa", "--loop-closures", "surf", "--no-progress")
    assert code == 2 and "invalid choice" in err


def test_train_with_relative_pose_closures(tiny, tmp_path, capsys):
    """Without ground truth the pose graph's closures are GTSAM's relative
    poses by whichever warping method fits better by default (auto; recorded
    in the model with the method kept and both misfits); --closures heading
    keeps the heading-only closures, relative-pose / min-warping measure them
    by one method; --closures with the metric learner is one clear error."""
    for flag, want, method in (([], "auto", None), (["--closures", "heading"], "heading", "-"),
                               (["--closures", "relative-pose"], "relative-pose", "warping"),
                               (["--closures", "min-warping"], "min-warping", "min-warping")):
        code, _, err = run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"],
                           "--out", tmp_path / f"rp-{want}.sfa", "--supervision", "odometry", *flag, "--no-progress")
        assert code == 0, err
        info = sfanav.load(tmp_path / f"rp-{want}.sfa").info
        assert info["closures"] == want and info["supervision"] == "odometry"
        if method is None:  # auto: the method of the lower misfit (None: no closure measured a position here)
            m = {k: (np.inf if v is None else v) for k, v in info["closure misfit by method"].items()}
            assert set(m) == {"warping", "min-warping"}
            assert info["closure method"] == ("min-warping" if m["min-warping"] < m["warping"] else "warping")
        else:
            assert info.get("closure method", "-") == method and "closure misfit by method" not in info
    code, _, err = run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"],
                       "--out", tmp_path / "ml.sfa", "--supervision", "odometry", "--closures", "relative-pose",
                       "--metric-map", "metric-learning", "--no-progress")
    assert_one_line_error(code, err, "--closures relative-pose needs --metric-map pose-graph")
    assert not (tmp_path / "ml.sfa").exists()


def test_the_closures_choices_are_the_librarys():
    """`sfanav train --closures` lists its choices literally (the CLI imports
    the library lazily): they must stay the pipeline's."""
    import argparse

    from sfanav.app.cli import build_parser
    from sfanav.pipeline import CLOSURES

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    train = sub.choices["train"]
    action = next(a for a in train._actions if "--closures" in a.option_strings)
    assert tuple(action.choices) == tuple(CLOSURES)
