"""The sfanav default (issue 7): the "auto" readout's cross-validation,
Localizer readouts and rows saved and loaded, the default as the default of
``sfanav train`` and ``sfanav.Localizer`` (thesis presets unchanged), and a
tiny realistic garden end to end where the default beats the thesis
configuration."""

import json
import zipfile

import numpy as np
import pytest

import sfanav
from sfanav import sim
from sfanav.data import ImageRows
from sfanav.sfa import read_model, save_model
from sfanav.localization import AUTO_BLOCK, AUTO_FOLDS, GPReadout, KernelRidgeReadout, KNNReadout, auto_candidates, make_readout, readout_from_state, readout_state, select_auto_readout, select_readout
from sfanav.localization.readouts import describe_spec
from sfanav.localization import QuadraticRegression
from sfanav.sim import trajectories as T


def _serpentine(n: int = 20) -> np.ndarray:
    g = np.linspace(-3, 3, n)
    X, Y = np.meshgrid(g, g)
    X[1::2] = X[1::2, ::-1]
    return np.column_stack([X.ravel(), Y.ravel()])


def _rings(xy: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """12 features, not smooth global functions of position (rings around
    two 'nearby objects', waves), slowest first, plus a little noise."""
    r1, r2 = np.hypot(*(xy - [1.0, 1.0]).T), np.hypot(*(xy - [-1.5, -0.5]).T)
    F = np.column_stack([np.cos(2.5 * r1), np.sin(2.5 * r1), np.cos(2.5 * r2), np.sin(2.5 * r2),
                         np.sin(1.3 * xy[:, 0]), np.sin(1.3 * xy[:, 1]), np.cos(3 * r1) * np.cos(3 * r2), 0.1 * r1,
                         np.cos(1.7 * xy[:, 0] + xy[:, 1]), np.sin(0.9 * xy[:, 1] - xy[:, 0]), np.cos(r2), np.sin(r1)])
    return F + 0.01 * rng.standard_normal(F.shape)


# --------------------------------------------------------------------- the auto readout


def test_auto_readout_prefers_kernel_ridge_within_the_tolerance_and_is_the_argmin_without_it():
    rng = np.random.default_rng(0)
    xy = _serpentine()
    F = _rings(xy, rng)
    sel = select_auto_readout(F, xy, gp=False)
    assert sel.spec["kind"] in ("kernel", "knn") and sel.spec["n_outputs"] in (8, 12)
    assert f"{AUTO_FOLDS}-fold blocked CV" in sel.rule
    (k_spec, k_err), (n_spec, n_err) = sel.best_of("kernel"), sel.best_of("knn")
    # the rule: kNN only when its CV error is more than 10 % below kernel ridge's
    assert sel.spec == (n_spec if n_err < 0.9 * k_err else k_spec)
    # tolerance 0 is the plain argmin over the same candidates and folds
    plain = select_auto_readout(F, xy, tolerance=0.0, gp=False)
    ref = select_readout(F, xy, auto_candidates((8, 12)), n_folds=AUTO_FOLDS, block=AUTO_BLOCK)
    assert plain.spec == ref.spec
    np.testing.assert_allclose(plain.scores, ref.scores)
    # a tolerance near 1 keeps kernel ridge unless kNN is 100x better
    assert select_auto_readout(F, xy, tolerance=0.99, gp=False).spec["kind"] == "kernel"
    # the chosen readout is refitted on the whole run
    np.testing.assert_allclose(sel.readout.predict(F), make_readout(sel.spec).fit(F, xy).predict(F))
    # with the GP (the default): the GP unless the best other candidate's CV error is 10 % lower
    full = select_auto_readout(F, xy)
    gp_err = float(full.scores[-1])
    assert full.candidates[-1]["kind"] == "gp" and len(full.candidates[-1]["length_scale"]) == 12
    other = min(float(e) for c, e in zip(full.candidates, full.scores) if c["kind"] != "gp")
    assert (full.spec["kind"] == "gp") == (not other < 0.9 * gp_err), (other, gp_err, full.rule)
    assert select_auto_readout(F, xy, tolerance=0.99).spec == {"kind": "gp", "n_outputs": 12}


def test_auto_readout_on_smooth_features_is_kernel_ridge_and_nearly_exact():
    """Features that are smooth functions of position (the thesis's ideal):
    kernel ridge interpolates them far better than kNN, on a separate walk."""
    xy = _serpentine(16)
    f = lambda p: np.column_stack([p[:, 0], p[:, 1], p[:, 0] * p[:, 1], np.sin(p[:, 0]), np.cos(p[:, 1]),  # noqa: E731
                                   p[:, 0] ** 2, p[:, 1] ** 2, np.sin(p[:, 0] + p[:, 1])])
    te = np.random.default_rng(1).uniform(-2.8, 2.8, (200, 2))
    sel = select_auto_readout(f(xy), xy, gp=False)
    assert sel.spec["kind"] == "kernel" and sel.spec["n_outputs"] == 8  # only 8 features: 12 is not a candidate
    err = np.hypot(*(sel.readout.predict(f(te)) - te).T).mean()
    assert err < 0.05, err  # grid spacing 0.4 m
    sel = select_auto_readout(f(xy), xy)  # the default: the GP on all 8, at least as exact
    assert sel.spec == {"kind": "gp", "n_outputs": 8} and "GP (ARD, marginal likelihood)" in sel.rule
    assert np.hypot(*(sel.readout.predict(f(te)) - te).T).mean() < err


def test_auto_readout_picks_knn_when_its_cv_error_is_much_lower():
    """Features that are a place code (one-hot-like bumps per training
    place, no smooth structure): neighbours are right, a smooth kernel fit
    of few dims is not; with n_outputs fixed."""
    rng = np.random.default_rng(3)
    xy = _serpentine(14)
    # 8 features: a random embedding of a 1-D hash of the grid cell, very non-smooth in position
    cell = (np.round((xy[:, 0] + 3) / 6 * 13) * 14 + np.round((xy[:, 1] + 3) / 6 * 13)).astype(int)
    table = rng.standard_normal((14 * 14, 8)) * 3
    F = table[cell] + 0.001 * rng.standard_normal((len(xy), 8))
    F2 = np.repeat(F, 2, axis=0) + 0.001 * rng.standard_normal((2 * len(F), 8))  # each place seen twice
    xy2 = np.repeat(xy, 2, axis=0)
    sel = select_auto_readout(F2, xy2, n_outputs=8, gp=False)
    k_err, n_err = sel.best_of("kernel")[1], sel.best_of("knn")[1]
    assert n_err < 0.9 * k_err and sel.spec["kind"] == "knn", (k_err, n_err)
    # with the GP: kNN must beat the GP's CV error by the same margin
    sel = select_auto_readout(F2, xy2, n_outputs=8)
    gp_err = float(sel.scores[-1])
    assert (sel.spec["kind"] == "knn") == (n_err < 0.9 * gp_err), (n_err, gp_err)
    assert ("beats the GP's CV" in sel.rule) == (sel.spec["kind"] == "knn")


def test_gp_readout_learns_which_features_code_position():
    """ARD: two smooth codes of position plus two pure-noise features; the
    noise features get length scales far longer than the codes', the fit is
    accurate on a separate walk, fixed hyperparameters reproduce it, and it
    survives a model-file state round trip."""
    rng = np.random.default_rng(5)
    xy = _serpentine(14)
    f = lambda p, r: np.column_stack([np.sin(0.5 * p[:, 0]), np.sin(0.4 * p[:, 1]), r.standard_normal(len(p)),  # noqa: E731
                                      r.standard_normal(len(p))])
    gp = GPReadout(n_outputs=4).fit(f(xy, rng), xy)
    ls = gp.length_scale_
    assert min(ls[2:]) > 10 * max(ls[:2]), ls
    assert gp.log_marginal_likelihood_ is not None and gp.noise_ > 0
    te = rng.uniform(-2.8, 2.8, (200, 2))
    Fte = f(te, rng)
    err = np.hypot(*(gp.predict(Fte) - te).T).mean()
    assert err < 0.05, err
    fixed = make_readout(gp.fixed_spec()).fit(f(xy, np.random.default_rng(5)), xy)
    np.testing.assert_allclose(fixed.predict(Fte), gp.predict(Fte), atol=1e-9)
    assert fixed.log_marginal_likelihood_ is None
    back = readout_from_state(readout_state({"kind": "gp", "n_outputs": 4}, gp))
    np.testing.assert_allclose(back.predict(Fte), gp.predict(Fte))
    assert describe_spec(gp.fixed_spec()).startswith("gp(n_outputs=4, noise=")


def test_gp_readout_bad_input():
    xy = _serpentine(4)
    F = np.c_[xy, xy[:, ::-1]]
    with pytest.raises(ValueError, match="give both length_scale and noise"):
        GPReadout(length_scale=[1.0, 1.0])
    with pytest.raises(ValueError, match="length_scale must be positive"):
        GPReadout(length_scale=[1.0, -1.0], noise=0.1)
    with pytest.raises(ValueError, match="noise must be positive"):
        GPReadout(length_scale=[1.0], noise=0.0)
    with pytest.raises(ValueError, match="length_scale has 1 entries for 4 features"):
        GPReadout(n_outputs=None, length_scale=[1.0], noise=0.1).fit(F, xy)
    with pytest.raises(ValueError, match="at least 3 training samples"):
        GPReadout(n_outputs=4).fit(F[:2], xy[:2])
    with pytest.raises(ValueError, match="fewer than n_outputs=12"):
        GPReadout().fit(F, xy)
    with pytest.raises(sfanav.NotFittedError):
        GPReadout().predict(F)
    with pytest.raises(ValueError, match="invalid GPReadout state"):
        g = GPReadout(n_outputs=4).fit(F, xy)
        st = readout_state({"kind": "gp"}, g)
        st["state"]["length_scale"] = st["state"]["length_scale"][:2]
        readout_from_state(st)


def test_block_folds_contiguous_and_interleaved():
    from sfanav.localization import block_folds

    for folds in (block_folds(47, 5), block_folds(47, 5, block=4)):
        held = np.concatenate([te for _, te in folds])
        assert sorted(held.tolist()) == list(range(47))  # every sample held out exactly once
        for tr, te in folds:
            assert not set(tr) & set(te) and len(tr) + len(te) == 47
    f = block_folds(47, 5, block=4)
    assert f[0][1].tolist() == [0, 1, 2, 3, 20, 21, 22, 23, 40, 41, 42, 43]  # blocks 0, 5, 10
    assert block_folds(47, 5)[0][1].tolist() == list(range(9))  # one contiguous stretch
    with pytest.raises(ValueError, match="too few for 5 folds"):
        block_folds(12, 5, block=4)


def test_auto_readout_errors_and_short_runs():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 1, (12, 2))
    F = np.c_[xy, rng.standard_normal((12, 6))]
    sel = select_auto_readout(F, xy)  # 12 samples: 6 folds of one 2-image block each
    assert sel.rule.startswith("6-fold blocked CV (blocks of 2 images)")
    assert select_auto_readout(F, xy, block=None).rule.startswith("6-fold blocked CV (contiguous)")
    with pytest.raises(ValueError, match="too few"):
        select_auto_readout(F[:3], xy[:3])
    with pytest.raises(ValueError, match="tolerance"):
        select_auto_readout(F, xy, tolerance=1.0)
    with pytest.raises(ValueError, match=r"n_outputs \[9\] out of range"):
        select_auto_readout(F, xy, n_outputs=9)
    with pytest.raises(ValueError, match="features has 12 rows but xy has 11"):
        select_auto_readout(F, xy[:-1])


