"""The readout of slow features with an appearance signature (the sfanav
default's): its likelihood's gradient, the choice between the combination
and the signature alone, state round trips, the Localizer that carries it,
and bad input."""

import numpy as np
import pytest
from scipy.optimize import approx_fprime

import sfanav
from sfanav.localization import (
    FourierSignature,
    Localizer,
    SignatureGPReadout,
    fourier_signature,
    make_readout,
    readout_from_state,
    readout_state,
    select_auto_readout,
)
from sfanav.sfa.modelfile import read_model


def _place_data(n, rng, slow_noise, sig_noise):
    """Positions in a 4 x 4 m square; slow features = a smooth code of the
    position plus noise; a 20-value 'signature' = another smooth code plus
    noise."""
    xy = rng.uniform(-2, 2, (n, 2))
    slow = np.column_stack([xy[:, 0], xy[:, 1], np.sin(xy[:, 0]), np.cos(xy[:, 1])])
    slow = slow + slow_noise * rng.normal(size=slow.shape)
    centres = rng.uniform(-3, 3, (20, 2))
    sig = 1.0 / (1.0 + np.hypot(*(xy[:, None, :] - centres[None]).transpose(2, 0, 1)))
    sig = sig + sig_noise * rng.normal(size=sig.shape)
    return xy, slow, sig


def test_likelihood_gradient_matches_finite_differences():
    rng = np.random.default_rng(1)
    S, G, Y = rng.normal(size=(30, 3)), rng.uniform(size=(30, 6)), rng.normal(size=(30, 2))
    r = SignatureGPReadout(3, 6)
    Dg = r._l1(G, G)
    for theta in (np.array([0.1, -0.2, 0.3, 0.5, np.log(1e-2)]), np.array([1.0, 0.5, -0.5, -1.0, np.log(1e-3)])):
        value, grad = r._neg_lml(theta, S, Dg, Y)
        num = approx_fprime(theta, lambda t: r._neg_lml(t, S, Dg, Y)[0], 1e-6)
        np.testing.assert_allclose(grad, num, rtol=1e-4, atol=1e-4)


def test_it_interpolates_a_smooth_map_and_beats_the_signature_nearest_neighbour():
    rng = np.random.default_rng(0)
    xy, slow, sig = _place_data(300, rng, 0.02, 0.0)
    xt, st, gt = _place_data(100, np.random.default_rng(5), 0.02, 0.0)
    # the same landmarks in both runs
    xy2, slow2, sig2 = _place_data(400, np.random.default_rng(0), 0.02, 0.0)
    xy, slow, sig, xt, st, gt = xy2[:300], slow2[:300], sig2[:300], xy2[300:], slow2[300:], sig2[300:]
    r = SignatureGPReadout(4, 20).fit(np.hstack([slow, sig]), xy)
    err = np.hypot(*(r.predict(np.hstack([st, gt])) - xt).T).mean()
    nn = xy[np.argmin(np.abs(gt[:, None] - sig[None]).sum(axis=2), axis=1)]
    err_nn = np.hypot(*(nn - xt).T).mean()
    assert err < 0.05 and err < 0.5 * err_nn
    assert r.length_scale_.shape == (4,) and r.signature_scale_ > 0 and r.noise_ > 0


@pytest.mark.parametrize("informative", ["slow", "signature"])
def test_the_choice_keeps_the_slow_features_only_where_they_code_position(informative):
    data = _place_data(400, np.random.default_rng(2), 0.01 if informative == "slow" else 3.0,
                       0.03 if informative == "slow" else 0.0)
    xy, slow, sig = data
    if informative == "signature":  # slow features that are pure noise
        slow = np.random.default_rng(3).normal(size=slow.shape)
    sel = select_auto_readout(np.hstack([slow, sig]), xy, n_signature=20)
    assert sel.spec["kind"] == "gp-signature" and sel.spec["n_signature"] == 20
    assert sel.spec["n_outputs"] == (4 if informative == "slow" else 0), sel.rule
    assert "BIC" in sel.rule


