"""Training without ground truth: positions learned from a run's odometry
(sfanav.odometry.self_supervision, sfanav train --supervision)."""

import csv
import json
import shutil

import numpy as np
import pytest
import sfanav
from sfanav import sim
from sfanav.app import cli
from sfanav.experiments.synthetic_odometry import make_odometry_run
from sfanav.localization import align, med
from sfanav.localization.recipe import supervision_for
from sfanav.odometry import OdometryMapWarning, learn_positions


@pytest.fixture(scope="module")
def run():
    return make_odometry_run(n_legs=12, random_state=3)


def test_learned_positions_match_the_ground_truth_up_to_a_rigid_motion(run):
    lp = learn_positions(run["features"], run["odometry"])
    assert lp.positions.shape == (len(run["xy"]), 2) and np.isfinite(lp.positions).all()
    assert lp.lines.n_lines >= 5 and not lp.warnings
    # evaluation only: a rigid transform (no scale) to the world
    err = med(align(lp.positions, run["xy"]).apply(lp.positions), run["xy"])
    assert err < 0.15, err
    # the positions are in the frame of the odometry's first pose: on the first line, before the odometry
    # drifts, the best rigid fit to it is the identity and they agree
    first = np.flatnonzero(lp.lines.labels == 0)
    again = align(lp.positions[first], run["odometry"][first, :2])
    np.testing.assert_allclose(again.rotation, np.eye(2), atol=1e-9)
    np.testing.assert_allclose(again.translation, 0, atol=1e-9)
    assert med(lp.positions[first], run["odometry"][first, :2]) < 0.15
    # better than the drifting odometry itself
    assert err < med(align(run["odometry"][:, :2], run["xy"]).apply(run["odometry"][:, :2]), run["xy"])
    info = lp.info()
    assert info["supervision"] == "odometry" and info["lines"] == lp.lines.n_lines


def test_learned_positions_do_not_depend_on_anything_but_features_and_odometry(run):
    a = learn_positions(run["features"], run["odometry"]).positions
    b = learn_positions(run["features"].copy(), run["odometry"].copy()).positions
    np.testing.assert_array_equal(a, b)


def test_bad_odometry_is_refused_with_a_clear_error(run):
    F, P = run["features"], run["odometry"].copy()
    bad = P.copy()
    bad[5, 0] = np.nan
    with pytest.raises(ValueError, match="odometry"):
        learn_positions(F, bad)
    with pytest.raises(ValueError, match="does not move"):
        learn_positions(F, np.zeros_like(P))
    with pytest.raises(ValueError, match="must match|same length|rows"):
        learn_positions(F[:-3], P)
    with pytest.raises(ValueError, match="only 8 columns"):
        learn_positions(F, P, n_outputs=9)


def test_a_run_of_one_straight_line_cannot_fix_the_map():
    n = 200
    P = np.c_[np.linspace(0, 5, n), np.zeros(n), np.zeros(n)]
    F = np.random.default_rng(0).normal(size=(n, 8))
    with pytest.raises(ValueError, match="straight line segment"):
        learn_positions(F, P)


def test_parallel_lines_warn_that_the_map_is_not_fixed():
    # back and forth along x: every line has one direction
    legs = []
    for k in range(4):
        x = np.linspace(0, 4, 80) if k % 2 == 0 else np.linspace(4, 0, 80)
        th = 0.0 if k % 2 == 0 else np.pi
        legs.append(np.c_[x, np.full(80, 0.5 * k), np.full(80, th)])
        legs.append(np.c_[np.full(8, x[-1]), np.linspace(0.5 * k, 0.5 * k + 0.5, 8), np.linspace(th, th + np.pi, 8)])
    P = np.concatenate(legs)
    from sfanav.experiments.synthetic_odometry import synthetic_features

    F = synthetic_features(P[:, :2], area=(4.0, 2.0), noise=0.01)
    with pytest.warns(OdometryMapWarning, match="parallel"):
        lp = learn_positions(F, P)
    assert any("parallel" in w for w in lp.warnings)


def test_supervision_policy():
    assert supervision_for("auto", has_ground_truth=True, has_odometry=True) == "ground-truth"
    assert supervision_for(None, has_ground_truth=False, has_odometry=True) == "odometry"
    assert supervision_for("odometry", has_ground_truth=True, has_odometry=True) == "odometry"
    with pytest.raises(ValueError, match="supervision 'odometry'"):
        supervision_for("ground-truth", has_ground_truth=False, has_odometry=True)
    with pytest.raises(ValueError, match="lacks odometry"):
        supervision_for("odometry", has_ground_truth=True, has_odometry=False)
    with pytest.raises(ValueError, match="neither"):
        supervision_for("auto", has_ground_truth=False, has_odometry=False)
    with pytest.raises(ValueError, match="one of"):
        supervision_for("gps", has_ground_truth=True, has_odometry=True)