# --------------------------------------------------------------------- Localizer readouts and rows


@pytest.mark.parametrize("readout", ["auto", "quadratic", {"kind": "knn", "n_outputs": 6, "k": 3},
                                     {"kind": "kernel", "n_outputs": 8, "gamma": 0.5, "alpha": 1e-3},
                                     {"kind": "gp", "n_outputs": 8}])
def test_localizer_readouts_save_and_load(readout, tmp_path):
    rng = np.random.default_rng(0)
    xy = _serpentine(14)
    F = _rings(xy, rng)
    loc = sfanav.Localizer(None, readout=readout).fit_features(F, xy)
    if isinstance(readout, dict):
        cls = {"knn": KNNReadout, "kernel": KernelRidgeReadout, "gp": GPReadout}[readout["kind"]]
    else:
        cls = QuadraticRegression if readout == "quadratic" else (GPReadout, KernelRidgeReadout, KNNReadout)
    assert isinstance(loc.regression_, cls)
    if readout == "quadratic":
        assert loc.readout_spec_ == {"kind": "quadratic", "n_outputs": 8, "ridge": 0.0, "degree": 2}
    path = loc.save(tmp_path / "l.sfa")
    back = sfanav.load(path)
    np.testing.assert_array_equal(back.predict_features(F[:50]), loc.predict_features(F[:50]))
    assert back.readout == readout and back.readout_spec_ == loc.readout_spec_ and back.n_outputs_ == loc.n_outputs_
    with zipfile.ZipFile(path) as z:
        manifest = json.loads(z.read("manifest.json"))
    # the thesis's readout stays readable by older sfanav (format 1, "regression" kept); the others need format 2
    assert manifest["version"] == {"quadratic": 1, "gp": 3}.get(loc.readout_spec_["kind"], 2)
    assert ("regression" in manifest["state"]) == (loc.readout_spec_["kind"] == "quadratic")


