"""The community's trajectory evaluation: TUM files (sfanav.data.tum,
``sfanav localize --out NAME.tum``) and evo's APE / RPE
(sfanav.localization.trajectory_metrics), with evo (PyPI ``evo``, a test
dependency) as the independent reference for the files, the rigid alignment
and the errors."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sfanav.data.tum import read_tum, stamp_text, tum_text, write_tum
from sfanav.localization import align
from sfanav.localization.trajectory_metrics import ape, rpe, trajectory_errors

evo_trajectory = pytest.importorskip("evo.core.trajectory")
from evo.core import metrics  # noqa: E402
from evo.tools import file_interface  # noqa: E402


def _rot(a):
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def _evo_traj(xy, heading=None, stamps=None):
    n = len(xy)
    h = np.zeros(n) if heading is None else np.asarray(heading, float)
    xyz = np.column_stack([xy, np.zeros(n)])
    quat_wxyz = np.column_stack([np.cos(h / 2), np.zeros(n), np.zeros(n), np.sin(h / 2)])
    return evo_trajectory.PoseTrajectory3D(xyz, quat_wxyz, np.arange(n, dtype=float) if stamps is None else stamps)


def _evo_errors(est, ref, est_h=None, ref_h=None, delta=1):
    e, r = _evo_traj(est, est_h), _evo_traj(ref, ref_h)
    e.align(r, correct_scale=False)
    a = metrics.APE(metrics.PoseRelation.translation_part)
    a.process_data((r, e))
    p = metrics.RPE(metrics.PoseRelation.translation_part, delta=delta, delta_unit=metrics.Unit.frames)
    p.process_data((r, e))
    return a.get_all_statistics(), p.get_all_statistics(), e


def _random_run(seed, n=40):
    rng = np.random.default_rng(seed)
    xy = np.cumsum(rng.normal(size=(n, 2)), axis=0)
    return rng, xy, rng.uniform(-np.pi, np.pi, n)


# --- TUM files ------------------------------------------------------------------------------------------------


def test_tum_round_trip_through_evo_with_exact_stamps(tmp_path):
    rng, xy, h = _random_run(0, 25)
    stamps = 1_700_000_000_000_000_000 + np.cumsum(rng.integers(1, 10**9, 25)).astype(np.int64)
    stamps[3] = stamps[2] + 1  # one nanosecond apart
    path = write_tum(tmp_path / "est.tum", stamps, xy, h)
    lines = path.read_text().splitlines()
    assert lines[0].startswith("#") and len(lines) == 26
    # the text holds every stamp exactly, to the nanosecond
    assert [ln.split()[0] for ln in lines[1:]] == [stamp_text(s) for s in stamps]
    ns, xyz, quat = read_tum(path)
    np.testing.assert_array_equal(ns, stamps)
    np.testing.assert_array_equal(xyz[:, :2], xy)
    assert (xyz[:, 2] == 0).all()
    # evo reads the same file: the float64 nearest each exact stamp, the positions, the headings
    traj = file_interface.read_tum_trajectory_file(str(path))
    np.testing.assert_array_equal(traj.timestamps, [float(ln.split()[0]) for ln in lines[1:]])
    np.testing.assert_allclose(traj.timestamps, stamps / 1e9, rtol=0, atol=5e-7)
    np.testing.assert_array_equal(traj.positions_xyz[:, :2], xy)
    yaw = np.array([np.arctan2(T[1, 0], T[0, 0]) for T in traj.poses_se3])
    np.testing.assert_allclose(np.angle(np.exp(1j * (yaw - h))), 0, atol=1e-12)
    # small stamps (a simulated run) come back exact through evo's floats too
    small = np.arange(25, dtype=np.int64) * 625_000_001
    write_tum(tmp_path / "s.tum", small, xy)
    traj = file_interface.read_tum_trajectory_file(str(tmp_path / "s.tum"))
    np.testing.assert_array_equal(np.round(traj.timestamps * 1e9).astype(np.int64), small)
    # without headings: the identity rotation
    np.testing.assert_array_equal(read_tum(tmp_path / "s.tum")[2], np.tile([0.0, 0, 0, 1], (25, 1)))


def test_stamp_text_is_exact_and_signed():
    assert stamp_text(1_700_000_000_123_456_789) == "1700000000.123456789"
    assert stamp_text(0) == "0.000000000"
    assert stamp_text(-1) == "-0.000000001"
    assert stamp_text(-1_500_000_000) == "-1.500000000"
    assert stamp_text(np.iinfo(np.int64).max) == "9223372036.854775807"


def test_write_tum_is_atomic_and_refuses_bad_input(tmp_path):
    path = tmp_path / "e.tum"
    path.write_text("old\n")
    xy = np.zeros((3, 2)) + [[0, 0], [1, 0], [2, 0]]
    with pytest.raises(ValueError, match="increase"):
        write_tum(path, np.array([0, 2, 2]), xy)
    with pytest.raises(ValueError, match="NaN"):
        write_tum(path, np.arange(3), np.array([[0, 0], [np.nan, 0], [1, 1.0]]))
    with pytest.raises(ValueError, match="shape"):
        write_tum(path, np.arange(4), xy)
    with pytest.raises(ValueError, match="heading"):
        write_tum(path, np.arange(3), xy, [0.0, np.nan, 0.0])
    with pytest.raises(TypeError, match="integers"):
        write_tum(path, np.arange(3) * 0.5, xy)
    with pytest.raises(ValueError, match="unit"):
        write_tum(path, np.arange(3), xy, unit="ms")
    with pytest.raises(FileExistsError):
        write_tum(path, np.arange(3), xy, overwrite=False)
    assert path.read_text() == "old\n"  # every failure left what was there
    assert not list(tmp_path.glob(".*part"))
    # float seconds, nine decimals
    assert tum_text(np.array([0.5, 1.25]), xy[:2], unit="s").splitlines()[1:] == [
        "0.500000000 0.0 0.0 0 0 0 0.0 1.0", "1.250000000 1.0 0.0 0 0 0 0.0 1.0"]
    bad = tmp_path / "bad.tum"
    bad.write_text("# c\n1.0 2 3 0 0 0 0\n")
    with pytest.raises(ValueError, match="line 2"):
        read_tum(bad)


# --- the rigid alignment against evo's Umeyama -----------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(angle=st.floats(-np.pi, np.pi), tx=st.floats(-100, 100), ty=st.floats(-100, 100),
       noise=st.floats(0, 0.5), n=st.integers(3, 60), seed=st.integers(0, 2**32 - 1))
def test_rigid_alignment_agrees_with_evo_umeyama(angle, tx, ty, noise, n, seed):
    rng = np.random.default_rng(seed)
    ref = np.cumsum(rng.normal(size=(n, 2)), axis=0) * 3
    est = (ref - [tx, ty]) @ _rot(angle) + noise * rng.normal(size=(n, 2))  # a rotated, shifted, noisy copy
    a = align(est, ref)
    e, r = _evo_traj(est), _evo_traj(ref)
    R3, t3, s = e.align(r, correct_scale=False)
    assert s == 1.0
    # evo's 3-D rotation of planar data: about z, or a half turn about a horizontal axis (a mirror in x, y) where
    # the best proper 2-D rotation fits worse than a mirror; the random copies here are never mirrored enough
    if np.linalg.det(R3[:2, :2]) > 0:
        np.testing.assert_allclose(R3[:2, :2], a.rotation, atol=1e-9)
        np.testing.assert_allclose(t3[:2], a.translation, atol=1e-9 * (1 + np.abs(ref).max()))
        np.testing.assert_allclose(e.positions_xyz[:, :2], a.apply(est), atol=1e-9 * (1 + np.abs(ref).max()))
        assert np.abs(e.positions_xyz[:, 2]).max() < 1e-9
    else:  # pragma: no cover - a mirror fits better than any rotation: evo mirrors, sfanav does not
        assert a.rmse >= np.sqrt(np.mean(np.sum((e.positions_xyz[:, :2] - ref) ** 2, axis=1))) - 1e-9


def test_evo_mirrors_a_mirrored_estimate_and_sfanav_does_not():
    """Planar data in 3-D: evo's proper rotation can be a half turn about a horizontal axis, a mirror of x, y
    (z = 0 everywhere); sfanav's 2-D rigid alignment stays a rotation (allow_reflection=False)."""
    _, ref, _ = _random_run(5)
    est = ref * [1, -1]
    e, r = _evo_traj(est), _evo_traj(ref)
    R3, _, _ = e.align(r, correct_scale=False)
    assert np.linalg.det(R3[:2, :2]) < 0 and np.allclose(e.positions_xyz[:, :2], ref, atol=1e-9)
    a = align(est, ref)
    assert np.linalg.det(a.rotation) > 0 and a.rmse > 1.0
    assert ape(est, ref)["rmse"] == pytest.approx(a.rmse, rel=1e-12)


