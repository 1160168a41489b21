"""The readout by the nearest training views' signatures, leave-one-recording-
out folds, and the default readout's choice between it and the GP when the
training set is several recordings of the same places."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import cdist

import sfanav
from sfanav.localization import (
    Localizer,
    SignatureKNNReadout,
    fit_localizer,
    group_folds,
    make_readout,
    readout_from_state,
    readout_state,
    select_auto_readout,
)
from sfanav.localization.signature_distance import l1_distances
from sfanav.sfa.modelfile import read_model


def _naive_knn(G_tr, y_tr, G_q, k):
    out = []
    for g in G_q:
        d = np.abs(G_tr - g).sum(axis=1)
        idx = np.argsort(d, kind="stable")[:k]
        w = 1.0 / np.maximum(d[idx], 1e-12)
        out.append((w[:, None] * y_tr[idx]).sum(axis=0) / w.sum())
    return np.array(out)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 40), m=st.integers(1, 30), q=st.integers(1, 9), chunk=st.integers(1, 16),
       seed=st.integers(0, 2**31 - 1))
def test_l1_distances_equal_scipys_cityblock(n, m, q, chunk, seed):
    rng = np.random.default_rng(seed)
    A, B = rng.normal(size=(n, q)), rng.normal(size=(m, q))
    np.testing.assert_allclose(l1_distances(A, B, chunk=chunk), cdist(A, B, "cityblock"), rtol=1e-12, atol=1e-12)
    assert l1_distances(A, B, dtype=np.float32).dtype == np.float32


@pytest.mark.parametrize("k", [1, 3])
def test_knn_readout_equals_a_naive_search(k):
    rng = np.random.default_rng(0)
    G, xy = rng.uniform(size=(50, 7)), rng.uniform(-3, 3, (50, 2))
    F = np.hstack([rng.normal(size=(50, 4)), G])  # slow features before the signature are ignored
    Q = np.hstack([rng.normal(size=(20, 4)), rng.uniform(size=(20, 7))])
    r = SignatureKNNReadout(n_signature=7, k=k).fit(F, xy)
    np.testing.assert_allclose(r.predict(Q), _naive_knn(G.astype(np.float32).astype(float), xy, Q[:, 4:], k),
                               rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(r.predict(F[:5]), xy[:5], atol=1e-5)  # a stored view answers with its place


def test_views_choose_what_is_stored_and_max_train_thins_evenly():
    rng = np.random.default_rng(1)
    G, xy = rng.uniform(size=(40, 5)), rng.uniform(size=(40, 2))
    r = SignatureKNNReadout(5).fit(G, xy, views=np.arange(0, 40, 2))
    assert r.G_.shape == (20, 5) and r.views_.tolist() == list(range(0, 40, 2))
    np.testing.assert_allclose(r.predict(G[1::2]), _naive_knn(G[0::2], xy[0::2], G[1::2], 1), atol=1e-6)
    t = SignatureKNNReadout(5, max_train=10).fit(G, xy)
    assert t.views_.tolist() == np.linspace(0, 39, 10).round().astype(int).tolist()


def test_state_round_trip_and_bad_input():
    rng = np.random.default_rng(2)
    G, xy = rng.uniform(size=(30, 6)), rng.uniform(size=(30, 2))
    spec = {"kind": "knn-signature", "n_outputs": 0, "n_signature": 6, "k": 3}
    r = make_readout(spec).fit(G, xy)
    back = readout_from_state(readout_state(spec, r))
    np.testing.assert_allclose(back.predict(G[:4] + 0.01), r.predict(G[:4] + 0.01))
    state = readout_state(spec, r)["state"]
    with pytest.raises(ValueError, match="inconsistent"):
        SignatureKNNReadout.from_state(dict(state, G=state["G"][:, :3]))
    with pytest.raises(ValueError, match="non-finite"):
        SignatureKNNReadout.from_state(dict(state, y=np.full_like(state["y"], np.nan)))
    with pytest.raises(ValueError, match="n_outputs must be 0"):
        SignatureKNNReadout(6, n_outputs=4)
    with pytest.raises(ValueError, match="at least 1"):
        SignatureKNNReadout(6, k=0)
    with pytest.raises(ValueError, match="signature of 9"):
        SignatureKNNReadout(9).fit(G, xy)
    with pytest.raises(ValueError, match="views must index"):
        SignatureKNNReadout(6).fit(G, xy, views=[0, 30])
    with pytest.raises(ValueError, match="views must be"):
        SignatureKNNReadout(6).fit(G, xy, views=[])
    with pytest.raises(sfanav.NotFittedError):
        SignatureKNNReadout(6).predict(G)


def test_group_folds_hold_out_each_recording_once():
    g = np.array(["b", "b", "a", "c", "a", "b", "d"])
    folds = group_folds(g)
    assert [sorted(set(g[h])) for _, h in folds] == [["b"], ["a"], ["c"], ["d"]]  # order of first appearance
    for tr, held in folds:
        assert set(g[tr]).isdisjoint(g[held]) and len(tr) + len(held) == len(g)
    assert [sorted(set(g[h])) for _, h in group_folds(g, max_folds=2)] == [["b"], ["d"]]
    with pytest.raises(ValueError, match="at least 2 groups"):
        group_folds(["a", "a"])
    with pytest.raises(ValueError, match="1-D"):
        group_folds(np.zeros((3, 2)))


def _recordings(n_rec=4, n_places=60, invariant_slow=False, seed=0):
    """``n_rec`` recordings of one loop of ``n_places`` places, place-major.
    The signature is the same code of the place in every recording (plus a
    little noise); the slow features code the place too but, unless
    ``invariant_slow``, shifted by each recording's own offset (features that
    are not invariant to its light)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n_places, endpoint=False)
    place_xy = np.column_stack([3 * np.cos(t), 2 * np.sin(t)])
    centres = np.random.default_rng(100).uniform(-4, 4, (12, 2))  # the same places in every call
    code = 1.0 / (1.0 + np.hypot(*(place_xy[:, None, :] - centres[None]).transpose(2, 0, 1)))
    F, xy, rec = [], [], []
    for p in range(n_places):
        for r in range(n_rec):
            shift = 0.0 if invariant_slow else 0.6 * np.sin(1.7 * r + np.arange(4))
            slow = np.r_[place_xy[p], np.sin(t[p]), np.cos(2 * t[p])] + shift + 0.01 * rng.normal(size=4)
            sig = code[p] + (0.3 if invariant_slow else 0.002) * rng.normal(size=12)
            F.append(np.r_[slow, sig])
            xy.append(place_xy[p] + 0.01 * rng.normal(size=2))
            rec.append(f"light{r}")
    return np.array(F), np.array(xy), np.array(rec)