def test_state_round_trip_and_corrupt_state():
    xy, slow, sig = _place_data(80, np.random.default_rng(4), 0.02, 0.0)
    X = np.hstack([slow, sig])
    r = make_readout({"kind": "gp-signature", "n_outputs": 4, "n_signature": 20}).fit(X, xy)
    state = readout_state({"kind": "gp-signature", "n_outputs": 4, "n_signature": 20}, r)
    back = readout_from_state(state)
    np.testing.assert_allclose(back.predict(X[:7]), r.predict(X[:7]), rtol=1e-6, atol=1e-9)
    bad = dict(state["state"], G=state["state"]["G"][:, :5])
    with pytest.raises(ValueError, match="inconsistent"):
        SignatureGPReadout.from_state(bad)
    with pytest.raises(ValueError, match="positive"):
        SignatureGPReadout.from_state(dict(state["state"], signature_scale=-1.0))


def test_bad_input_is_refused():
    xy, slow, sig = _place_data(20, np.random.default_rng(6), 0.02, 0.0)
    with pytest.raises(ValueError, match="24 columns"):
        SignatureGPReadout(12, 20).fit(np.hstack([slow, sig]), xy)
    with pytest.raises(ValueError, match="same|length|rows"):
        SignatureGPReadout(4, 20).fit(np.hstack([slow, sig]), xy[:10])
    with pytest.raises(ValueError, match="at least 1"):
        SignatureGPReadout(4, 0)
    with pytest.raises(TypeError):
        SignatureGPReadout(4.5, 3)
    with pytest.raises(sfanav.NotFittedError):
        SignatureGPReadout(4, 20).predict(np.hstack([slow, sig]))
    with pytest.raises(ValueError, match="n_signature"):
        select_auto_readout(slow, xy, n_signature=99)


def test_fourier_signature_is_rotation_invariant_and_matches_the_peer():
    rng = np.random.default_rng(7)
    imgs = rng.integers(0, 255, (3, 6, 40, 3)).astype(np.uint8)
    g = fourier_signature(imgs, 15)
    assert g.shape == (3, 6 * 3 * 15) and g.dtype == np.float32
    np.testing.assert_allclose(fourier_signature(np.roll(imgs, 13, axis=2), 15), g, rtol=1e-4, atol=1e-2)
    peer = FourierSignature(15).fit(imgs, np.zeros((3, 2)))
    np.testing.assert_allclose(peer.transform(imgs).reshape(3, -1), g, rtol=1e-6)
    with pytest.raises(ValueError, match="n_coefficients"):
        fourier_signature(imgs, 30)


def _tiny_localizer(signature):
    net = sfanav.Network({"input": {"width": 24, "height": 4, "channels": 1},
                          "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 6, "degree": 2},
                                     {"rf": "full", "out": 4, "degree": 2}]})
    rng = np.random.default_rng(8)
    t = np.linspace(0, 6, 60)
    xy = np.column_stack([np.cos(t), np.sin(2 * t)])
    cols = np.arange(24)
    imgs = np.stack([np.sin(cols[None, :] * 0.3 + x) * np.ones((4, 1)) + 0.5 * y * np.cos(cols[None, :] * 0.6)
                     + 0.01 * rng.normal(size=(4, 24)) for x, y in xy]).astype(np.float64)
    net.fit(imgs, sfanav.Rotation(step=3, window=1.0), progress=False)
    return Localizer(net, signature=signature, rotation_pooling=None), imgs, xy


