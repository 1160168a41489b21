"""The IncSFA peer of the update experiments (sfanav.experiments.incsfa_peer):
a localizer's top stage replaced by IncSFA fed that stage's training
sequence. On a run whose position moves slowly around a loop, enough passes
recover the exact top stage's slowest feature (one pass does not); the
readout is refitted on the IncSFA features of A's remembered and B's views;
bad arguments are refused."""

import numpy as np
import pytest
from sfanav import Network, Rotation
from sfanav.experiments.incsfa_peer import IncSFATopStage, canonical_correlations, incsfa_update
from sfanav.localization.training import fit_localizer
from sfanav.localization.updates import top_stage_features, top_stage_inputs

TINY = {
    "input": {"width": 60, "height": 8, "channels": 3},
    "network": {"precision": "double"},
    # a small top stage (5 inputs, 20 expanded): IncSFA whitens all of it
    "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 6}, {"rf": "full", "out": 3, "reduce_to": 5}],
}
ROT = Rotation(step=10)


def _loop(n, seed, phase=0.0):
    """Panoramas along one slow loop (the position), with pixel noise; the
    loop's (x, y)."""
    rng = np.random.default_rng(seed)
    t = 2 * np.pi * np.arange(n) / n + phase
    p = np.c_[np.sin(t), np.cos(t)]
    x = np.arange(60) * 2 * np.pi / 60
    y = np.arange(8)[:, None]
    out = np.empty((n, 8, 60, 3))
    for i in range(n):
        for c in range(3):
            out[i, :, :, c] = (np.sin(x + 1.5 * p[i, 0] + 0.3 * y) + 0.6 * np.cos(2 * x + 1.5 * p[i, 1] * (1 + c))
                               + 0.1 * rng.standard_normal((8, 60)))
    return np.clip((out + 2.5) / 5.0, 0.0, 1.0), 3 * p


(A, YA), (B, YB), (C, YC) = _loop(200, 1), _loop(60, 2, 0.05), _loop(30, 3, 0.1)


@pytest.fixture(scope="module")
def loc():
    return fit_localizer(Network(TINY), A, YA, rotation=ROT, progress=False, readout="quadratic", n_outputs=3,
                         readout_memory=1000)


def test_enough_passes_recover_the_exact_slowest_feature(loc):
    mem = loc.readout_memory_
    exact = top_stage_features(loc.network, mem.inputs)
    one = IncSFATopStage(loc, n_whitened=20, mca_rates=(0.5,)).partial_fit(A)
    many = IncSFATopStage(loc, n_whitened=20, mca_rates=(0.5,) * 8).partial_fit(A)
    assert many.degree_ == 2 and many.node_.n_components == loc.network.n_outputs_ == 3
    assert many.n_samples_ == 8 * len(A) * 6 and many.n_runs_ == 1  # 6 rotations of 60 px in steps of 10
    F1, F = one.features_of_inputs(mem.inputs), many.features_of_inputs(mem.inputs)
    assert F.shape == (len(A), 3) and np.isfinite(F).all()
    np.testing.assert_allclose(many.features(A), F, rtol=1e-9, atol=1e-12)
    corr = abs(np.corrcoef(F[:, 0], exact[:, 0])[0, 1])
    assert corr > 0.9  # the slowest feature, after 8 passes
    assert abs(np.corrcoef(F1[:, 0], exact[:, 0])[0, 1]) < corr  # one pass is not enough
    assert canonical_correlations(F, exact)[0] > 0.95


