"""Online updates of a trained localizer (sfanav.localization.updates): with
the network's lower stages frozen and a readout memory holding every old
view, adding run B to a localizer trained on run A equals retraining the
top stage and the readout on A + B (outputs to 1e-9 for deterministic
readouts); the memory stays bounded, survives the model file, and bad runs
are refused leaving the localizer as it was."""

import numpy as np
import pytest
import sfanav
from sfanav import Localizer, Network, Rotation
from sfanav.localization.training import fit_localizer
from sfanav.localization.updates import (
    LocalizerUpdater,
    ReadoutMemory,
    drop_readout_memory,
    readout_memory_bytes,
    remember,
    top_stage_degree,
    top_stage_features,
    top_stage_inputs,
    top_stage_training_inputs,
)
from sfanav.sfa.updates import NetworkUpdater, UpdatePolicy

TINY = {
    "input": {"width": 60, "height": 8, "channels": 3},
    "network": {"precision": "double"},
    "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 6}, {"rf": "full", "out": 5}],
}
ROT = Rotation(step=10)
KERNEL = {"kind": "kernel", "n_outputs": 5, "gamma": 0.5, "alpha": 1e-3}


def _run(n, seed):
    """Smooth periodic panoramas along a random walk, and the walk's (x, y)."""
    rng = np.random.default_rng(seed)
    x = np.arange(60) * 2 * np.pi / 60
    y = np.arange(8)[:, None]
    walk = np.cumsum(rng.normal(0, 0.3, (n, 6)), axis=0)
    out = np.empty((n, 8, 60, 3))
    for i in range(n):
        p = walk[i]
        for c in range(3):
            out[i, :, :, c] = (np.sin(x + p[0] + 0.3 * y) + 0.5 * np.cos(2 * x + p[1] * (1 + c))
                               + 0.3 * np.sin(3 * x + p[2] * y) + 0.1 * rng.standard_normal((8, 60)))
    return np.clip((out + 2.5) / 5.0, 0.0, 1.0), walk[:, :2].copy()


(A, YA), (B, YB), (C, YC) = _run(40, 1), _run(30, 2), _run(12, 3)


def _trained(**kw):
    net = Network(TINY)
    return fit_localizer(net, A, YA, rotation=ROT, progress=False, readout_memory=1000, **kw)


def _retrained(loc, **kw):
    """The reference: the top stage trained on A and B (each its own
    recording), then the readout fitted on A + B's features."""
    net = NetworkUpdater(loc.network).partial_fit(B).network_
    ref = Localizer(net, **kw)
    return ref.fit(np.concatenate([A, B]), np.concatenate([YA, YB]))


def _close(a, b, tol=1e-9):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert float(np.abs(a - b).max()) <= tol * max(1.0, float(np.abs(b).max()))


@pytest.fixture(scope="module")
def quad():
    return _trained(readout="quadratic", n_outputs=5)


@pytest.fixture(scope="module")
def pooled():
    return _trained(readout=KERNEL, rotation_pooling=3)


def test_stage_inputs_give_the_features(quad, pooled):
    for loc in (quad, pooled):
        Z = top_stage_inputs(loc, C)
        assert Z.shape == (len(C), loc.rotation_pooling_ if loc.rotation_pooling_ > 1 else 1, Z.shape[2])
        _close(top_stage_features(loc.network, Z), loc.features(C), 1e-12)
    assert pooled.readout_memory_.inputs.shape[1] == 3