def test_localizer_with_a_signature_saves_loads_and_checks_its_input(tmp_path):
    loc, imgs, xy = _tiny_localizer("fourier")
    loc.fit(imgs, xy)
    assert loc.n_signature_ == 4 * 1 * 13  # rows x channels x coefficients (13 on 24-px panoramas)
    assert loc.describe_readout().startswith("gp-signature(")
    path = loc.save(tmp_path / "m.sfa")
    kind, state, manifest = read_model(path)
    assert manifest["version"] == 5 and state["signature"]["kind"] == "fourier"
    back = sfanav.load(path)
    np.testing.assert_allclose(back.predict(imgs[:5]), loc.predict(imgs[:5]), rtol=1e-6, atol=1e-9)
    F = loc.features(imgs)
    with pytest.raises(ValueError, match="signatures=localizer.signatures"):
        loc.predict_features(F)
    with pytest.raises(ValueError, match="signatures have"):
        loc.predict_features(F, signatures=loc.signatures(imgs)[:, :5])
    with pytest.raises(ValueError, match="signatures=localizer.signatures"):
        Localizer(loc.network, signature="fourier").fit_features(F, xy)
    with pytest.raises(ValueError, match="quadratic"):
        Localizer(loc.network, signature="fourier", readout="quadratic").fit(imgs, xy)
    with pytest.raises(ValueError, match="signature must be"):
        Localizer(loc.network, signature="colour").fit(imgs, xy)
    with pytest.raises(ValueError, match="reads none"):
        Localizer(loc.network, rotation_pooling=None).fit_features(F, xy, signatures=loc.signatures(imgs))


def test_a_localizer_without_a_signature_is_unchanged(tmp_path):
    loc, imgs, xy = _tiny_localizer(None)
    loc.fit(imgs, xy)
    assert loc.n_signature_ == 0 and not loc.describe_readout().startswith("gp-signature")
    _, state, manifest = read_model(loc.save(tmp_path / "m.sfa"))
    assert "signature" not in state and manifest["version"] < 5
    with pytest.raises(ValueError, match="reads no appearance signature"):
        loc.signatures(imgs)


def test_the_recipe_reads_the_signature_with_the_default_only():
    from sfanav.localization import recipe_for

    assert recipe_for().signature == "fourier" and recipe_for().name == "sfanav default"
    assert recipe_for("thesis-5.1").signature is None
    assert recipe_for(config=True).signature is None
    assert recipe_for(readout="quadratic").signature is None
    off = recipe_for(signature=None)
    assert off.signature is None and off.name == "custom"
    with pytest.raises(ValueError, match="signature must be"):
        recipe_for(signature="colour")


def test_cli_train_without_a_signature_and_a_refused_combination(tmp_path, capsys):
    from sfanav import sim
    from sfanav.app import cli

    ds = sim.simulate("realistic-garden", tmp_path / "d", 0, max_frames=30, camera=sim.PanoramicCamera(70, 8),
                      progress=False)
    model = tmp_path / "m.sfa"
    assert cli.main(["train", "--dataset", str(ds.root), "--out", str(model), "--no-progress",
                     "--signature", "none"]) == 0
    assert "readout gp-signature(" not in capsys.readouterr().out
    loc = sfanav.load(model)
    assert loc.n_signature_ == 0 and loc.signature is None
    with pytest.raises(SystemExit) as exc:
        cli.main(["train", "--dataset", str(ds.root), "--out", str(tmp_path / "q.sfa"), "--no-progress",
                  "--signature", "fourier", "--readout", "quadratic"])
    assert exc.value.code == 2 and "--signature fourier needs the auto readout" in capsys.readouterr().err
    assert not (tmp_path / "q.sfa").exists()


@pytest.mark.parametrize("factor", [1e-3, 7.0, 255.0])
def test_the_signature_scale_does_not_matter(factor):
    """Distances are measured in units of the median training distance: a
    signature in other units (e.g. images in [0, 1] instead of [0, 255])
    gives the same fit."""
    xy, slow, sig = _place_data(120, np.random.default_rng(9), 0.02, 0.0)
    a = SignatureGPReadout(4, 20).fit(np.hstack([slow, sig]), xy)
    b = SignatureGPReadout(4, 20).fit(np.hstack([slow, factor * sig]), xy)
    np.testing.assert_allclose(b.predict(np.hstack([slow[:9], factor * sig[:9]])), a.predict(np.hstack([slow[:9], sig[:9]])),
                               atol=1e-3)