def _without_ground_truth(src, dst):
    shutil.copytree(src, dst)
    rows = list(csv.reader(open(dst / "frames.csv", newline="")))
    head = rows[0]
    cols = [head.index(c) for c in ("x", "y", "heading")]
    for r in rows[1:]:
        for c in cols:
            r[c] = ""
    with open(dst / "frames.csv", "w", newline="") as f:
        csv.writer(f).writerows(rows)


TINY = {"input": {"width": 70, "height": 8, "channels": 3}, "network": {"precision": "mixed"},
        "layers": [{"rf": [7, 4], "stride": [3, 4], "out": 8}, {"rf": "full", "out": 10}]}


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    return sim.simulate("demo", tmp_path_factory.mktemp("demo") / "d", 0, camera=sim.PanoramicCamera(70, 8),
                        progress=False)


def test_experiment_rows_without_ground_truth(demo):
    from sfanav.data import Preprocessing, load_run
    from sfanav.experiments.localization import no_ground_truth_rows
    from sfanav.localization import fit_localizer

    prep = Preprocessing(70, 8, False)
    X, xy = load_run(demo.select(run="train"), prep, progress=False)
    Xt, xyt = load_run(demo.select(run="test"), prep, progress=False)
    loc = fit_localizer(sfanav.Network(TINY), X, xy, progress=False)
    sup = med(loc.predict(Xt), xyt)
    rows, note = no_ground_truth_rows(loc, demo, (X, xy, Xt, xyt), suffix=" [tiny]", supervised_med=sup)
    by = {r["metric"]: r["sfanav"] for r in rows}
    assert set(by) >= {"MED (m) [tiny, no ground truth]", "MED ratio no ground truth / ground truth [tiny, no ground truth]"}
    assert np.isfinite(by["MED (m) [tiny, no ground truth]"]) and by["loop closures kept [tiny, no ground truth]"] >= 10
    # the thesis's metric learning beside the pose graph, same readout
    assert np.isfinite(by["MED (m) [tiny, no ground truth, metric learning]"])
    assert by["straight lines of the odometry [tiny, no ground truth, metric learning]"] >= 3
    assert by["MED ratio no ground truth / ground truth [tiny, no ground truth]"] == pytest.approx(
        by["MED (m) [tiny, no ground truth]"] / sup)
    assert "odometry" in note and "rigid" in note


