"""The odometry experiments (5.3.1-sim, 5.3.1-real, 5.3.2) as quick smoke
runs through the registry and the CLI: required rows, finite values, JSON,
plots; plus the helpers they add (lines from the simulator's segment column,
chord lines)."""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from clitools import SFANAV_ROOT
from sfanav import experiments
from sfanav.experiments.odometry import sim_lines
from sfanav.odometry import dead_reckon
from sfanav.sim import trajectories as T

ROWS_5_3_1 = ["lines", "points on lines", "iterations", "train MED supervised (m)", "train MED unsupervised (m)",
              "test MED supervised (m)", "test MED unsupervised (m)", "unsupervised/supervised test MED ratio",
              "thesis gradient descent: test MED unsupervised (m)",
              "target: unsupervised test MED within 1.3x of supervised",
              "pose graph (no ground truth): test MED, regression on the whole run (m)",
              "pose graph (no ground truth) / supervised whole-run test MED ratio",
              "test MED perfect memory (m)", "test MED Fourier signature (m)"]
ROWS_5_3_2 = ["SFA MED (m)", "odometry MED (m)", "EKF MED (m)", "EKF improvement over SFA alone (%)",
              "test MED supervised (m)", "test MED unsupervised (m)", "EKF MED, noise tuned on the training run (m)",
              "target: EKF at least 20 % better than SFA alone", "target: EKF better than odometry alone",
              "EKF MED (sfanav path, no ground truth (pose graph, held-out noise)) (m)",
              "EKF improvement over SFA alone (sfanav path, no ground truth (pose graph, held-out noise)) (%)",
              "test MED perfect memory (m)", "test MED Fourier signature (m)"]


PRODUCT = [f"{m} {c}" for m in ("MED (m)", "MAE x (%)", "MAE y (%)") for c in (
    "thesis configuration", "sfanav default [ground truth]", "sfanav default [ground truth, fused]",
    "sfanav default [no ground truth]", "sfanav default [no ground truth, fused]", "peer perfect memory",
    "peer Fourier signature")] + [
    "MED ratio sfanav default [ground truth] / best peer", "MED ratio sfanav default [no ground truth] / best peer",
    "MED ratio sfanav default [no ground truth, fused] / best peer",
    "MED ratio sfanav default [no ground truth] / [ground truth]"]
"""The product rows beside the thesis configuration and the peers (the scenes have odometry in every run)."""


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    return tmp_path_factory.mktemp("odometry-experiments")


def check(d, out, required):
    names = [r["metric"] for r in d["rows"]]
    assert len(names) == len(set(names)), "metric names must be unique"
    missing = [n for n in required if n not in names]
    assert not missing, missing
    for r in d["rows"]:
        assert set(r) >= {"metric", "thesis", "sfanav"}
        v = r["sfanav"]
        assert isinstance(v, (int, float, str)) and not isinstance(v, bool), r
        if isinstance(v, (int, float)):
            assert math.isfinite(v), r
    for p in d["plots"]:
        assert not Path(p).is_absolute() and (out / p).exists(), p  # relative to the JSON's folder
    assert d["notes"] and "quick" in d["notes"]
    return {r["metric"]: r for r in d["rows"]}


def test_registered():
    assert {"5.3.1-sim", "5.3.1-real", "5.3.2"} <= set(experiments.names())


@pytest.mark.parametrize("name", ["5.3.1-real", "5.3.1-sim"])
def test_5_3_1_quick(name, out):
    res = experiments.run(name, out, quick=True, progress=False)
    d = json.loads((out / f"{name}.json").read_text())
    assert d["experiment"] == name and len(d["rows"]) == len(res.rows)
    rows = check(d, out, ROWS_5_3_1 + PRODUCT)
    assert rows["MED (m) thesis configuration"]["sfanav"] == pytest.approx(rows["test MED unsupervised (m)"]["sfanav"])
    assert rows["lines"]["sfanav"] >= 2
    assert rows["test MED unsupervised (m)"]["thesis"] == (0.36 if name == "5.3.1-sim" else 0.14)
    assert rows["target: unsupervised test MED within 1.3x of supervised"]["sfanav"] in ("met", "NOT met")
    assert any(p.endswith(f"{name}-fig5.19.png") for p in d["plots"])
    assert res.table().splitlines()[0].split() == ["metric", "thesis", "sfanav"]


def test_5_3_2_cli_quick(out):
    # after 5.3.1-real in the same directory: reuses its dataset and features
    env = {**os.environ, "PYTHONPATH": SFANAV_ROOT}
    p = subprocess.run([sys.executable, "-m", "sfanav.app.cli", "experiment", "5.3.2", "--quick", "--out", str(out),
                        "--no-progress"], capture_output=True, text=True, env=env, timeout=600)
    assert p.returncode == 0, p.stderr
    assert "EKF MED (m)" in p.stdout and "odometry MED (m)" in p.stdout
    rows = check(json.loads((out / "5.3.2.json").read_text()), out, ROWS_5_3_2 + PRODUCT)
    assert rows["MED (m) thesis configuration"]["sfanav"] == pytest.approx(rows["EKF MED (m)"]["sfanav"])
    assert rows["EKF MED (m)"]["thesis"] == 0.11 and rows["odometry MED (m)"]["thesis"] == 0.31
    assert rows["EKF MED (m)"]["sfanav"] > 0
    assert (out / "5.3.2" / "fusion.png").exists()


def test_sim_lines_distances_from_odometry():
    # two straight lines joined by a turn on the spot; odometry reports 1 % more distance
    steps = [(0.2, 0.0)] * 10 + [(0.0, np.pi / 8)] * 4 + [(0.2, 0.0)] * 6
    poses = dead_reckon(np.array(steps) * [1.01, 1.0], (1.0, 2.0, 0.3))
    seg = np.array([0] * 11 + [-1] * 3 + [1] * 7)
    lines = sim_lines(seg, poses)
    assert lines.n_lines == 2 and lines.relative_angles is None
    np.testing.assert_allclose(lines.distances[:11], 0.202 * np.arange(11), atol=1e-12)
    np.testing.assert_allclose(lines.distances[14:], 0.202 * np.arange(7), atol=1e-12)
    assert np.isnan(lines.distances[11:14]).all()
    with pytest.raises(ValueError, match="contiguous"):
        sim_lines(np.array([0] * 5 + [-1] * 3 + [0] * 13), poses)


def test_line_segments_through_are_chords():
    tr = T.line_segments((16.0, 18.0), 6, 8.0, 0.2, rng=3, through=True)
    seg = tr.extra["segment"]
    for n in range(6):
        p = tr.poses[seg == n, :2]
        assert np.hypot(*(p[-1] - p[0])) >= 8.0 - 0.2
        # the chord's ends touch the area shrunk by the margin (0.5 m) on both sides, to a step
        ends = np.abs(p[[0, -1]]) - [7.5, 8.5]
        assert (ends.max(axis=1) > -0.21).all(), ends