def test_localizer_default_readout_is_auto_and_old_files_load_as_the_thesis_readout(tmp_path):
    assert sfanav.Localizer(None).readout == "auto"
    rng = np.random.default_rng(0)
    xy = _serpentine(14)
    F = _rings(xy, rng)
    reg = QuadraticRegression(8).fit(F, xy)
    # a format-1 Localizer state as sfanav wrote it before the readouts
    save_model(tmp_path / "old.sfa", "Localizer", {
        "params": {"n_outputs": 8, "ridge": 0.0, "degree": 2}, "network": None, "regression": reg.get_state(),
        "n_features_in": 12, "train_metrics": {}, "info": {}})
    old = sfanav.load(tmp_path / "old.sfa")
    assert old.readout == "quadratic" and old.readout_spec_["kind"] == "quadratic" and old.n_outputs_ == 8
    np.testing.assert_allclose(old.predict_features(F), reg.predict(F))
    with pytest.raises(ValueError, match="readout must be 'auto', 'quadratic' or a readout spec"):
        sfanav.Localizer(None, readout="svm").fit_features(F, xy)
    with pytest.raises(TypeError, match="rows must be"):
        sfanav.Localizer(None, rows=(-10, 20))
    with pytest.raises(ValueError, match="n_outputs=13, but the features have only 12"):
        sfanav.Localizer(None, n_outputs=13).fit_features(F, xy)