def test_readout_on_incsfa_features_predicts(loc):
    model, info = incsfa_update(loc, (A, YA), (B, YB), mca_rates=(0.5, 0.1, 0.02), n_whitened=20)
    assert info["readout_views"] == len(A) + len(B) and info["passes"] == 3 and len(info["agreement_a"]) == 3
    assert model.node_.mca_rate == 0.02 and model.n_samples_ == 3 * (len(A) + len(B)) * 6
    assert info["seconds_update"] > 0 and info["seconds_a"] > 0
    assert model.n_runs_ == 2 and model.readout_.readout_spec_["kind"] == "quadratic"
    P = model.predict(C)
    assert P.shape == (len(C), 2) and np.isfinite(P).all()
    # the readout reads the IncSFA's features of the views, pooled as the localizer pools
    G = model.features_of_inputs(top_stage_inputs(loc, C))
    np.testing.assert_allclose(model.readout_.predict_features(G), P)
    # fitted on the remembered views of A and B's views, at their positions
    np.testing.assert_allclose(model.readout_.training_positions_, np.concatenate([YA, YB]))


def test_the_readout_is_of_the_kind_the_exact_update_has():
    """like=: the peer's readout takes the kind and settings of the exact
    update's (here one that chose the nearest views over the runs), its
    kernel learned again; by default the stale localizer's kind."""
    from sfanav.experiments.incsfa_peer import memory_views, views_with_run
    from sfanav.localization.updates import LocalizerUpdater

    auto = fit_localizer(Network(TINY), A, YA, rotation=ROT, progress=False, signature="fourier",
                         readout_memory=1000)
    exact = LocalizerUpdater(auto, kernel="learn").partial_fit(B, YB).localizer_
    model = IncSFATopStage(auto, n_whitened=20, mca_rates=(0.5,)).partial_fit(A).partial_fit(B)
    views = views_with_run(auto, memory_views(auto.readout_memory_), B, YB)
    assert views.runs.tolist() == [0] * len(A) + [1] * len(B) and len(views) == len(exact.readout_memory_)
    np.testing.assert_allclose(views.inputs, exact.readout_memory_.inputs)
    model.fit_readout(views.inputs, views.positions, views.signatures, like=exact)
    assert model.readout_.readout_spec_["kind"] == exact.readout_spec_["kind"]
    model.fit_readout(views.inputs, views.positions, views.signatures)  # default: the stale kind
    assert model.readout_.readout_spec_["kind"] == auto.readout_spec_["kind"]
    # a readout of the nearest views by signature answers as the exact update's, whatever the top stage
    knn = fit_localizer(Network(TINY), A, YA, rotation=ROT, progress=False, signature="fourier",
                        readout={"kind": "knn-signature", "k": 1}, readout_memory=1000)
    exact_knn = LocalizerUpdater(knn).partial_fit(B, YB).localizer_
    peer = IncSFATopStage(knn, n_whitened=20, mca_rates=(0.5,)).partial_fit(A).partial_fit(B)
    v = views_with_run(knn, memory_views(knn.readout_memory_), B, YB)
    peer.fit_readout(v.inputs, v.positions, v.signatures, like=exact_knn)
    assert peer.readout_.readout_spec_["kind"] == "knn-signature"
    np.testing.assert_allclose(peer.predict(C), exact_knn.predict(C))


def test_canonical_correlations():
    rng = np.random.default_rng(0)
    F = rng.standard_normal((500, 3))
    mixed = F @ rng.standard_normal((3, 3)) + 5.0
    np.testing.assert_allclose(canonical_correlations(F, mixed), 1.0, atol=1e-9)
    assert canonical_correlations(F, rng.standard_normal((500, 2))).max() < 0.3
    with pytest.raises(ValueError, match="the same N"):
        canonical_correlations(F, F[:10])


def test_bad_arguments(loc):
    for rates in ((), (0.5, 0.0), (1.5,)):
        with pytest.raises(ValueError, match=r"mca_rates must be one or more numbers in \(0, 1\]"):
            IncSFATopStage(loc, mca_rates=rates)
    with pytest.raises(ValueError, match="fit the readout"):
        IncSFATopStage(loc, n_whitened=20).partial_fit(A[:20]).predict(C)
    with pytest.raises(ValueError, match="n_whitened must lie between"):
        IncSFATopStage(loc, n_whitened=21).partial_fit(A[:20])