# --- APE and RPE against evo ------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("delta", [1, 3])
def test_ape_rpe_equal_evos(seed, delta):
    rng, ref, href = _random_run(seed)
    est = (ref + 0.3 * rng.normal(size=ref.shape)) @ _rot(2.0).T + [5, -7]
    hest = href + 2.0 + 0.05 * rng.normal(size=len(ref))
    ev_ape, ev_rpe, _ = _evo_errors(est, ref, delta=delta)  # positions only: identity rotations
    a, r = ape(est, ref), rpe(est, ref, delta=delta)
    ev_ape_h, ev_rpe_h, _ = _evo_errors(est, ref, hest, href, delta=delta)  # SE(2) poses
    rh = rpe(est, ref, estimate_heading=hest, reference_heading=href, delta=delta)
    for k in ("rmse", "mean", "median", "max"):
        assert a[k] == pytest.approx(ev_ape[k], rel=1e-9, abs=1e-12)
        assert a[k] == pytest.approx(ev_ape_h[k], rel=1e-9, abs=1e-12)  # headings do not change APE
        assert r[k] == pytest.approx(ev_rpe[k], rel=1e-9, abs=1e-12)
        assert rh[k] == pytest.approx(ev_rpe_h[k], rel=1e-9, abs=1e-12)
    assert a["n"] == len(ref) and r["n"] == len(range(0, len(ref), delta)) - 1
    # evo's alignment turns the poses, rotations included: no relative pose changes, with or without headings
    e, rr = _evo_traj(est), _evo_traj(ref)
    p = metrics.RPE(metrics.PoseRelation.translation_part, delta=delta, delta_unit=metrics.Unit.frames)
    p.process_data((rr, e))
    assert p.get_statistic(metrics.StatisticsType.rmse) == pytest.approx(r["rmse"], rel=1e-9)
    t = trajectory_errors(est, ref, delta=delta)
    assert t["ape_rmse"] == a["rmse"] and t["rpe_max"] == r["max"] and t["n"] == len(ref)


