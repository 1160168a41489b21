"""A run without ground truth joined to a trained localizer's map
(sfanav.odometry.map_joining): a simulated garden (tiny panoramas) where run
A trains the model with ground truth and run B, whose odometry starts at an
unknown pose in its own frame and drifts, lands in A's map frame near its
truth; the model updated with B's learned positions localizes no worse than
the stale one; bad input is refused naming why."""

import numpy as np
import pytest
from sfanav import Network, Rotation, sim
from sfanav.data.preprocessing import Preprocessing
from sfanav.data.sources import load_run, select_run
from sfanav.localization.training import fit_localizer
from sfanav.localization.updates import LocalizerUpdater
from sfanav.sim import reframed_odometry

gtsam = pytest.importorskip("gtsam")

from sfanav.odometry.map_joining import drift_corrected, join_run, map_closures  # noqa: E402

CONFIG = {"input": {"width": 60, "height": 8, "channels": 3}, "network": {"precision": "double"},
          "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 10}, {"rf": "full", "out": 10}]}


def disguise(odo, theta=1.1, t=(7.0, -3.0), drift_deg_per_m=0.5, noise_deg=0.2, seed=0):
    """The run's odometry as a second drive reports it (sfanav.sim.reframed_odometry)."""
    return reframed_odometry(odo, (t[0], t[1], theta), drift_deg_per_m=drift_deg_per_m, heading_noise_deg=noise_deg,
                             seed=seed)


@pytest.fixture(scope="module")
def garden(tmp_path_factory):
    ds = sim.simulate("suite-small-dense", tmp_path_factory.mktemp("garden") / "d", seed=0,
                      camera=sim.PanoramicCamera(60, 8), progress=False)
    prep = Preprocessing(60, 8, False, False)
    out = {}
    for name in ("train-grid", "train-cross", "test-walk"):
        d = select_run(ds, name)
        X, Y = load_run(d, prep, progress=False)
        out[name] = (X, Y, d.odometry)
    XA, YA, _ = out["train-grid"]
    out["model"] = fit_localizer(Network(CONFIG), XA, YA, rotation=Rotation(step=4), readout="quadratic",
                                 n_outputs=8, progress=False, readout_memory=3000)
    out["root"] = ds.root
    return out


def _err(a, b):
    return np.hypot(*(np.asarray(a) - np.asarray(b)).T)


def test_a_run_without_ground_truth_lands_in_the_map_frame(garden):
    XB, YB, OB = garden["train-cross"]
    odo = disguise(OB)
    # the disguised odometry is far from the map frame and, even best aligned to the truth, drifts
    from sfanav.localization.error_metrics import align

    assert np.median(_err(odo[:, :2], YB)) > 3.0
    assert np.median(_err(align(odo[:, :2], YB).apply(odo[:, :2]), YB)) > 0.3
    joined = join_run(garden["model"], XB, odo)
    e = _err(joined.positions, YB)
    # measured 0.036 m median, 0.08 m max (suite-small-dense, 60x8)
    assert np.median(e) < 0.12 and e.max() < 0.4
    assert joined.positions.shape == (len(XB), 2) and joined.poses.shape == (len(XB), 3)
    assert joined.n_kept >= 0.8 * len(joined.closures) and joined.n_ransac_inliers >= 10
    assert joined.n_compass > 0 and joined.odometry_chi < 2.0
    kept = joined.weights >= 0.5
    assert np.median(joined.residuals[kept]) < 0.5
    # the initial alignment undid the disguise's 1.1 rad, up to the heading the odometry drifted over the run
    drifted = np.radians(0.5) * np.hypot(*np.diff(OB[:, :2], axis=0).T).sum()
    assert abs(np.angle(np.exp(1j * (joined.alignment[0] + 1.1)))) < drifted
    info = joined.info()
    assert info["map closures kept"] == joined.n_kept and info["solver"] == "lm"


def test_a_strong_systematic_drift_is_found_and_corrected(garden):
    XB, YB, OB = garden["train-cross"]
    joined = join_run(garden["model"], XB, disguise(OB, drift_deg_per_m=2.0))
    assert np.median(_err(joined.positions, YB)) < 0.12
    base = join_run(garden["model"], XB, disguise(OB, drift_deg_per_m=0.0))
    # the added 2 deg/m found, beside whatever drift the simulated odometry has of its own (measured 2.0)
    assert np.degrees(joined.drift_rate - base.drift_rate) == pytest.approx(2.0, abs=0.15)


def test_drift_correction_undoes_a_drift():
    rng = np.random.default_rng(1)
    odo = np.cumsum(np.c_[rng.uniform(0.1, 0.3, (50, 2)), rng.normal(0, 0.2, 50)], axis=0)
    odo = disguise(odo, 0.0, (0.0, 0.0), 0.0, 0.0)  # a consistent odometry: steps along its headings
    bent = disguise(odo, 0.3, (1.0, 2.0), 1.5, 0.0)
    straight = disguise(odo, 0.3, (1.0, 2.0), 0.0, 0.0)
    np.testing.assert_allclose(drift_corrected(bent, np.radians(1.5)), straight, atol=1e-9)
    np.testing.assert_allclose(drift_corrected(bent, 0.0), bent, atol=1e-12)


def test_isam2_joins_as_levenberg_marquardt_does(garden):
    XB, YB, OB = garden["train-cross"]
    odo = disguise(OB)
    lm = join_run(garden["model"], XB, odo, solver="lm")
    inc = join_run(garden["model"], XB, odo, solver="isam2", chunk=60)
    assert np.median(_err(inc.positions, YB)) < 0.12
    assert np.max(_err(inc.positions, lm.positions)) < 0.05


def test_the_updated_model_localizes_no_worse_than_the_stale_one(garden):
    XB, YB, OB = garden["train-cross"]
    XT, YT, _ = garden["test-walk"]
    stale = garden["model"]
    joined = join_run(stale, XB, disguise(OB))
    updated = LocalizerUpdater(stale).partial_fit(XB, joined.positions).localizer_
    truth = LocalizerUpdater(stale).partial_fit(XB, YB).localizer_
    s, u, t = stale.score(XT, YT), updated.score(XT, YT), truth.score(XT, YT)
    # measured: stale 0.493, joined 0.452, with ground truth 0.453 m
    assert u <= s + 0.02
    assert abs(u - t) < 0.03


def test_map_closures_find_places_by_their_views():
    # views on a line with features = position; a frame between two views matches their place
    Y = np.c_[np.arange(10.0), np.zeros(10)]
    V = np.c_[Y, np.zeros((10, 1))]
    F = np.array([[2.4, 0.0, 0.0], [50.0, 50.0, 0.0]])
    C = map_closures(F, V, Y, n_neighbors=2, max_spread=1.0, min_sigma=0.1)
    np.testing.assert_array_equal(C.frame, [0, 1])  # the far frame's neighbours also agree (8, 9)
    np.testing.assert_allclose(C.position[0], [2.5, 0.0])
    np.testing.assert_allclose(C.sigma[0], 0.5)
    C = map_closures(F, V, Y, n_neighbors=3, max_spread=0.5)  # three neighbours spread 0.82 m: no closure
    assert len(C) == 0
    with pytest.raises(ValueError, match="same number of columns"):
        map_closures(F[:, :2], V, Y)


def test_bad_input_is_refused_naming_why(garden):
    XB, YB, OB = garden["train-cross"]
    loc = garden["model"]
    odo = disguise(OB)
    with pytest.raises(ValueError, match="no odometry"):
        join_run(loc, XB, None)
    with pytest.raises(ValueError, match="must match"):
        join_run(loc, XB[:-5], odo)
    with pytest.raises(ValueError, match="odometry"):
        join_run(loc, XB, odo[:, :2])
    with pytest.raises(ValueError, match="solver"):
        join_run(loc, XB, odo, solver="magic")
    # images of nowhere (noise): their views scatter over the map, no placement agrees
    rng = np.random.default_rng(0)
    noise = rng.uniform(0, XB.max(), XB[:120].shape)
    with pytest.raises(ValueError, match="no closures to the map found"):
        join_run(loc, noise, odo[:120])
    # odometry that does not belong to the images (shuffled): the matches agree on no placement beyond chance
    with pytest.raises(ValueError, match="agree on one placement"):
        join_run(loc, XB, odo[rng.permutation(len(odo))])
    # a localizer without its map's views
    plain = fit_localizer(Network(CONFIG), *garden["train-grid"][:2], rotation=Rotation(step=10),
                          readout="quadratic", n_outputs=5, progress=False)
    with pytest.raises(ValueError, match="readout memory"):
        join_run(plain, XB, odo)


def test_cli_update_joins_a_run_with_odometry_only(garden, tmp_path, capsys):
    import csv
    import json
    import shutil

    import sfanav
    from clitools import assert_one_line_error, run

    root = garden["root"]
    # run A with ground truth -> an updatable model; run B with its x, y blanked, odometry disguised
    (tmp_path / "net.json").write_text(json.dumps(CONFIG))
    model = tmp_path / "loc.sfanav"
    code, out, err = run(capsys, "train", "--dataset", root, "--run", "train-grid", "--out", model, "--updatable",
                         "--config", tmp_path / "net.json", "--readout", "quadratic", "--n-outputs", "8",
                         "--step", "4", "--no-progress")
    assert code == 0, err
    original = model.read_bytes()
    b = tmp_path / "b"
    shutil.copytree(root, b)
    ds = sfanav.Dataset(b)
    m = ds.runs == "train-cross"
    odo = disguise(ds.odometry[m])
    rows = list(csv.reader(open(b / "frames.csv", newline="")))
    head = rows[0]
    cx, cy = head.index("x"), head.index("y")
    ox, oy, oh = (head.index(c) for c in ("odom_x", "odom_y", "odom_heading"))
    k = 0
    for r, sel in zip(rows[1:], m):
        r[cx] = r[cy] = ""
        if sel:
            r[ox], r[oy], r[oh] = (repr(float(v)) for v in odo[k])
            k += 1
    with open(b / "frames.csv", "w", newline="") as f:
        csv.writer(f).writerows(rows)
    code, out, err = run(capsys, "update", model, "--dataset", b, "--run", "train-cross",
                         "--out", tmp_path / "new.sfanav", "--no-progress")
    assert code == 0, err
    assert "no ground-truth x, y: joining" in err and "closures to the map kept" in err
    assert model.read_bytes() == original
    new = sfanav.load(tmp_path / "new.sfanav")
    assert new.info["updates"][-1]["joined"]["map closures kept"] >= 10
    XT, YT, _ = garden["test-walk"]
    assert new.score(XT, YT) <= garden["model"].score(XT, YT) + 0.05
    # neither x, y nor odometry: refused in one line, MODEL as it was
    rows = list(csv.reader(open(b / "frames.csv", newline="")))
    for r in rows[1:]:
        r[ox] = r[oy] = r[oh] = ""
    with open(b / "frames.csv", "w", newline="") as f:
        csv.writer(f).writerows(rows)
    code, out, err = run(capsys, "update", model, "--dataset", b, "--run", "train-cross",
                         "--out", tmp_path / "bad.sfanav")
    assert_one_line_error(code, err, "neither ground-truth", "odometry")
    assert not (tmp_path / "bad.sfanav").exists() and model.read_bytes() == original


def test_a_model_trained_without_ground_truth_is_updatable_and_joins_a_run(garden):
    """The training recipe without ground truth keeps a readout memory of the
    learned positions (the model's odometry frame); a second run joins it."""
    from sfanav.localization.recipe import recipe_for
    from sfanav.pipeline import train_localizer

    XA, _, OA = garden["train-grid"]
    loc = train_localizer(XA, odometry=OA, network=Network(CONFIG), recipe=recipe_for(config=True, readout="quadratic",
                                                                                    robustness="none"),
                          rotation=Rotation(step=4), readout_memory=3000)
    assert loc.info["supervision"] == "odometry" and loc.readout_memory_ is not None
    np.testing.assert_allclose(loc.readout_memory_.positions, loc.training_positions_, atol=1e-9)
    XB, _, OB = garden["train-cross"]
    joined = join_run(loc, XB, OB)
    assert joined.poses.shape == (len(XB), 3) and len(joined.closures) > 0


def test_reframed_odometry_keeps_steps_and_turns():
    """Re-integrated from another start without drift or noise, the odometry
    is the same path moved rigidly; a drift bends it; bad input is refused."""
    rng = np.random.default_rng(3)
    h = np.cumsum(rng.normal(0, 0.2, 40))
    xy = np.cumsum(np.c_[np.cos(h), np.sin(h)] * 0.5, axis=0)
    odo = np.c_[xy, h]
    out = sim.reframed_odometry(odo, (2.0, -1.0, 0.7), drift_deg_per_m=0.0, heading_noise_deg=0.0)
    a = 0.7 - h[0]
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    np.testing.assert_allclose(out[:, :2], (xy - xy[0]) @ R.T + [2.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(out[:, 2], h + a, atol=1e-9)
    bent = sim.reframed_odometry(odo, (2.0, -1.0, 0.7), drift_deg_per_m=2.0, heading_noise_deg=0.0)
    d = np.hypot(*np.diff(xy, axis=0).T)
    np.testing.assert_allclose(bent[-1, 2] - out[-1, 2], np.radians(2.0) * d.sum(), atol=1e-9)
    with pytest.raises(ValueError, match="shape"):
        sim.reframed_odometry(odo[:, :2])


def test_a_gyro_steadies_a_run_whose_odometry_turns_badly(garden):
    """The run's odometry with 1.5 deg of heading noise per frame and a
    0.5 deg/m drift: fused with a simulated yaw gyro (the true turns plus
    its own small noise) the joined positions are closer to the truth than
    without it, with iSAM2 as well."""
    from sfanav import Dataset
    from sfanav.sim.robot import GyroNoise, simulate_gyro

    XB, YB, OB = garden["train-cross"]
    d = select_run(Dataset(garden["root"]), "train-cross")
    truth = d.poses
    gyro = simulate_gyro(truth, np.arange(len(truth)) * 0.5, GyroNoise(), rng=3)
    odo = disguise(OB, noise_deg=1.5, seed=4)
    plain = join_run(garden["model"], XB, odo, solver="isam2", chunk=60)
    steady = join_run(garden["model"], XB, odo, gyro=gyro, solver="isam2", chunk=60)
    e_plain, e_gyro = _err(plain.positions, YB), _err(steady.positions, YB)
    assert np.median(e_gyro) < np.median(e_plain) and np.median(e_gyro) < 0.12
    with pytest.raises(ValueError, match="gyro"):
        join_run(garden["model"], XB, odo, gyro=gyro[:-1])