def test_several_recordings_choose_the_nearest_views_when_the_slow_features_are_not_invariant():
    F, xy, rec = _recordings()
    sel = select_auto_readout(F, xy, n_signature=12, groups=rec)
    assert sel.spec["kind"] == "knn-signature" and "leave-one-recording-out" in sel.rule, sel.rule
    assert sel.scores[1 + SIGNATURE_K.index(sel.spec["k"])] < 0.9 * sel.scores[0]
    # one recording: no recordings to hold out, the GP as before
    one = select_auto_readout(F, xy, n_signature=12)
    assert one.spec["kind"] == "gp-signature" and "leave-one" not in one.rule
    # a new light: shifted slow features, the same places' signatures
    Ft, xyt, _ = _recordings(n_rec=5, seed=1)
    Ft, xyt = Ft[4::5], xyt[4::5]
    err = lambda r: np.hypot(*(r.predict(Ft) - xyt).T).mean()  # noqa: E731
    assert err(sel.readout) < err(one.readout)


def test_several_recordings_keep_the_gp_when_the_slow_features_are_invariant():
    F, xy, rec = _recordings(invariant_slow=True)
    sel = select_auto_readout(F, xy, n_signature=12, groups=rec)
    assert sel.spec["kind"] == "gp-signature" and "not 10% lower" in sel.rule, sel.rule


def test_bad_groups_are_refused():
    F, xy, rec = _recordings(n_rec=2, n_places=20)
    with pytest.raises(ValueError, match="one label per training sample"):
        select_auto_readout(F, xy, n_signature=12, groups=rec[:-1])
    with pytest.raises(ValueError, match="NaN"):
        select_auto_readout(F, xy, n_signature=12, groups=np.r_[np.nan, np.zeros(len(F) - 1)])
    with pytest.raises(ValueError, match="views must be"):
        select_auto_readout(F, xy, n_signature=12, groups=rec, views=[len(F)])


SIGNATURE_K = list(sfanav.localization.readout_selection.SIGNATURE_KNN_K)


def _tiny_net():
    return sfanav.Network({"input": {"width": 24, "height": 4, "channels": 1},
                           "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 6, "degree": 2},
                                      {"rf": "full", "out": 4, "degree": 2}]})


def _tiny_recordings(n_rec=3, n=40):
    """Images of one loop in ``n_rec`` lights (brightness and contrast of each
    recording its own), place-major."""
    t = np.linspace(0, 6, n)
    xy = np.column_stack([np.cos(t), np.sin(2 * t)])
    cols = np.arange(24)
    rng = np.random.default_rng(8)
    imgs, pos, rec = [], [], []
    for i in range(n):
        for r in range(n_rec):
            x, y = xy[i]
            img = np.sin(cols[None, :] * 0.3 + x) * np.ones((4, 1)) + 0.5 * y * np.cos(cols[None, :] * 0.6)
            imgs.append(np.clip(110 + (40 + 10 * r) * img + 15 * r + rng.normal(0, 1, (4, 24)), 0, 255))
            pos.append(xy[i])
            rec.append(r)
    return np.array(imgs).astype(np.uint8), np.array(pos), np.array(rec)