def test_perfect_estimate_has_zero_errors():
    _, ref, h = _random_run(3)
    moved = ref @ _rot(-1.1).T + [100, 40]  # in another frame: the alignment finds it
    assert ape(moved, ref)["max"] < 1e-9
    assert rpe(ref, ref)["max"] == 0.0
    assert rpe(moved, ref, estimate_heading=h - 1.1, reference_heading=h)["max"] < 1e-9
    # without headings each step is compared in its own frame: a frame turned by a gives 2 sin(a / 2) per metre
    steps = np.linalg.norm(np.diff(ref, axis=0), axis=1)
    np.testing.assert_allclose(rpe(moved, ref)["max"], 2 * np.sin(1.1 / 2) * steps.max(), rtol=1e-12)
    assert ape(ref, ref, align=False) == {"rmse": 0.0, "mean": 0.0, "median": 0.0, "max": 0.0, "n": len(ref)}


def test_analytic_ape_and_rpe():
    ref = np.array([[0.0, 0], [1, 0], [2, 0], [3, 0]])
    # a constant offset: aligned away (APE 0); unaligned every error is 0.5, the MED
    assert ape(ref + [0, 0.5], ref)["max"] < 1e-12
    assert ape(ref + [0, 0.5], ref, align=False) == pytest.approx({"rmse": 0.5, "mean": 0.5, "median": 0.5,
                                                                   "max": 0.5, "n": 4})
    # e, -e, -e, e across the line: no mean, no trend, so the alignment leaves it, APE e everywhere; the steps
    # change the cross-track error by -2e, 0, 2e: RPE errors 2e, 0, 2e
    e = 0.1
    est = ref + np.c_[np.zeros(4), [e, -e, -e, e]]
    assert ape(est, ref) == pytest.approx({"rmse": e, "mean": e, "median": e, "max": e, "n": 4}, abs=1e-12)
    assert rpe(est, ref) == pytest.approx({"rmse": 2 * e * np.sqrt(2 / 3), "mean": 4 * e / 3, "median": 2 * e,
                                           "max": 2 * e, "n": 3}, abs=1e-12)
    # steps of 1 m estimated as 1.5 m: 0.5 m per frame, 1.0 m per two frames
    est = ref * 1.5
    assert rpe(est, ref)["mean"] == pytest.approx(0.5)
    assert rpe(est, ref, delta=2) == pytest.approx({"rmse": 1.0, "mean": 1.0, "median": 1.0,
                                                                 "max": 1.0, "n": 1})
    # headings: the estimate turned by 90 degrees at pose 0 sees its 1 m step sideways: RPE sqrt(2) there
    h = np.zeros(4)
    he = np.array([np.pi / 2, 0, 0, 0])
    r = rpe(ref, ref, estimate_heading=he, reference_heading=h)
    assert r["max"] == pytest.approx(np.sqrt(2)) and r["median"] == pytest.approx(0.0, abs=1e-12)