def test_a_fit_with_kept_hyperparameters_equals_the_learned_fit_on_the_same_data():
    """Refitting with the hyperparameters of a fit on the same data reproduces
    its posterior (the random-split protocol's shortcut); a resample keeps
    the kernel and only refits the posterior; mismatched shapes are refused."""
    rng = np.random.default_rng(3)
    xy, slow, sig = _place_data(200, rng, 0.02, 0.01)
    F = np.hstack([slow, sig])
    a = SignatureGPReadout(4, 20).fit(F, xy)
    b = SignatureGPReadout(4, 20).fit(F, xy, hyperparameters_from=a)
    np.testing.assert_allclose(b.predict(F[:20]), a.predict(F[:20]), rtol=1e-9, atol=1e-9)
    assert np.isclose(b.log_marginal_likelihood_, a.log_marginal_likelihood_, rtol=1e-6)
    c = SignatureGPReadout(4, 20).fit(F[::2], xy[::2], hyperparameters_from=a)
    np.testing.assert_array_equal(c.length_scale_, a.length_scale_)
    assert c.noise_ == a.noise_ and c.signature_scale_ == a.signature_scale_
    assert np.hypot(*(c.predict(F[1::2]) - xy[1::2]).T).mean() < 0.1
    with pytest.raises(ValueError, match="reads 4 slow features"):
        SignatureGPReadout(3, 20).fit(F, xy, hyperparameters_from=a)
    with pytest.raises(TypeError, match="fitted SignatureGPReadout"):
        SignatureGPReadout(4, 20).fit(F, xy, hyperparameters_from=SignatureGPReadout(4, 20))
    # the same kernel given as constructor parameters (what a model's spec carries)
    d = SignatureGPReadout(4, 20, **a.hyperparameters()).fit(F, xy)
    np.testing.assert_allclose(d.predict(F[:20]), a.predict(F[:20]), rtol=1e-9, atol=1e-9)
    with pytest.raises(ValueError, match="length_scale, signature_scale and noise"):
        SignatureGPReadout(4, 20, length_scale=[1.0] * 4, noise=0.1)
    with pytest.raises(ValueError, match="length_scale must be 4 positive"):
        SignatureGPReadout(4, 20, length_scale=[1.0] * 3, signature_scale=1.0, noise=0.1)
    with pytest.raises(ValueError, match="noise must be a positive finite"):
        SignatureGPReadout(4, 20, length_scale=[1.0] * 4, signature_scale=1.0, noise=float("nan"))
    with pytest.raises(sfanav.NotFittedError):
        SignatureGPReadout(4, 20).hyperparameters()


def test_training_predictions_are_the_posterior_mean_at_the_training_samples():
    """Computed from the fit (Y - noise * dual) they equal predict() on the
    training features (up to the float32 signatures predict reads); None
    after a model-file round trip."""
    rng = np.random.default_rng(5)
    xy, slow, sig = _place_data(150, rng, 0.02, 0.01)
    F = np.hstack([slow, sig])
    r = SignatureGPReadout(4, 20).fit(F, xy)
    np.testing.assert_allclose(r.training_predictions_, r.predict(F), atol=1e-6)
    thinned = SignatureGPReadout(4, 20, max_train=100).fit(F, xy)  # the DTC posterior's, from the cached distances
    np.testing.assert_allclose(thinned.training_predictions_, thinned.predict(F), atol=1e-4)
    assert SignatureGPReadout.from_state(r.get_state()).training_predictions_ is None


def _kernel(r, A, B):
    """The fitted readout's kernel between feature rows A and B, evaluated
    directly (float64 signatures)."""
    S_a, G_a = r._split(A)
    S_b, G_b = r._split(B)
    Za, Zb = (S_a - r.mean_) / r.scale_ / r.length_scale_, (S_b - r.mean_) / r.scale_ / r.length_scale_
    d2 = ((Za[:, None, :] - Zb[None]) ** 2).sum(axis=2)
    d1 = np.abs(G_a[:, None, :] - G_b[None]).sum(axis=2)
    return np.exp(-0.5 * d2 - d1 / (r.distance_unit_ * r.signature_scale_))


def _dtc_check(r, F, xy, inducing):
    """The readout's predictions at F against the DTC normal equations solved
    directly with those inducing samples and the readout's kernel."""
    kept = F[inducing]
    Knm, Kmm = _kernel(r, F, kept), _kernel(r, kept, kept)
    w = np.linalg.solve(Knm.T @ Knm + r.noise_ * Kmm, Knm.T @ (xy - xy.mean(axis=0)))
    np.testing.assert_allclose(r.predict(F), Knm @ w + xy.mean(axis=0), atol=2e-3)
    return Knm, Kmm