def test_localizer_rows_are_applied_before_the_network_and_saved(tmp_path):
    from sfanav.experiments.localization import tiny_config

    rng = np.random.default_rng(0)
    X = rng.integers(0, 255, (40, 16, 30, 3)).astype(np.uint8)
    X = (X + np.roll(X, 1, axis=0)) // 2
    rows = ImageRows(band=(-10.0, 20.0), camera_elevation=(-30.0, 20.0))
    net = sfanav.Network(tiny_config(30, 16, 3, out=8)).fit(rows(X), sfanav.Rotation(5, 1.0), progress=False)
    loc = sfanav.Localizer(net, rows=rows, readout="quadratic", n_outputs=4).fit(X, rng.uniform(0, 1, (40, 2)))
    np.testing.assert_allclose(loc.features(X), net.transform(rows(X)))
    np.testing.assert_allclose(loc.features(X[3]), net.transform(rows(X[3:4]))[0])  # one image in
    back = sfanav.load(loc.save(tmp_path / "r.sfa"))
    assert back.rows == rows
    np.testing.assert_array_equal(back.predict(X[:5]), loc.predict(X[:5]))


def test_default_network_preset_is_table_5_1_wider_with_12_outputs():
    from sfanav.localization import BAND, default_network, default_rows

    d, t = sfanav.Network.from_preset("sfanav-default").config, sfanav.Network.from_preset("thesis-5.1").config
    assert [layer["out"] for layer in d["layers"]] == [20, 24, 24, 12]
    assert [layer["out"] for layer in t["layers"]] == [14, 16, 16, 8]  # the thesis preset is unchanged
    for a, b in zip(d["layers"], t["layers"]):
        assert a["rf"] == b["rf"] and a.get("stride") == b.get("stride")
    assert d["input"] == t["input"] and d["network"]["precision"] == "mixed"
    assert default_network().input_shape == (40, 350, 3)
    assert default_rows().band == BAND == (-10.0, 20.0)