def test_bad_input_raises_value_error():
    ref = np.array([[0.0, 0], [1, 0], [2, 1]])
    with pytest.raises(ValueError, match="rows"):
        ape(ref[:2], ref)
    with pytest.raises(ValueError, match="NaN"):
        ape(np.array([[0.0, 0], [np.nan, 0], [2, 1]]), ref)
    with pytest.raises(ValueError, match="NaN"):
        rpe(ref, ref, estimate_heading=[0, np.nan, 0], reference_heading=[0, 0, 0])
    with pytest.raises(ValueError, match="columns"):
        ape(np.zeros((3, 3)), ref)
    with pytest.raises(ValueError, match="both"):
        rpe(ref, ref, estimate_heading=[0, 0, 0])
    with pytest.raises(ValueError, match="shape"):
        rpe(ref, ref, estimate_heading=[0, 0], reference_heading=[0, 0, 0])
    with pytest.raises(ValueError, match="delta"):
        rpe(ref, ref, delta=3)
    with pytest.raises(ValueError, match="delta"):
        rpe(ref, ref, delta=0)
    with pytest.raises(ValueError, match="single point"):
        ape(np.ones((3, 2)), ref)


# --- the command line --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    from clitools import tiny_dataset
    from sfanav.app.cli import main

    root = tmp_path_factory.mktemp("evo")
    ds, cfg = tiny_dataset(root)
    model = root / "tiny.sfa"
    assert main(["train", "--dataset", str(root / "data"), "--config", str(cfg), "--out", str(model),
                 "--no-progress"]) == 0
    return {"root": root, "ds": ds, "model": model}


