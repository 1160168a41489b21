"""``sfanav simulate``: presets, determinism by seed, one-line errors."""

import os
import subprocess
import sys

import numpy as np
import pytest

from sfanav import Dataset, sim
from clitools import run


def test_help_lists_the_presets(capsys):
    code, out, _ = run(capsys, "simulate", "--help")
    assert code == 0
    for name in sim.PRESETS:
        assert name in out
    for name in ("thesis-5.1.1-grid", "thesis-5.3-garden", "thesis-6.2.1-light", "thesis-6.2.1-dynamic",
                 "thesis-6.2.2-conditions", "thesis-7.1-open", "thesis-7.1-obstacle"):
        assert name in sim.PRESETS


def test_simulate_is_deterministic_by_seed(tmp_path, capsys):
    args = ["simulate", "--preset", "demo", "--max-frames", "3", "--no-progress", "--size", "80x12"]
    code, out, err = run(capsys, *args, "--out", str(tmp_path / "a"), "--seed", "7")
    assert code == 0, err
    assert "wrote 6 images" in out
    code, _, err = run(capsys, *args, "--out", str(tmp_path / "b"), "--seed", "7")
    assert code == 0, err
    a, b = Dataset(tmp_path / "a"), Dataset(tmp_path / "b")
    assert len(a) == 6 and set(a.runs) == {"train", "test"}
    np.testing.assert_array_equal(a.poses, b.poses)
    np.testing.assert_array_equal(a.odometry, b.odometry)
    np.testing.assert_array_equal(a.load_images(), b.load_images())
    assert a.image(0).shape == (12, 80, 3)
    assert (tmp_path / "a" / "frames.csv").read_text() == (tmp_path / "b" / "frames.csv").read_text()
    world = sim.World.load(tmp_path / "a" / "world.json")
    assert a.metadata["preset"] == "demo" and a.metadata["seed"] == 7 and world.area == (8.0, 8.0)
    code, _, err = run(capsys, *args, "--out", str(tmp_path / "c"), "--seed", "8")
    assert not np.array_equal(Dataset(tmp_path / "c").load_images(), a.load_images())


def test_two_cameras_conditions_and_omni(tmp_path):
    ds = sim.simulate("thesis-6.2.2-conditions", tmp_path / "cond", seed=1, max_frames=2, progress=False,
                      camera=sim.PanoramicCamera(60, 8))
    assert len(ds) == 20 and len(set(ds.conditions)) == 10
    assert len(set(ds.frames)) == 20  # every condition's drive has its own frames
    # every condition drives the loop again, a few centimetres off (the jitter)
    gap = np.hypot(*(ds.select(condition="c0").poses[:, :2] - ds.select(condition="c5").poses[:, :2]).T)
    assert 0 < gap.max() <= 0.1 + 1e-9
    ds = sim.simulate("thesis-7.1-obstacle", tmp_path / "two", seed=1, max_frames=2, progress=False,
                      camera=sim.OmniCamera(40))
    assert set(ds.cameras) == {"left", "right"} and ds.image(0).shape == (40, 40, 3)
    left, right = ds.select(camera="left").poses, ds.select(camera="right").poses
    np.testing.assert_allclose(np.hypot(*(left[:, :2] - right[:, :2]).T), 0.7)
    world = sim.World.load(tmp_path / "two" / "world.json")
    assert any(o.kind == "wall" for o in world.obstacles)
    assert world.free(ds.poses[:, 0], ds.poses[:, 1]).all()


def test_dynamic_preset_circles_once(tmp_path):
    ds = sim.simulate("thesis-6.2.1-dynamic", tmp_path / "dyn", seed=0, max_frames=2, progress=False,
                      camera=sim.PanoramicCamera(40, 6))
    world = sim.World.load(tmp_path / "dyn" / "world.json")
    assert len(world.dynamic) == 1
    train_t = ds.select(run="train").timestamps
    assert world.dynamic[0].period == pytest.approx(train_t.max())


@pytest.mark.parametrize(
    "args, message",
    [
        (["--preset", "nope"], "unknown preset 'nope'; available: demo"),
        (["--preset", "demo", "--size", "12xfoo"], "size must be WIDTHxHEIGHT"),
        (["--preset", "demo", "--seed", "-1"], "expected an integer >= 0"),
        (["--preset", "demo", "--camera", "omni", "--size", "40x30"], "an omni image is square"),
    ],
)
def test_bad_arguments_give_one_line_errors(tmp_path, capsys, args, message):
    code, _, err = run(capsys, "simulate", *args, "--out", str(tmp_path / "x"))
    assert code == 2
    assert message in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_existing_output_is_refused(tmp_path, capsys):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "f.txt").write_text("mine")
    code, _, err = run(capsys, "simulate", "--preset", "demo", "--out", str(tmp_path / "x"), "--max-frames", "1",
                       "--no-progress")
    assert code == 2 and "is not empty" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_command_line_entry_point_without_traceback(tmp_path):
    code = "import sys; from sfanav.app.cli import main; sys.exit(main())"
    r = subprocess.run([sys.executable, "-c", code, "simulate", "--preset", "bogus", "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, env=dict(os.environ))
    assert r.returncode == 2 and "unknown preset 'bogus'" in r.stderr and "Traceback" not in r.stderr