def test_a_localizer_with_copies_stores_only_the_originals_and_round_trips(tmp_path):
    from sfanav.data.corruptions import CAMERA

    imgs, xy, rec = _tiny_recordings()
    loc = fit_localizer(_tiny_net(), imgs, xy, rotation=sfanav.Rotation(step=3, window=1.0), progress=False,
                        rotation_pooling=None, signature="fourier",
                        readout={"kind": "knn-signature", "k": 1}, readout_augmentation=CAMERA, groups=rec)
    assert loc.readout_spec_["kind"] == "knn-signature" and loc.readout_spec_["n_outputs"] == 0
    assert len(loc.regression_.G_) == len(imgs)  # the originals, not their corrupted copies
    np.testing.assert_allclose(loc.predict(imgs[:6]), xy[:6], atol=1e-9)
    path = loc.save(tmp_path / "m.sfa")
    assert read_model(path)[2]["version"] == 7  # format 7: older readers refuse the nearest views
    back = sfanav.load(path)
    np.testing.assert_allclose(back.predict(imgs[::7]), loc.predict(imgs[::7]), atol=1e-9)
    # the default readout with the recordings: a choice with a rule that names them
    auto = fit_localizer(_tiny_net(), imgs, xy, rotation=sfanav.Rotation(step=3, window=1.0), progress=False,
                         rotation_pooling=None, signature="fourier", groups=rec)
    assert "leave-one-recording-out CV (3 of 3 recordings held out)" in auto.info["readout_rule"]


def test_groups_of_the_wrong_length_fail_before_training():
    imgs, xy, rec = _tiny_recordings(n_rec=2, n=10)
    net = _tiny_net()
    with pytest.raises(ValueError, match="one label per training image"):
        fit_localizer(net, imgs, xy, progress=False, groups=rec[:-1])
    loc = Localizer(net, signature="fourier", rotation_pooling=None)
    with pytest.raises(ValueError, match="one label per image"):
        loc.fit_features(np.zeros((20, 4)), xy, signatures=np.zeros((20, 3)),
                         augmented=(np.zeros((20, 4)), np.zeros((20, 3))), groups=rec[:-1])


def test_cli_train_chooses_the_readout_by_recordings(tmp_path, capsys):
    from clitools import assert_one_line_error, run

    from sfanav import sim

    ds = sim.simulate("thesis-6.2.2-conditions", tmp_path / "d", 0, max_frames=8,
                      camera=sim.PanoramicCamera(70, 8), progress=False)
    model = tmp_path / "m.sfa"
    code, out, err = run(capsys, "train", "--dataset", str(ds.root), "--out", str(model), "--no-progress")
    assert code == 0, err
    assert "10 recordings (auto)" in out + err
    assert "leave-one-recording-out CV (5 of 10 recordings held out)" in sfanav.load(model).info["readout_rule"]
    code, out, err = run(capsys, "train", "--dataset", str(ds.root), "--out", str(tmp_path / "r.sfa"),
                         "--no-progress", "--recordings", "runs")
    assert_one_line_error(code, err, "--recordings runs", "one run")
    assert not (tmp_path / "r.sfa").exists()


def test_without_a_signature_groups_replace_the_blocks_of_the_cv():
    F, xy, rec = _recordings(n_rec=3, n_places=30)
    sel = select_auto_readout(F[:, :4], xy, groups=rec)
    assert "leave-one-group-out CV (3 of 3 groups held out)" in sel.rule, sel.rule
    assert "blocked" in select_auto_readout(F[:, :4], xy).rule


def test_a_localizer_reading_the_signature_alone_takes_updates():
    """Its readout reads no slow feature (n_outputs 0): an update refits it on the old and new views."""
    from sfanav.localization.updates import LocalizerUpdater

    imgs, xy, rec = _tiny_recordings()
    old = rec < 2
    for spec in ({"kind": "knn-signature", "k": 1}, {"kind": "gp-signature", "n_outputs": 0}):
        loc = fit_localizer(_tiny_net(), imgs[old], xy[old], rotation=sfanav.Rotation(step=3, window=1.0),
                            progress=False, rotation_pooling=None, signature="fourier", readout=spec,
                            readout_memory=1000)
        new = LocalizerUpdater(loc).partial_fit(imgs[~old], xy[~old]).solve()
        assert new.readout_spec_["kind"] == spec["kind"] and new.readout_spec_["n_outputs"] == 0
        if spec["kind"] == "knn-signature":  # the new run's views are stored: they answer with their places
            assert len(new.regression_.G_) == len(imgs)
            np.testing.assert_allclose(new.predict(imgs[~old][:5]), xy[~old][:5], atol=1e-9)