def test_cli_trains_without_ground_truth_and_gets_the_same_model_as_with_it(tmp_path, capsys, demo):
    ds = demo
    _without_ground_truth(ds.root, tmp_path / "nogt")
    assert not np.isfinite(sfanav.Dataset(tmp_path / "nogt").poses[:, :2]).any()
    config = tmp_path / "net.json"
    config.write_text(json.dumps(TINY))
    common = ["--config", str(config), "--no-progress"]
    a, b = tmp_path / "a.sfa", tmp_path / "b.sfa"
    assert cli.main(["train", "--dataset", str(ds.root), "--supervision", "odometry", "--out", str(a), *common]) == 0
    assert cli.main(["train", "--dataset", str(tmp_path / "nogt"), "--out", str(b), *common]) == 0  # auto: odometry
    out = capsys.readouterr().out
    assert "to the learned positions" in out
    la, lb = sfanav.load(a), sfanav.load(b)
    assert la.info["supervision"] == lb.info["supervision"] == "odometry"
    assert "odometry" in la.info["frame"] and la.info["lines"] >= 3
    assert la.info["metric map"] == "pose-graph" and la.info["loop closures kept"] >= 10
    test = ds.select(run="test")
    from sfanav.data import Preprocessing, load_run

    X, xy = load_run(test, Preprocessing.of_model(la), progress=False)
    np.testing.assert_allclose(la.predict(X), lb.predict(X), rtol=0, atol=1e-9)
    # ground truth is used here for evaluation only
    X_tr, xy_tr = load_run(ds.select(run="train"), Preprocessing.of_model(la), progress=False)
    al = align(la.predict(X_tr), xy_tr)
    assert med(al.apply(la.predict(X)), xy) < 2.0
    # localize says which frame; evaluate aligns the frames on the training run (evaluation only)
    assert cli.main(["localize", str(a), str(ds.root), "--run", "test", "--out", str(tmp_path / "e.csv"),
                     "--no-progress"]) == 0
    assert "odometry frame" in capsys.readouterr().out
    assert cli.main(["evaluate", str(a), str(ds.root), "--out", str(tmp_path / "rep"), "--no-baselines",
                     "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert "world frame by the rigid transform fitted on the training run" in captured.err
    metrics = json.loads((tmp_path / "rep" / "metrics.json").read_text())
    assert metrics["test_run"]["med"] == pytest.approx(med(al.apply(la.predict(X)), xy), rel=1e-6)


def test_cli_ground_truth_supervision_needs_ground_truth(tmp_path, capsys):
    ds = sim.simulate("demo", tmp_path / "d", 0, max_frames=30, camera=sim.PanoramicCamera(70, 8), progress=False)
    _without_ground_truth(ds.root, tmp_path / "nogt")
    with pytest.raises(SystemExit) as e:
        cli.main(["train", "--dataset", str(tmp_path / "nogt"), "--supervision", "ground-truth",
                  "--out", str(tmp_path / "m.sfa"), "--no-progress"])
    assert e.value.code == 2
    assert "supervision 'odometry'" in capsys.readouterr().err
    assert not (tmp_path / "m.sfa").exists()


def test_timestamps_must_increase(run):
    from sfanav.odometry.self_supervision import check_timestamps

    n = len(run["odometry"])
    t = np.arange(n, dtype=float) * 0.5
    np.testing.assert_array_equal(check_timestamps(t, n), t)
    back = t.copy()
    back[7] = back[6]
    with pytest.raises(ValueError, match="frame 7 at 3 s does not come after frame 6"):
        learn_positions(run["features"], run["odometry"], timestamps=back)
    bad = t.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="finite; frame 3"):
        learn_positions(run["features"], run["odometry"], timestamps=bad)
    with pytest.raises(ValueError, match="must match"):
        check_timestamps(t[:-1], n)


def test_train_localizer_checks_closures_first():
    """An unknown closures kind, or relative-pose closures with the metric
    learner, is a ValueError before any training."""
    from sfanav.pipeline import train_localizer

    X = np.zeros((6, 8, 60, 3))
    odo = np.c_[np.arange(6.0), np.zeros(6), np.zeros(6)]
    with pytest.raises(ValueError, match="closures must be one of"):
        train_localizer(X, odometry=odo, closures="pose")
    with pytest.raises(ValueError, match="needs metric_map='pose-graph'"):
        train_localizer(X, odometry=odo, closures="relative-pose", metric_map="metric-learning")
    with pytest.raises(ValueError, match="needs metric_map='pose-graph'"):
        train_localizer(X, odometry=odo, closures="heading", metric_map="metric-learning")


def test_describe_closures_says_what_the_pose_graph_measured():
    from sfanav.pipeline import describe_closures

    auto = {"loop closures": 12, "loop closures kept": 11, "closures": "auto", "closure method": "warping",
            "closure misfit by method": {"warping": 0.05, "min-warping": 0.08}}
    assert describe_closures(auto) == ("11 of 12 loop closures kept, relative poses by the warping (closures' "
                                       "misfit 0.05 against 0.08 by min-warping)")
    # no closure measured a position: both misfits unknown, no comparison printed
    none = {**auto, "closure misfit by method": {"warping": None, "min-warping": None}}
    assert describe_closures(none) == "11 of 12 loop closures kept, relative poses by the warping"
    assert describe_closures({"loop closures": 3, "loop closures kept": 3, "closures": "heading"}) == \
        "3 of 3 loop closures kept, relative headings only"
    assert describe_closures({"loop closures": 3, "loop closures kept": 2, "closures": "min-warping",
                              "closure method": "min-warping"}) == \
        "2 of 3 loop closures kept, relative poses by min-warping"


def test_a_map_learned_before_is_kept_and_no_map_is_learned(monkeypatch):
    """``learned=``: the readout is fitted to the given positions (the recipe's first training's map when it
    trains again with feedback); the run's features are not mapped again; a map of another run is refused."""
    import sfanav.odometry.self_supervision as ss
    from sfanav import Network, Rotation
    from sfanav.odometry import segment_lines
    from sfanav.odometry.self_supervision import LearnedPositions, fit_localizer_from_odometry

    from test_revisits import CONFIG as config
    from test_revisits import tiny_loop_run

    X, xy = tiny_loop_run(120)
    odometry = np.c_[xy, np.arctan2(*np.gradient(xy, axis=0).T[::-1])]
    lp = LearnedPositions(xy + [0.3, -0.2], "pose-graph", segment_lines(odometry))

    def never(*a, **k):
        raise AssertionError("a map was learned although one was given")

    monkeypatch.setattr(ss, "learn_positions", never)
    kw = dict(rotation=Rotation(step=6), readout="quadratic", n_outputs=4, progress=False)
    loc = fit_localizer_from_odometry(Network(config), X, odometry, learned=lp, **kw)
    assert loc.learned_positions_ is lp and loc.info["supervision"] == "odometry"
    np.testing.assert_array_equal(loc.training_positions_, lp.positions)
    with pytest.raises(ValueError, match="holds 119 positions but the run has 120"):
        fit_localizer_from_odometry(Network(config), X, odometry, learned=LearnedPositions(
            lp.positions[:-1], "pose-graph", lp.lines), **kw)
    with pytest.raises(TypeError, match="LearnedPositions"):
        fit_localizer_from_odometry(Network(config), X, odometry, learned=lp.positions, **kw)