def test_cli_writes_tum_estimates_and_ground_truth_that_evo_reads(tiny, tmp_path, capsys):
    import csv

    from clitools import run

    test = tiny["ds"].select(run="test")
    code, out, err = run(capsys, "localize", tiny["model"], tiny["root"] / "data", "--run", "test",
                         "--out", tmp_path / "e.tum", "--out", tmp_path / "e.csv",
                         "--out-ground-truth", tmp_path / "gt.tum", "--no-progress")
    assert code == 0, err
    assert "MED" in out and "APE rmse" in out and "RPE rmse" in out
    rows = list(csv.DictReader(open(tmp_path / "e.csv")))
    est = file_interface.read_tum_trajectory_file(str(tmp_path / "e.tum"))
    gt = file_interface.read_tum_trajectory_file(str(tmp_path / "gt.tum"))
    assert est.num_poses == gt.num_poses == len(test)
    np.testing.assert_array_equal(est.timestamps, test.timestamps)
    np.testing.assert_array_equal(gt.timestamps, est.timestamps)
    np.testing.assert_allclose(est.positions_xyz[:, :2], [[float(r["x"]), float(r["y"])] for r in rows], atol=1e-4)
    np.testing.assert_array_equal(gt.positions_xyz[:, :2], test.poses[:, :2])
    for T in est.poses_se3 + gt.poses_se3:  # single-image estimates: identity rotations, and the truth beside them
        np.testing.assert_array_equal(T[:3, :3], np.eye(3))
    # evo's numbers on the files are the ones localize printed (evo's 3-D Umeyama refuses this tiny model's
    # estimates as a degenerate covariance, sfanav's 2-D one fits them: compare the RPE, which needs no alignment)
    m = metrics.RPE(metrics.PoseRelation.translation_part, delta=1, delta_unit=metrics.Unit.frames)
    m.process_data((gt, est))
    assert f"RPE rmse {m.get_statistic(metrics.StatisticsType.rmse):.3f} m" in out
    # an existing file without --overwrite; several runs (times restart); a CSV name for the truth
    code, _, err = run(capsys, "localize", tiny["model"], tiny["root"] / "data", "--run", "test",
                       "--out", tmp_path / "e.tum", "--no-progress")
    assert code == 2 and "--overwrite" in err
    code, _, err = run(capsys, "localize", tiny["model"], tiny["root"] / "data", "--out", tmp_path / "all.tum",
                       "--no-progress")
    assert code == 2 and "--run" in err and not (tmp_path / "all.tum").exists()
    code, _, err = run(capsys, "localize", tiny["model"], tiny["root"] / "data", "--run", "test",
                       "--out", tmp_path / "x.csv", "--out-ground-truth", tmp_path / "gt.csv", "--no-progress")
    assert code == 2 and "TUM" in err and not (tmp_path / "x.csv").exists()
    code, _, err = run(capsys, "localize", tiny["model"], tiny["root"] / "data", "--run", "test",
                       "--out", tmp_path / "x.tum", "--tum-track", "fused", "--no-progress")
    assert code == 2 and "--odometry" in err


def test_cli_fused_track_as_tum_with_headings_matches_evo(tiny, tmp_path, capsys):
    from clitools import run

    test = tiny["ds"].select(run="test")
    code, out, err = run(capsys, "localize", tiny["model"], tiny["root"] / "data", "--run", "test", "--odometry",
                         "--out", tmp_path / "f.tum", "--out-ground-truth", tmp_path / "g.tum", "--no-progress")
    assert code == 0, err
    assert "images farther from the training run than its own images are" in out + err  # the novelty's summary
    est = file_interface.read_tum_trajectory_file(str(tmp_path / "f.tum"))
    gt = file_interface.read_tum_trajectory_file(str(tmp_path / "g.tum"))
    # beside the fused track (headings) the truth carries its heading
    yaw = np.array([np.arctan2(T[1, 0], T[0, 0]) for T in gt.poses_se3])
    np.testing.assert_allclose(np.angle(np.exp(1j * (yaw - test.poses[:, 2]))), 0, atol=1e-12)
    assert not all(np.allclose(T[:3, :3], np.eye(3)) for T in est.poses_se3)
    fused = out.split("fused: ")[1]
    m = metrics.RPE(metrics.PoseRelation.translation_part, delta=1, delta_unit=metrics.Unit.frames)
    m.process_data((gt, est))
    assert f"RPE rmse {m.get_statistic(metrics.StatisticsType.rmse):.3f} m" in fused
    est.align(gt, correct_scale=False)
    m = metrics.APE(metrics.PoseRelation.translation_part)
    m.process_data((gt, est))
    assert f"APE rmse {m.get_statistic(metrics.StatisticsType.rmse):.3f} m" in fused
