"""Run-time fusion without ground truth (sfanav.odometry.fusion, sfanav
localize --odometry)."""

import csv

import numpy as np
import pytest

from sfanav.experiments.synthetic_odometry import make_odometry_run
from sfanav.localization import med
from sfanav.odometry import fuse, noise_from_run, start_pose_from_estimates


def _estimates(run, sigma, seed):
    rng = np.random.default_rng(seed)
    Z = run["xy"] + sigma * rng.normal(size=run["xy"].shape)
    Z[rng.random(len(Z)) < 0.02] += 3.0  # a few outliers
    return Z


def test_noise_from_one_run_fuses_another_better_than_its_estimates():
    train, test = make_odometry_run(random_state=1), make_odometry_run(random_state=2)
    noise = noise_from_run(train["odometry"], _estimates(train, 0.2, 0))
    assert set(noise) == {"distance_noise", "heading_noise", "measurement_noise", "turn_noise"}
    Z = _estimates(test, 0.2, 1)
    poses = fuse(test["odometry"], Z, noise)
    assert poses.shape == (len(Z), 3) and np.isfinite(poses).all()
    assert med(poses[:, :2], test["xy"]) < 0.8 * med(Z, test["xy"])


def test_start_pose_from_the_first_estimates():
    run = make_odometry_run(random_state=4)
    s0 = start_pose_from_estimates(run["odometry"], _estimates(run, 0.05, 3))
    true = run["poses"][0]
    assert np.hypot(*(s0[:2] - true[:2])) < 0.15
    assert abs(np.angle(np.exp(1j * (s0[2] - true[2])))) < 0.15


def test_fusion_refuses_bad_input():
    run = make_odometry_run(random_state=5)
    Z = _estimates(run, 0.1, 0)
    with pytest.raises(ValueError, match="do not move"):
        start_pose_from_estimates(np.zeros_like(run["odometry"]), Z)
    with pytest.raises(ValueError, match="infinity"):
        fuse(run["odometry"], np.where(np.arange(len(Z))[:, None] == 3, np.inf, Z), {"distance_noise": 0.01,
             "heading_noise": 0.01, "measurement_noise": 0.2})
    with pytest.raises(ValueError, match="noise must give"):
        fuse(run["odometry"], Z, {"distance_noise": 0.01})
    with pytest.raises(ValueError, match="same length|must match|rows"):
        fuse(run["odometry"][:-2], Z, {"distance_noise": 0.01, "heading_noise": 0.01, "measurement_noise": 0.2})


def test_cli_localize_with_odometry(tmp_path, capsys):
    import json

    from sfanav import sim
    from sfanav.app import cli

    ds = sim.simulate("demo", tmp_path / "d", 0, camera=sim.PanoramicCamera(70, 8), progress=False)
    config = tmp_path / "net.json"
    config.write_text(json.dumps({"input": {"width": 70, "height": 8, "channels": 3},
                                  "network": {"precision": "mixed"},
                                  "layers": [{"rf": [7, 4], "stride": [3, 4], "out": 8}, {"rf": "full", "out": 10}]}))
    model = tmp_path / "m.sfa"
    assert cli.main(["train", "--dataset", str(ds.root), "--config", str(config), "--out", str(model),
                     "--no-progress"]) == 0
    out = tmp_path / "e.csv"
    assert cli.main(["localize", str(model), str(ds.root), "--run", "test", "--odometry", "--out", str(out),
                     "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "fused" in printed and "re-initialisations)" in printed
    rows = list(csv.DictReader(open(out)))
    assert list(rows[0]) == ["frame", "x", "y", "fused_x", "fused_y", "fused_heading"]
    assert len(rows) == int((ds.runs == "test").sum())
    # an image folder has no odometry: a clear usage error, no CSV
    folder = tmp_path / "imgs"
    folder.mkdir()
    for p in list(ds.image_paths)[:3]:
        (folder / p.name).write_bytes(p.read_bytes())
    with pytest.raises(SystemExit) as e:
        cli.main(["localize", str(model), str(folder), "--odometry", "--out", str(tmp_path / "f.csv"),
                  "--no-progress"])
    assert e.value.code == 2 and "needs a dataset with odometry" in capsys.readouterr().err
    assert not (tmp_path / "f.csv").exists()


def _smooth_bias(run, sigma, seed, width=60):
    """Estimates whose errors drift slowly along the run (what a readout's are), plus a little white noise."""
    rng = np.random.default_rng(seed)
    n = len(run["xy"])
    w = rng.normal(size=(n + 2 * width, 2))
    k = np.hanning(2 * width + 1)
    b = np.c_[np.convolve(w[:, 0], k, "same"), np.convolve(w[:, 1], k, "same")][width : width + n]
    return run["xy"] + sigma * b / b.std(axis=0) + 0.02 * rng.normal(size=(n, 2))


def test_noise_against_a_reference_map_handles_errors_correlated_in_time():
    train, test = make_odometry_run(random_state=1), make_odometry_run(random_state=2)
    Ztr, Zte = _smooth_bias(train, 0.15, 0), _smooth_bias(test, 0.15, 1)
    learned = train["xy"] + 0.03 * np.random.default_rng(2).normal(size=train["xy"].shape)  # a map, not the truth
    # this run's odometry errs per step, not per turn: the thesis's process model (turn_noise 0)
    by_map = noise_from_run(train["odometry"], Ztr, reference=learned, turn_noise=0.0)
    by_nll = noise_from_run(train["odometry"], Ztr, turn_noise=0.0)
    single = med(Zte, test["xy"])
    fused_map = med(fuse(test["odometry"], Zte, by_map)[:, :2], test["xy"])
    fused_nll = med(fuse(test["odometry"], Zte, by_nll)[:, :2], test["xy"])
    assert by_map["measurement_noise"] > by_nll["measurement_noise"]  # the likelihood trusts a smooth bias
    assert fused_map < 0.8 * single and fused_map < fused_nll, (single, fused_map, fused_nll)
    with pytest.raises(ValueError, match="reference"):
        noise_from_run(train["odometry"], Ztr, reference=learned[:-3])