# --------------------------------------------------------------------- end to end


def test_tiny_realistic_garden_default_beats_the_thesis_configuration():
    """A tiny realistic garden (objects and ground patches inside the area),
    training run -> separate test walk: the default's recipe (wider lower
    layer, horizon band, auto readout) on a tiny network beats the thesis's
    (the same tiny network at the thesis's width, all rows, quadratic
    regression of 8 outputs), end to end through fit_localizer/evaluate."""
    from sfanav.localization import default_rows
    from sfanav.experiments.localization import tiny_config
    from sfanav.localization import fit_localizer

    w = sim.World.generate(0, area=(7, 7), n_objects=16, depth=6.0, inner={"tree": 1, "bush": 1, "pole": 2},
                           patches={"path": 1, "bed": 2})
    tr = T.detour(T.grid(w.area, spacing=1.0, step=0.3, turn="arc", margin=0.4), w)
    te = T.random_walk(w.area, 120, 0.2, margin=0.45, world=w, rng=0)
    r = sim.Renderer(w)
    cam = sim.PanoramicCamera(99, 16)  # elevation -30..+20 deg
    X_tr = np.stack([r.render(cam, p) for p in tr.poses])
    X_te = np.stack([r.render(cam, p) for p in te.poses])
    xy_tr, xy_te = tr.poses[:, :2], te.poses[:, :2]
    thesis_cfg = tiny_config(99, 16, 3, out=12)
    wide_cfg = tiny_config(99, 16, 3, out=12)
    wide_cfg["layers"][0]["out"] = 12  # "wider layers", as sfanav-default widens Table 5.1's
    thesis = fit_localizer(sfanav.Network(thesis_cfg), X_tr, xy_tr, rotation=sfanav.Rotation(5, 1.0), n_outputs=8,
                           readout="quadratic", progress=False)
    default = fit_localizer(sfanav.Network(wide_cfg), X_tr, xy_tr, rotation=sfanav.Rotation(5, 1.0),
                            rows=default_rows(cam.elevation_deg), progress=False)
    assert default.readout == "auto" and default.rows.band == (-10.0, 20.0)
    e_thesis = thesis.score(X_te, xy_te)
    e_default = default.score(X_te, xy_te)
    assert e_default < 0.75 * e_thesis, (e_default, e_thesis)


# --------------------------------------------------------------------- CLI


def test_cli_train_uses_the_default_without_a_preset_and_the_thesis_with_one(tmp_path, monkeypatch, capsys):
    """Which configuration ``sfanav train`` builds: captured at fit_localizer
    as the training recipe (sfanav.pipeline) calls it (no training here)."""
    from sfanav import pipeline
    from sfanav.app import cli

    ds = sim.simulate("realistic-garden", tmp_path / "d", 0, max_frames=6, camera=sim.PanoramicCamera(70, 8),
                      progress=False)
    seen = {}

    class Stop(Exception):
        pass

    def fake(network, images, xy, **kw):
        seen.update(kw, network=network, shape=images.shape)
        raise Stop

    monkeypatch.setattr(pipeline, "fit_localizer", fake)
    with pytest.raises(Stop):
        cli.main(["train", "--dataset", str(ds.root), "--out", str(tmp_path / "m.sfa"), "--no-progress"])
    assert seen["readout"] == "auto" and seen["n_outputs"] is None
    assert seen["rows"].band == (-10.0, 20.0) and seen["rows"].camera_elevation == (-30.0, 20.0)
    assert [layer["out"] for layer in seen["network"].config["layers"]] == [20, 24, 24, 12]
    assert seen["shape"][1:] == (40, 350, 3)
    assert seen["info"]["configuration"] == "sfanav default"
    for preset in ("thesis-5.1", "thesis-5.3"):
        seen.clear()
        with pytest.raises(Stop):
            cli.main(["train", "--dataset", str(ds.root), "--preset", preset, "--out", str(tmp_path / "m.sfa"),
                      "--no-progress"])
        assert seen["readout"] == "quadratic" and seen["n_outputs"] == 8 and seen["rows"] is None
        assert seen["network"].config == sfanav.Network.from_preset(preset).config
    seen.clear()
    with pytest.raises(Stop):
        cli.main(["train", "--dataset", str(ds.root), "--preset", "thesis-5.1", "--readout", "auto", "--rows", "band",
                  "--out", str(tmp_path / "m.sfa"), "--no-progress"])
    assert seen["readout"] == "auto" and seen["rows"].band == (-10.0, 20.0)