def test_training_inputs_are_the_sequence_the_top_stage_was_solved_from(quad, pooled):
    """Batch SFA (numpy) on the top stage's training inputs, flattened image
    after image and expanded with the stage's degree, gives the stage's
    delta values and its outputs."""
    from sfanav import _core

    for loc in (quad, pooled):
        Z = top_stage_training_inputs(loc, A)
        n_views = -(-A.shape[2] // ROT.step)
        assert Z.shape == (len(A), n_views, loc.readout_memory_.inputs.shape[2])
        assert top_stage_degree(loc.network) == 2
        E = np.asarray(_core.expand(Z.reshape(-1, Z.shape[2]), 2))
        w, V = np.linalg.eigh(np.cov(E.T, bias=True))
        keep = w > w.max() * 1e-10
        W = V[:, keep] / np.sqrt(w[keep])
        D = np.diff(E, axis=0)
        delta, U = np.linalg.eigh(W.T @ (D.T @ D / len(D)) @ W)
        m = loc.network.n_outputs_
        np.testing.assert_allclose(delta[:m], loc.network.delta_values_, rtol=1e-6)
        Y = (E - E.mean(axis=0)) @ W @ U[:, :m]
        F = top_stage_features(loc.network, Z.reshape(-1, 1, Z.shape[2]))
        for j in range(m):
            assert abs(np.corrcoef(Y[:, j], F[:, j])[0, 1]) > 0.9999


def test_update_equals_retraining_quadratic(quad):
    up = LocalizerUpdater(quad, cross_pairs=False).partial_fit(B, YB)
    ref = _retrained(quad, readout="quadratic", n_outputs=5)
    new = up.localizer_
    _close(new.predict(C), ref.predict(C))
    _close(new.training_positions_, np.concatenate([YA, YB]))
    assert new.readout_memory_.n_seen == len(A) + len(B) and len(new.readout_memory_) == len(A) + len(B)
    assert new.info["n_train_images"] == len(A) + len(B) and new.info["updates"][-1]["n_images"] == len(B)
    assert quad.readout_memory_.n_seen == len(A)  # the original is not modified


def test_update_equals_retraining_pooled_kernel(pooled):
    new = LocalizerUpdater(pooled, cross_pairs=False).partial_fit(B, YB).localizer_
    ref = _retrained(pooled, readout=KERNEL, rotation_pooling=3)
    assert new.rotation_pooling_ == 3 and new.readout == KERNEL
    _close(new.predict(C), ref.predict(C))


SIG_GP = {"kind": "gp-signature", "n_outputs": 5}


@pytest.fixture(scope="module")
def sig_gp():
    return _trained(readout=SIG_GP, signature="fourier", rotation_pooling=3)


def test_update_with_signature_gp_learning_its_kernel_matches_loosely(sig_gp):
    new = LocalizerUpdater(sig_gp, kernel="learn", cross_pairs=False).partial_fit(B, YB).localizer_
    ref = _retrained(sig_gp, readout=SIG_GP, signature="fourier", rotation_pooling=3)
    err = np.linalg.norm(new.predict(C) - ref.predict(C), axis=1)
    assert err.max() < 1e-4 * max(1.0, float(np.ptp(YA)))
    assert new.info["updates"][-1]["kernel"] == "learned"


def test_update_keeping_the_kernel_equals_a_retrain_with_that_kernel(sig_gp):
    new = LocalizerUpdater(sig_gp, kernel="keep", cross_pairs=False).partial_fit(B, YB).localizer_
    kept = {**SIG_GP, **sig_gp.regression_.hyperparameters()}
    ref = _retrained(sig_gp, readout=kept, signature="fourier", rotation_pooling=3)
    _close(new.predict(C), ref.predict(C), 1e-8)
    np.testing.assert_array_equal(new.regression_.length_scale_, sig_gp.regression_.length_scale_)
    assert new.regression_.noise_ == sig_gp.regression_.noise_
    assert new.info["updates"][-1]["kernel"] == "kept" and new.info["readout_kernel_images"] == len(A)
    # the kernel learned again differs: keeping it is a choice, not a no-op
    relearned = LocalizerUpdater(sig_gp, kernel="learn", cross_pairs=False).partial_fit(B, YB).localizer_
    assert not np.allclose(relearned.regression_.length_scale_, sig_gp.regression_.length_scale_)


def test_auto_learns_the_kernel_again_when_the_images_doubled(sig_gp):
    half = LocalizerUpdater(sig_gp).partial_fit(B[:10], YB[:10]).localizer_  # 50 images seen, kernel on 40
    assert half.info["updates"][-1]["kernel"] == "kept" and half.info["readout_kernel_images"] == len(A)
    more = LocalizerUpdater(half).partial_fit(B[10:], YB[10:]).localizer_  # 70 seen: still < 80
    assert more.info["updates"][-1]["kernel"] == "kept"
    doubled = LocalizerUpdater(more).partial_fit(C, YC).localizer_  # 82 seen >= 2 x 40
    assert doubled.info["updates"][-1]["kernel"] == "learned" and doubled.info["readout_kernel_images"] == 82
    with pytest.raises(ValueError, match="kernel must be one of auto, keep, learn"):
        LocalizerUpdater(sig_gp, kernel="fixed")


def test_cross_run_pairs_join_each_new_view_to_the_nearest_old_one(quad):
    """The update with cross-run pairs equals the top stage re-solved with
    the run and those pairs added to its statistics (the pairs at every
    pooled rotation, the transition weight spread over them), to 1e-9;
    pairs only within the radius; bad radii refused."""
    from sfanav.localization.updates import cross_run_pairs

    mem = quad.readout_memory_
    i_old, j_new = cross_run_pairs(mem.positions, YB, 0.4)
    assert len(i_old) > 0 and len(i_old) < len(YB)
    d = np.hypot(*(mem.positions[i_old] - YB[j_new]).T)
    assert d.max() < 0.4
    nearest = np.hypot(*(mem.positions[None, :, :] - YB[j_new][:, None, :]).transpose(2, 0, 1)).min(axis=1)
    np.testing.assert_allclose(d, nearest)
    new = LocalizerUpdater(quad, cross_pairs=True, pair_radius=0.4).partial_fit(B, YB).localizer_
    assert new.info["updates"][-1]["cross_pairs"] == len(i_old)
    net_up = NetworkUpdater(quad.network)
    Z_old, Z_new = mem.inputs[i_old], top_stage_inputs(quad, B)[j_new]
    K, k = Z_new.shape[1:]
    net_up.add_pairs(Z_old.reshape(-1, k), Z_new.reshape(-1, k), np.full(len(i_old) * K, net_up.transition_weight / K))
    ref = Localizer(net_up.partial_fit(B).network_, readout="quadratic", n_outputs=5)
    ref.fit(np.concatenate([A, B]), np.concatenate([YA, YB]))
    _close(new.predict(C), ref.predict(C))
    without = LocalizerUpdater(quad).partial_fit(B, YB).localizer_  # the default: no pairs
    assert without.info["updates"][-1]["cross_pairs"] == 0
    assert not np.allclose(new.predict(C), without.predict(C))
    with pytest.raises(ValueError, match="pair_radius must be a positive"):
        LocalizerUpdater(quad, pair_radius=0.0)
    with pytest.raises(ValueError, match=r"a and b must both be \(M, 23\)"):
        NetworkUpdater(quad.network).add_pairs(np.zeros((2, 5)), np.zeros((2, 5)))
    with pytest.raises(ValueError, match="weights must be 2 finite"):
        NetworkUpdater(quad.network).add_pairs(np.zeros((2, k)), np.zeros((2, k)), [1.0, -1.0])


def test_one_solve_for_two_runs_equals_two_solves(quad):
    half = len(B) // 2
    two = LocalizerUpdater(quad).partial_fit(B[:half], YB[:half]).partial_fit(B[half:], YB[half:]).localizer_
    up = LocalizerUpdater(quad, UpdatePolicy(every=10 * len(B)))
    up.partial_fit(B[:half], YB[:half]).partial_fit(B[half:], YB[half:])
    assert up.n_solves_ == 0 and up.n_pending_ == len(B)
    one = up.solve()
    _close(one.predict(C), two.predict(C))


def test_memory_is_bounded_and_evenly_spaced():
    loc = fit_localizer(Network(TINY), A, YA, rotation=ROT, progress=False, readout="quadratic", n_outputs=5,
                        readout_memory=16)
    mem = loc.readout_memory_
    assert len(mem) == 16 and mem.n_seen == len(A)
    _close(mem.positions[[0, -1]], YA[[0, -1]])
    assert mem.nbytes == mem.inputs.nbytes + mem.positions.nbytes
    new = LocalizerUpdater(loc).partial_fit(B, YB).localizer_
    assert len(new.readout_memory_) == 16 and new.readout_memory_.n_seen == len(A) + len(B)
    sizes = readout_memory_bytes(new)
    assert sizes["readout_memory"] == new.readout_memory_.nbytes and sizes["network_statistics"] > 0


def test_model_file_round_trip(quad, tmp_path):
    path = quad.save(tmp_path / "loc.sfanav")
    import sfanav

    back = sfanav.load(path)
    assert isinstance(back.readout_memory_, ReadoutMemory)
    _close(back.readout_memory_.inputs, quad.readout_memory_.inputs, 0)
    a = LocalizerUpdater(back).partial_fit(B, YB).localizer_
    b = LocalizerUpdater(quad).partial_fit(B, YB).localizer_
    _close(a.predict(C), b.predict(C), 1e-12)
    # without the memory: a smaller file with no statistics, loadable, not updatable
    plain = sfanav.load(path)
    small = drop_readout_memory(plain).save(tmp_path / "plain.sfanav")
    assert small.stat().st_size < path.stat().st_size / 2
    old = sfanav.load(small)
    assert old.readout_memory_ is None
    _close(old.predict(C), quad.predict(C), 1e-12)
    with pytest.raises(ValueError, match="no readout memory"):
        LocalizerUpdater(old)
    with pytest.raises(ValueError, match="without its training statistics"):
        LocalizerUpdater(remember(old, A, YA))


def test_partial_fit_on_the_localizer(quad):
    loc = sfanav_copy(quad)
    loc.partial_fit(B, YB)
    ref = LocalizerUpdater(quad).partial_fit(B, YB).localizer_
    _close(loc.predict(C), ref.predict(C), 1e-12)


def sfanav_copy(loc):
    import tempfile
    from pathlib import Path

    import sfanav

    with tempfile.TemporaryDirectory() as tmp:
        return sfanav.load(loc.save(Path(tmp) / "m.sfanav"))


def test_bad_runs_are_refused_and_change_nothing(quad):
    loc = sfanav_copy(quad)
    before = loc.predict(C)
    with pytest.raises(ValueError, match="no positions"):
        loc.partial_fit(B)
    with pytest.raises(ValueError, match="60x8"):
        loc.partial_fit(B[:, :, :50], YB)
    with pytest.raises(ValueError, match="same length|rows|length"):
        loc.partial_fit(B, YB[:-1])
    with pytest.raises(ValueError, match="channel"):
        loc.partial_fit(B[..., :1], YB)
    _close(loc.predict(C), before, 0)
    assert loc.readout_memory_.n_seen == len(A)
    with pytest.raises(TypeError):
        LocalizerUpdater("model.sfanav")
    with pytest.raises(ValueError, match="readout memory inputs"):
        ReadoutMemory(np.zeros((3, 4)), np.zeros((3, 2)))


# ---------------------------------------------------------------- sfanav train --updatable, sfanav update


def _dataset(path, images, xy):
    from sfanav.data.dataset import write_dataset

    u8 = np.round(np.asarray(images) * 255).astype(np.uint8)
    return write_dataset(path, list(u8), np.c_[xy, np.zeros(len(xy))])


def test_cli_update_of_a_localizer(tmp_path, capsys):
    import json

    import sfanav
    from clitools import assert_one_line_error, run

    (tmp_path / "tiny.json").write_text(json.dumps(TINY))
    _dataset(tmp_path / "a", A, YA)
    _dataset(tmp_path / "b", B, YB)
    model = tmp_path / "loc.sfanav"
    common = ["--config", tmp_path / "tiny.json", "--readout", "quadratic", "--n-outputs", "5", "--step", "10",
              "--no-progress"]
    code, out, err = run(capsys, "train", "--dataset", tmp_path / "a", "--out", model, "--updatable", *common)
    assert code == 0, err
    original = model.read_bytes()
    loc = sfanav.load(model)
    assert len(loc.readout_memory_) == len(A) and loc.info["source_image"] == [60, 8, 3]
    code, out, err = run(capsys, "update", model, "--dataset", tmp_path / "b", "--out", tmp_path / "new.sfanav",
                         "--no-progress")
    assert code == 0, err
    assert "refitted on 70 views" in out and "bytes of readout memory" in out
    assert model.read_bytes() == original
    new = sfanav.load(tmp_path / "new.sfanav")
    Xb = np.round(B * 255).astype(np.uint8)
    ref = LocalizerUpdater(loc).partial_fit(Xb, YB).localizer_
    Xc = np.round(C * 255).astype(np.uint8)
    _close(new.predict(Xc), ref.predict(Xc), 1e-12)
    assert new.info["n_train_images"] == len(A) + len(B)
    # runs that do not match, a run without ground truth, a model without memory: one line, MODEL unchanged
    _dataset(tmp_path / "gray", B[..., 0], YB)
    _dataset(tmp_path / "narrow", B[:, :, :50], YB)
    _dataset(tmp_path / "nogt", B, YB)
    frames = tmp_path / "nogt" / "frames.csv"  # x, y blanked: no ground truth
    rows = [r.split(",") for r in frames.read_text().splitlines()]
    frames.write_text("\n".join(",".join(r if i == 0 else r[:3] + ["", ""] + r[5:]) for i, r in enumerate(rows))
                      + "\n")
    for bad, words in ((tmp_path / "gray", ("channel", "does not match")),
                       (tmp_path / "narrow", ("50x8", "does not match")),
                       (tmp_path / "nogt", ("ground-truth",))):
        code, out, err = run(capsys, "update", model, "--dataset", bad, "--out", tmp_path / "bad.sfanav")
        assert_one_line_error(code, err, *words)
        assert not (tmp_path / "bad.sfanav").exists() and model.read_bytes() == original
    code, out, err = run(capsys, "train", "--dataset", tmp_path / "a", "--out", tmp_path / "plain.sfanav", *common)
    assert code == 0, err
    code, out, err = run(capsys, "update", tmp_path / "plain.sfanav", "--dataset", tmp_path / "b",
                         "--out", tmp_path / "bad.sfanav")
    assert_one_line_error(code, err, "--updatable")
    assert not (tmp_path / "bad.sfanav").exists()
    # every layer trained again: a model that keeps its images, --resolve all equals the Python update
    code, out, err = run(capsys, "update", model, "--dataset", tmp_path / "b", "--out", tmp_path / "bad.sfanav",
                         "--resolve", "all")
    assert_one_line_error(code, err, "keep_images")
    code, out, err = run(capsys, "train", "--dataset", tmp_path / "a", "--out", tmp_path / "img.sfanav",
                         "--updatable", "--keep-images", *common)
    assert code == 0, err
    kept = sfanav.load(tmp_path / "img.sfanav")
    assert kept.readout_memory_.images.shape == (len(A), 8, 60, 3)
    code, out, err = run(capsys, "update", tmp_path / "img.sfanav", "--dataset", tmp_path / "b", "--resolve", "all",
                         "--out", tmp_path / "all.sfanav", "--no-progress")
    assert code == 0, err
    new_all = sfanav.load(tmp_path / "all.sfanav")
    ref_all = LocalizerUpdater(kept, UpdatePolicy(resolve="all")).partial_fit(Xb, YB).localizer_
    _close(new_all.predict(Xc), ref_all.predict(Xc), 1e-9)
    assert new_all.info["updates"][-1]["resolve"] == "all"
    code, out, err = run(capsys, "train", "--dataset", tmp_path / "a", "--out", tmp_path / "x.sfanav",
                         "--keep-images", *common)
    assert_one_line_error(code, err, "--updatable")
    # an automatic readout: chosen again over the runs when the kernel is learned, unless --readout keep
    code, out, err = run(capsys, "train", "--dataset", tmp_path / "a", "--out", tmp_path / "auto.sfanav",
                         "--updatable", "--config", tmp_path / "tiny.json", "--step", "10", "--no-progress")
    assert code == 0, err
    for extra, words in (((), "chosen again over the map's runs"), (("--readout", "keep"), "refitted on 70 views")):
        code, out, err = run(capsys, "update", tmp_path / "auto.sfanav", "--dataset", tmp_path / "b", "--kernel",
                             "learn", "--out", tmp_path / "auto2.sfanav", "--overwrite", "--no-progress", *extra)
        assert code == 0 and words in out, (out, err)
    code, out, err = run(capsys, "update", tmp_path / "auto.sfanav", "--dataset", tmp_path / "b", "--readout",
                         "again", "--out", tmp_path / "auto3.sfanav")
    assert code != 0 and not (tmp_path / "auto3.sfanav").exists()


def test_readout_augmentation_copies_are_kept_and_extended():
    from sfanav.data.corruptions import CAMERA

    u8 = [np.round(x * 255).astype(np.uint8) for x in (A, B, C)]
    loc = fit_localizer(Network(TINY), u8[0], YA, rotation=ROT, progress=False, readout="quadratic", n_outputs=5,
                        readout_augmentation=CAMERA, readout_memory=1000)
    mem = loc.readout_memory_
    assert mem.augmented is not None and mem.augmented[0].shape == mem.inputs.shape
    with pytest.raises(ValueError, match="corrupted copies"):
        LocalizerUpdater(loc)
    new = LocalizerUpdater(loc, augmentation=CAMERA).partial_fit(u8[1], YB).localizer_
    assert new.readout_memory_.augmented[0].shape == new.readout_memory_.inputs.shape == (70,) + mem.inputs.shape[1:]
    assert np.isfinite(new.predict(u8[2])).all() and new.n_augmented_ == 70


def test_resolve_all_trains_every_layer_again_on_the_remembered_images(tmp_path):
    """With a memory that keeps the images, resolve="all" equals training the
    localizer again on A + B (one sequence) with B's views paired to their
    nearest A views, to 1e-9; the memory keeps both runs' images and run
    labels; without images, or for a network alone, one clear error."""
    from sfanav.localization.updates import cross_run_pairs

    loc = fit_localizer(Network(TINY), A, YA, rotation=ROT, progress=False, readout="quadratic", n_outputs=5)
    remember(loc, A, YA, max_views=1000, keep_images=True)
    assert loc.readout_memory_.images.shape == A.shape
    up = LocalizerUpdater(loc, UpdatePolicy(resolve="all"), pair_radius=0.4, pair_max_turn_deg=None)
    new = up.partial_fit(B, YB).localizer_
    i, j = cross_run_pairs(YA, YB, 0.4)
    ref = fit_localizer(Network(TINY), np.concatenate([A, B]), np.concatenate([YA, YB]), rotation=ROT,
                        progress=False, readout={"kind": "quadratic", "n_outputs": 5, "ridge": 0.0, "degree": 2},
                        n_outputs=5, rotation_pooling=1, network_fit={"pairs": (i, len(A) + j, np.ones(len(i)))})
    _close(new.predict(C), ref.predict(C))
    mem = new.readout_memory_
    assert len(mem) == len(A) + len(B) and mem.runs.tolist() == [0] * len(A) + [1] * len(B)
    assert new.info["updates"][-1]["resolve"] == "all" and new.info["updates"][-1]["cross_run_pairs"] == len(i)
    # the memory survives the model file
    back = sfanav.load(new.save(tmp_path / "all.sfanav"))
    np.testing.assert_array_equal(back.readout_memory_.images, mem.images)
    assert back.readout_memory_.runs.tolist() == mem.runs.tolist()
    with pytest.raises(ValueError, match="keeps none"):
        LocalizerUpdater(_trained(readout="quadratic", n_outputs=5), UpdatePolicy(resolve="all"))
    with pytest.raises(ValueError, match="pair_max_turn_deg"):
        LocalizerUpdater(loc, UpdatePolicy(resolve="all"), pair_max_turn_deg=-1.0)
    with pytest.raises(ValueError, match="a network alone re-solves its top stage only"):
        NetworkUpdater(loc.network, UpdatePolicy(resolve="all"))


def test_resolve_all_pairs_only_views_that_face_the_same_way():
    """A second run through the first's places, half of its panoramas turned
    by 90 degrees: under resolve="all" only the pairs whose panoramas face
    the same way (within pair_max_turn_deg) join the runs, and the update
    equals the retrain with those pairs alone."""
    loc = fit_localizer(Network(TINY), A, YA, rotation=ROT, progress=False, readout="quadratic", n_outputs=5)
    remember(loc, A, YA, max_views=1000, keep_images=True)
    B2, Y2 = A[:30].copy(), YA[:30].copy()
    B2[1::2] = np.roll(B2[1::2], 15, axis=2)  # a quarter turn of 60 columns
    new = LocalizerUpdater(loc, UpdatePolicy(resolve="all"), pair_radius=0.01).partial_fit(B2, Y2).localizer_
    info = new.info["updates"][-1]
    assert info["cross_run_pairs"] == 15 and info["cross_run_pairs_turned"] == 15
    i = np.arange(0, 30, 2)
    ref = fit_localizer(Network(TINY), np.concatenate([A, B2]), np.concatenate([YA, Y2]), rotation=ROT,
                        progress=False, readout={"kind": "quadratic", "n_outputs": 5, "ridge": 0.0, "degree": 2},
                        n_outputs=5, rotation_pooling=1, network_fit={"pairs": (i, len(A) + i, np.ones(len(i)))})
    _close(new.predict(C), ref.predict(C))


def test_updates_keep_the_low_pass_widths():
    """A localizer whose photometric low-pass is not 2 px (the recipe's rows in degrees of elevation) keeps its
    widths through a top-stage update and through resolve="all", so the updated network sees images as before."""
    from sfanav.data.photometric import lowpass_log_contrast

    widths = (1.0, 2.0)
    loc = fit_localizer(Network(TINY), A, YA, rotation=ROT, progress=False, readout="quadratic", n_outputs=5,
                        photometric="lowpass-log-contrast", lowpass=widths, readout_memory=1000)
    top = LocalizerUpdater(loc).partial_fit(B, YB).solve()
    remember(loc, A, YA, max_views=1000, keep_images=True)
    every = LocalizerUpdater(loc, UpdatePolicy(resolve="all"), pair_radius=0.4).partial_fit(B, YB).solve()
    for new in (top, every):
        assert new.photometric_lowpass() == widths
        np.testing.assert_array_equal(new.normalized(C[:2]), lowpass_log_contrast(C[:2], sigma=widths))


def test_an_auto_readout_is_chosen_again_by_runs_when_the_kernel_is_learned():
    """readout="auto" (the default): a localizer whose readout was chosen
    automatically gets it chosen again, leave-one-run-out over the memory's
    runs, at a solve that learns the kernel again; exactly the selection
    select_auto_readout makes on the same features, signatures and run
    labels. readout="keep", a readout given by kind, or a solve that keeps
    the kernel refit the fitted kind."""
    from sfanav.localization.readout_selection import select_auto_readout

    loc = _trained(signature="fourier", rotation_pooling=3)  # readout="auto"
    assert loc.readout == "auto"
    new = LocalizerUpdater(loc, kernel="learn").partial_fit(B, YB).localizer_
    note = new.info["updates"][-1]["readout"]
    assert note.startswith("chosen again by runs") and "2 of 2 recordings held out" in note
    mem = new.readout_memory_
    assert mem.runs.tolist() == [0] * len(A) + [1] * len(B)
    F = top_stage_features(new.network, mem.inputs)
    ref = select_auto_readout(np.hstack([F, mem.signatures]), mem.positions, n_outputs=loc.n_outputs_ or None,
                              n_signature=mem.signatures.shape[1], groups=mem.runs)
    assert new.readout_spec_["kind"] == ref.spec["kind"] and new.selection_.rule == ref.rule
    np.testing.assert_allclose(new.selection_.scores, ref.scores, rtol=1e-9)
    assert new.readout == "auto"  # as the user gave it: the next update may choose again
    # refitted as fitted: on request, when the kernel is kept, and for a readout given by kind
    kept = LocalizerUpdater(loc, kernel="learn", readout="keep").partial_fit(B, YB).localizer_
    assert kept.info["updates"][-1]["readout"].startswith("refitted") and kept.selection_ is None
    assert kept.readout_spec_["kind"] == loc.readout_spec_["kind"]
    small = LocalizerUpdater(loc).partial_fit(B[:10], YB[:10]).localizer_  # 50 of 2 x 40: kernel kept
    assert small.info["updates"][-1]["readout"].startswith("refitted")
    by_kind = _trained(readout=SIG_GP, signature="fourier", rotation_pooling=3)
    assert LocalizerUpdater(by_kind, kernel="learn").partial_fit(B, YB).localizer_.info["updates"][-1][
        "readout"].startswith("refitted")
    with pytest.raises(ValueError, match="readout must be one of auto, keep"):
        LocalizerUpdater(loc, readout="again")
    # a run that explores new ground is not a recording of the same places: the kind is kept
    far = LocalizerUpdater(loc, kernel="learn").partial_fit(B, YB + 50.0).localizer_
    assert far.info["updates"][-1]["readout"].startswith("refitted") and far.selection_ is None


def test_runs_share_places():
    from sfanav.localization.updates import runs_share_places

    t = np.linspace(0, 6, 60)
    loop = np.c_[np.cos(t), np.sin(t)]
    assert runs_share_places(np.r_[loop, loop + 0.02, loop[::2]], np.repeat([0, 1, 2], [60, 60, 30]))
    assert not runs_share_places(np.r_[loop, loop + 0.02, loop[:30] + 9.0], np.repeat([0, 1, 2], [60, 60, 30]))
    half = np.r_[loop[:30], loop[:30] + 9.0]  # half of the second run on the first's ground: enough
    assert runs_share_places(np.r_[loop, half], np.repeat([0, 1], 60))
    assert not runs_share_places(loop, np.zeros(60))  # one run
    with pytest.raises(ValueError, match="one label per view"):
        runs_share_places(loop, np.zeros(59))


def test_resolve_all_chooses_an_auto_readout_again_by_runs():
    loc = fit_localizer(Network(TINY), A, YA, rotation=ROT, progress=False, signature="fourier")
    remember(loc, A, YA, max_views=1000, keep_images=True)
    new = LocalizerUpdater(loc, UpdatePolicy(resolve="all"), pair_radius=0.4).partial_fit(B, YB).localizer_
    assert new.info["updates"][-1]["readout"].startswith("chosen again by runs")
    assert "recordings held out" in new.selection_.rule and new.readout == "auto"
    kept = LocalizerUpdater(loc, UpdatePolicy(resolve="all"), pair_radius=0.4,
                            readout="keep").partial_fit(B, YB).localizer_
    assert kept.info["updates"][-1]["readout"].startswith("refitted")