def test_a_thinned_fit_is_the_dtc_posterior_of_every_sample():
    """With max_train below N the weights of the kept samples minimise
    |Y - mean - K_nm w|^2 + noise w' K_mm w over all N samples (the normal
    equations solved directly here), not the kept samples' exact GP; the
    training predictions are its posterior mean at the N samples."""
    rng = np.random.default_rng(7)
    xy, slow, sig = _place_data(240, rng, 0.02, 0.01)
    F = np.hstack([slow, sig])
    r = SignatureGPReadout(4, 20, max_train=60).fit(F, xy)
    assert r.inducing_.shape == (60,) and len(np.unique(r.inducing_)) == 60 and r.inducing_[0] == 0
    Knm, Kmm = _dtc_check(r, F, xy, r.inducing_)
    np.testing.assert_allclose(r.training_predictions_, r.predict(F), atol=1e-4)
    # it uses what the thinning dropped: closer to the full GP than the kept samples' exact GP
    full = SignatureGPReadout(4, 20, **r.hyperparameters()).fit(F, xy).predict(F)
    subset_gp = np.linalg.solve(Kmm + r.noise_ * np.eye(60), xy[r.inducing_] - xy.mean(axis=0))
    assert np.abs(r.predict(F) - full).mean() < np.abs(Knm @ subset_gp + xy.mean(axis=0) - full).mean()


def test_the_inducing_samples_cover_the_run_farthest_first():
    """A run that lingers: 200 samples in one corner, 100 over the rest.
    Evenly spaced inducing samples crowd the corner; farthest-first ones
    cover the whole run better (the least covered sample's largest kernel
    value is higher). With every place twice (an image beside its corrupted
    copy) and fewer inducing samples than places, no place is taken twice."""
    rng = np.random.default_rng(11)
    xy = rng.uniform(-2, 2, (300, 2))
    xy[:200] = 0.2 * xy[:200] - 1.6  # the corner
    centres = rng.uniform(-3, 3, (20, 2))
    sig = 1.0 / (1.0 + np.hypot(*(xy[:, None, :] - centres[None]).transpose(2, 0, 1)))
    F = np.hstack([np.column_stack([xy[:, 0], xy[:, 1], np.sin(xy[:, 0]), np.cos(xy[:, 1])]), sig])
    kw = dict(length_scale=[0.3] * 4, signature_scale=0.5, noise=1e-3)
    r = SignatureGPReadout(4, 20, max_train=40, **kw).fit(F, xy)
    even = np.unique(np.linspace(0, 299, 40).round().astype(int))
    worst = lambda ind: _kernel(r, F, F[ind]).max(axis=1).min()  # the least covered sample's best kernel value
    assert worst(r.inducing_) > worst(even)
    F2 = np.stack([F, F + 1e-3 * rng.normal(size=F.shape)], axis=1).reshape(600, -1)
    r2 = SignatureGPReadout(4, 20, max_train=250, **kw).fit(F2, np.repeat(xy, 2, axis=0))
    assert len(np.unique(r2.inducing_ // 2)) == 250


def test_a_run_too_long_for_the_distance_cache_keeps_evenly_spaced_samples(monkeypatch):
    """Without room for the distance table the inducing samples are evenly
    spaced and the distances computed per block: still the DTC posterior,
    without training predictions."""
    import sfanav.localization.signature_readout as sr

    rng = np.random.default_rng(9)
    xy, slow, sig = _place_data(200, rng, 0.02, 0.01)
    F = np.hstack([slow, sig])
    monkeypatch.setattr(sr, "_DISTANCE_CACHE_BYTES", 0)
    r = SignatureGPReadout(4, 20, max_train=50).fit(F, xy)
    even = np.unique(np.linspace(0, 199, 50).round().astype(int))
    np.testing.assert_array_equal(r.inducing_, even)
    _dtc_check(r, F, xy, even)
    assert r.training_predictions_ is None