def test_cli_default_train_localize_round_trip(tmp_path, capsys):
    """The default path for real, on a tiny dataset (resized to 350x40)."""
    from sfanav.app import cli

    ds = sim.simulate("realistic-garden", tmp_path / "d", 0, max_frames=30, camera=sim.PanoramicCamera(70, 8),
                      progress=False)
    model = tmp_path / "m.sfa"
    assert cli.main(["train", "--dataset", str(ds.root), "--out", str(model), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "readout gp-signature(" in out  # the slow features with the Fourier signature
    assert "on features pooled over 8 rotations" in out
    loc = sfanav.load(model)
    assert loc.readout == "auto" and loc.rows.band == (-10.0, 20.0) and loc.info["configuration"] == "sfanav default"
    assert loc.photometric == "lowpass-log-contrast"  # robustness "standard"
    kind, state, manifest = read_model(model)
    assert manifest["version"] == 6 and loc.rotation_pooling_ == 8  # format 6: a signature beside pooled features, photometric
    assert state["readout"]["spec"]["kind"] == "gp-signature" and loc.n_signature_ == 40 * 3 * 15
    assert cli.main(["localize", str(model), str(ds.root), "--run", "test", "--out", str(tmp_path / "p.csv"),
                     "--no-progress"]) == 0
    assert len((tmp_path / "p.csv").read_text().splitlines()) == 31
    # pooled features: --rotations has nothing left to average, and says so
    with pytest.raises(SystemExit) as exc:
        cli.main(["localize", str(model), str(ds.root), "--run", "test", "--out", str(tmp_path / "q.csv"),
                  "--no-progress", "--rotations"])
    assert exc.value.code == 2 and "rotation pooling" in capsys.readouterr().err
    # evaluate: the network sees the band, the baselines the panoramas as they are
    assert cli.main(["evaluate", str(model), str(ds.root), "--out", str(tmp_path / "ev"), "--no-progress"]) == 0
    m = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert "mae_x_pct" in m["random_splits"] and set(m["baselines"]) == {"perfect memory", "Fourier signature"}
    np.testing.assert_allclose(m["test_run"]["med"], loc.evaluate(
        *_test_run(ds, loc))["med"], rtol=1e-9)


def _test_run(ds, loc):
    from sfanav.data import Preprocessing, load_run

    return load_run(ds.select(run="test"), Preprocessing.of_model(loc), log=lambda m: None)


def test_gardens_experiment_has_the_default_row(tmp_path):
    """`sfanav experiment gardens` measures the default as one row (quick: tiny images and network)."""
    from sfanav.experiments.gardens import run_scene

    res, plots = run_scene(tmp_path, "realistic-garden", 0, quick=True, progress=False, control=True,
                           row_variants={}, train_variants={}, baselines_too=False, firing_maps=False)
    assert list(res) == ["control: sfanav default", "control: sfanav default without rotation pooling",
                         "control: sfanav default, no ground truth"]
    assert plots == []
    free = res["control: sfanav default, no ground truth"]  # the same network, readout on learned positions
    assert free["MED (m)"] > 0 and free["MED ratio no ground truth / ground truth"] > 0
    assert free["loop closures kept"] >= 0 and free["training positions median error (m)"] >= 0
    row = res["control: sfanav default"]
    assert row["rotation pooling"] == 8 and res["control: sfanav default without rotation pooling"]["rotation pooling"] == 1
    # the slow features (or none) with the Fourier signature of the 8-row RGB panoramas (8 x 3 rows x 15)
    assert row["readout"].startswith("gp-signature(") and row["numbers per image"] in (360, 372)
    assert "BIC" in row["readout rule"] and row["MAE x (%)"] > 0 and "cv diagnostics" not in row
