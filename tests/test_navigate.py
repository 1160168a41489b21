"""Navigation to a goal with a trained model: ``sfanav.navigation.navigate``
and ``sfanav navigate`` (a tiny model on a tiny dataset: the behaviour of the
loop and the command, not the quality of the localizer)."""

import csv
import json
import shutil
import warnings

import numpy as np
import pytest
import sfanav
from sfanav import sim
from sfanav.app.cli import main
from sfanav.navigation import Mission, check_goal_in_map, image_goal, navigate
from clitools import assert_one_line_error, run

TINY = {"input": {"width": 60, "height": 8, "channels": 3}, "network": {"precision": "mixed"},
        "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 8}, {"rf": "full", "out": 10}]}


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("nav")
    ds = sim.simulate("demo", root / "data", seed=2, max_frames=120, camera=sim.PanoramicCamera(60, 8),
                      progress=False)
    cfg = root / "tiny.json"
    cfg.write_text(json.dumps(TINY))
    model = root / "tiny.sfa"
    assert main(["train", "--dataset", str(root / "data"), "--config", str(cfg), "--supervision", "odometry",
                 "--out", str(model), "--no-progress"]) == 0
    return {"root": root, "ds": ds, "model": model}


def test_navigate_returns_a_consistent_mission(trained):
    loc = sfanav.load(trained["model"])
    ds = trained["ds"]
    world = sim.World.load(ds.root / "world.json")
    tr = ds.select(run="train")
    X = tr.load_images()
    explore = loc.predict(X)
    cam = sim.PanoramicCamera(60, 8)
    goal = image_goal(loc, X[-1])
    assert goal.shape == (2,) and np.isfinite(goal).all()
    m = navigate(loc, world, cam, (-2.0, -2.0), goal, exploration=explore, max_iterations=15, seed=1)
    assert isinstance(m, Mission)
    r = m.result
    assert r.path.shape[1] == 2 and len(r.path) == r.iterations + 1 or r.success
    np.testing.assert_allclose(m.world_goal, goal)  # default: map and world agree
    end = float(np.hypot(*(r.path[-1] - m.world_goal)))
    assert r.success == (end <= 0.5)
    assert m.optimal == pytest.approx(np.hypot(*(m.world_goal - np.array([-2.0, -2.0]))))  # no obstacles
    if r.success:
        assert 0 < m.efficiency <= 1
    else:
        assert np.isnan(m.efficiency)
    d = m.to_dict()
    assert d["success"] == r.success and d["stops"] == r.iterations and json.dumps(d)
    # straight at the goal, and the same seed gives the same run
    s1 = navigate(loc, world, cam, (-2.0, -2.0), goal, exploration=explore, geodesic=False, max_iterations=5)
    s2 = navigate(loc, world, cam, (-2.0, -2.0), goal, exploration=explore, geodesic=False, max_iterations=5)
    assert s1.field is None
    np.testing.assert_array_equal(s1.result.path, s2.result.path)
    # by default the field is built over the positions the readout was fitted to (stored in the model)
    m2 = navigate(loc, world, cam, (-2.0, -2.0), goal, max_iterations=1, seed=1)
    np.testing.assert_array_equal(m2.field.cells, navigate(loc, world, cam, (-2.0, -2.0), goal, max_iterations=1,
                                                           exploration=loc.training_positions_).field.cells)
    loc.training_positions_ = None  # as a model file written before they were stored
    with pytest.raises(ValueError, match="exploration="):
        navigate(loc, world, cam, (-2.0, -2.0), goal, max_iterations=1)


def test_navigate_refuses_bad_starts_and_goals(trained):
    loc = sfanav.load(trained["model"])
    world = sim.World.load(trained["ds"].root / "world.json")
    cam = sim.PanoramicCamera(60, 8)
    explore = np.random.default_rng(0).uniform(-3, 3, (50, 2))
    with pytest.raises(ValueError, match="not free ground"):
        navigate(loc, world, cam, (40.0, 0.0), (0.0, 0.0), exploration=explore)
    with pytest.raises(ValueError, match="goal"):
        navigate(loc, world, cam, (0.0, 0.0), (np.nan, 0.0), exploration=explore)


def test_cli_navigate_writes_the_mission(trained, tmp_path, capsys):
    out = tmp_path / "nav"
    code, stdout, err = run(capsys, "navigate", trained["model"], trained["root"] / "data", "--start=-2,-2,45",
                            "--target", "1.5,1.5", "--max-stops", "12", "--out", out, "--no-progress")
    assert code == 0, err
    assert "the training run's odometry frame" in err  # a model trained without ground truth
    assert "the positions its readout was fitted to" in err  # the field over the stored learned positions
    d = json.loads((out / "navigation.json").read_text())
    assert d["supervision"] == "odometry" and d["geodesic field"] is True and d["stops"] <= 12
    assert d["map goal"] == [1.5, 1.5] and len(d["world goal"]) == 2
    with open(out / "path.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["stop", "x", "y"] and len(rows) - 1 == len({r[0] for r in rows[1:]})
    assert [float(v) for v in rows[1][1:]] == [-2.0, -2.0]
    assert (out / "trajectory.png").stat().st_size > 1000
    assert ("reached the target" in stdout) == d["success"]
    # again without --overwrite: refused; target as a frame of the dataset, as an image file
    code, _, err = run(capsys, "navigate", trained["model"], trained["root"] / "data", "--start=-2,-2",
                       "--target", "1,1", "--out", out)
    assert code == 2 and "--overwrite" in err
    code, _, err = run(capsys, "navigate", trained["model"], trained["root"] / "data", "--start=-2,-2",
                       "--target-frame", "5", "--max-stops", "3", "--out", tmp_path / "f", "--no-progress")
    assert code == 0, err
    img = sorted((trained["root"] / "data" / "images").iterdir())[7]
    code, _, err = run(capsys, "navigate", trained["model"], trained["root"] / "data", "--start=-2,-2",
                       "--target-image", img, "--max-stops", "3", "--out", tmp_path / "i", "--no-progress")
    assert code == 0, err
    assert json.loads((tmp_path / "i" / "navigation.json").read_text())["target"].startswith("the image")


@pytest.mark.parametrize("args, words", [
    (["--start", "1,2,3,4", "--target", "0,0"], "X,Y"),
    (["--start=0,0", "--target", "0,0,1"], "no heading"),
    (["--start=0,0", "--target-frame", "99999"], "no frame 99999"),
    (["--start=0,0", "--target-image", "/nonexistent.png"], "does not exist"),
    (["--start=0,0", "--target", "0,0", "--run", "nope"], "no run 'nope'"),
    (["--start=0,0", "--target", "0,0", "--success-radius", "-1"], "--success-radius"),
    (["--start=99,0", "--target", "0,0"], "not free ground"),
])
def test_cli_navigate_bad_input(trained, tmp_path, capsys, args, words):
    code, _, err = run(capsys, "navigate", trained["model"], trained["root"] / "data", *args, "--out",
                       tmp_path / "o", "--no-progress")
    assert code == 2, err
    assert words in err and "Traceback" not in err


@pytest.mark.parametrize("target", ["--target=1e6,1e6", "--target=-1e300,1e300", "--target=30,0"])
def test_cli_navigate_refuses_a_target_outside_the_map(trained, tmp_path, capsys, target):
    """A target 1414 km away (or 1e300 m) is refused as a far --start is,
    in one line without overflow warnings, before the robot moves; the map
    is the box around the exploration run, widened by a quarter of its side."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an overflow warning would fail here
        code, _, err = run(capsys, "navigate", trained["model"], trained["root"] / "data", "--start=-2,-2", target,
                           "--out", tmp_path / "o", "--no-progress")
    assert_one_line_error(code, err, f"--target ({', '.join(f'{float(v):.6g}' for v in target[9:].split(','))}) "
                                     "is outside the map: the exploration run spans x ")
    assert len(err) < 300 and not (tmp_path / "o").exists()
    explore = sfanav.load(trained["model"]).training_positions_
    lo, hi = explore.min(0), explore.max(0)
    margin = max(1.0, 0.25 * float((hi - lo).max()))
    check_goal_in_map(hi + 0.9 * margin, explore)  # just inside
    with pytest.raises(ValueError, match="goal .* is outside the map"):
        check_goal_in_map(hi + 1.1 * margin, explore)


def test_navigate_refuses_a_goal_outside_the_map(trained):
    loc = sfanav.load(trained["model"])
    world = sim.World.load(trained["ds"].root / "world.json")
    with pytest.raises(ValueError, match=r"goal \(1e\+06, 1e\+06\) is outside the map"):
        navigate(loc, world, sim.PanoramicCamera(60, 8), (-2.0, -2.0), (1e6, 1e6), max_iterations=1)


@pytest.mark.parametrize("value", ["-5", "0", "x"])
def test_cli_navigate_max_stops_states_its_real_bound(trained, tmp_path, capsys, value):
    code, _, err = run(capsys, "navigate", trained["model"], trained["root"] / "data", "--start=-2,-2",
                       "--target", "1,1", "--max-stops", value, "--out", tmp_path / "o")
    assert_one_line_error(code, err, f"--max-stops: expected an integer >= 1, got '{value}'")


def test_cli_navigate_needs_a_simulated_world(trained, tmp_path, capsys):
    shutil.copytree(trained["root"] / "data", tmp_path / "real")
    md = json.loads((tmp_path / "real" / "metadata.json").read_text())
    md.pop("world")
    (tmp_path / "real" / "metadata.json").write_text(json.dumps(md))
    (tmp_path / "real" / "world.json").unlink()
    code, _, err = run(capsys, "navigate", trained["model"], tmp_path / "real", "--start=0,0", "--target", "1,1",
                       "--out", tmp_path / "o")
    assert code == 2 and "no simulated world" in err
