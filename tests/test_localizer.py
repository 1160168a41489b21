"""sfanav.Localizer on a tiny toy world: fit, predict, evaluate, save/load."""

import numpy as np
import pytest

import sfanav
from sfanav.localization import pooling_step
from sfanav.sfa import eta_values
from sfanav.localization import error_vs_n

# A tiny world as in test_network.py (copied so the two files evolve independently).
LANDMARKS = np.array([[-1.0, -0.6], [1.6, -0.4], [0.4, 1.8], [-0.8, 1.5], [2.0, 1.2], [0.5, -1.4]])
HEIGHTS = np.array([0.9, 0.5, 1.2, 0.7, 1.0, 0.6])
SIZE = 2.0  # the unit square of the toy renderer is a 2 x 2 m area


def render(xy, heading, width=48, height=8):
    """A toy panorama at position xy (unit square) facing `heading` (rad)."""
    az = 2 * np.pi * np.arange(width) / width + heading
    rows = (np.arange(height)[::-1] + 0.5) / height
    img = np.zeros((height, width))
    for (lx, ly), hgt in zip(LANDMARKS, HEIGHTS):
        d = np.hypot(lx - xy[0], ly - xy[1])
        ang = np.arctan2(ly - xy[1], lx - xy[0])
        diff = np.angle(np.exp(1j * (az - ang)))
        top = np.clip(hgt / d, 0, 1.5)
        vertical = 1.0 / (1.0 + np.exp((rows[:, None] - top) / 0.15))
        img += np.exp(-(diff / (0.25 / d)) ** 2)[None, :] * vertical * (1.0 / d)
    return img + 0.2 * rows[:, None]


def grid_run(n_lines, per_line, seed):
    """Boustrophedon exploration over the unit square with a random heading walk."""
    rng = np.random.default_rng(seed)
    pts = []
    for i, y in enumerate(np.linspace(0.02, 0.98, n_lines)):
        xs = np.linspace(0.02, 0.98, per_line)
        pts += [(x, y) for x in (xs if i % 2 == 0 else xs[::-1])]
    xy = np.array(pts)
    return xy, np.cumsum(rng.standard_normal(len(xy)) * 0.2)


def tiny_config(top_out=6):
    return {
        "input": {"width": 48, "height": 8, "channels": 1},
        "layers": [{"rf": [6, 4], "stride": [3, 2], "out": 8}, {"rf": "full", "out": top_out}],
    }


@pytest.fixture(scope="module")
def world():
    xy, heading = grid_run(12, 40, seed=0)
    imgs = np.stack([render(p, h) for p, h in zip(xy, heading)])
    rng = np.random.default_rng(5)
    txy = rng.uniform(0.05, 0.95, (120, 2))
    timgs = np.stack([render(p, h) for p, h in zip(txy, rng.uniform(0, 2 * np.pi, 120))])
    net = sfanav.Network(tiny_config()).fit(imgs, sfanav.Rotation(step=4), progress=False)
    return net, imgs, SIZE * xy, timgs, SIZE * txy


@pytest.fixture(scope="module")
def fitted(world):
    net, imgs, xy, *_ = world
    return sfanav.Localizer(net, n_outputs=6).fit(imgs, xy)


def test_localizes_a_separate_test_run(world, fitted):
    net, imgs, xy, timgs, txy = world
    pred = fitted.predict(timgs)
    assert pred.shape == (120, 2)
    m = fitted.evaluate(timgs, txy)
    assert m["med"] < 0.25, m  # 2 x 2 m area; guessing the center gives about 0.75 m
    assert fitted.score(timgs, txy) == pytest.approx(m["med"])
    assert fitted.train_metrics_["med"] < m["med"] + 0.1
    # the default pools its features over 8 rotations: rotations=True has nothing left to average
    assert fitted.rotation_pooling_ == 8
    with pytest.raises(ValueError, match="averages its features over 8 rotations"):
        fitted.predict(timgs[:2], rotations=True)
    # one image in, one position out
    np.testing.assert_allclose(fitted.predict(timgs[3]), pred[3])


def test_without_pooling_rotations_average_the_estimates(world):
    net, imgs, xy, timgs, txy = world
    plain = sfanav.Localizer(net, n_outputs=6, rotation_pooling=None).fit(imgs, xy)
    assert plain.rotation_pooling_ == 1
    pred = plain.predict(timgs[:20])
    rot = plain.predict(timgs[:20], rotations=True)  # mean over the simulated rotations
    assert rot.shape == (20, 2) and np.abs(rot - pred).mean() < 0.2
    Fr = net.transform(timgs[:10], rotations=True)  # (10, K, 6)
    np.testing.assert_allclose(plain.predict_features(Fr), plain.predict(timgs[:10], rotations=True), atol=1e-10)


def test_rotation_pooling_is_the_mean_over_evenly_spaced_rotations(world, fitted):
    net, imgs, xy, timgs, txy = world
    W = timgs.shape[2]  # 48 px
    step = pooling_step(net, W, 8)
    assert step >= W // 8 and -(-W // step) <= 8
    F = fitted.features(timgs[:10])
    np.testing.assert_allclose(F, net.transform(timgs[:10], rotations=True, step=step).mean(axis=1), atol=1e-12)
    # under rotations by any angle the pooled features move much less than the network's own outputs
    shifts = [np.roll(timgs[:10], s, axis=2) for s in range(0, W, 5)]
    spread_pooled = np.std([fitted.features(a) for a in shifts], axis=0).mean()
    spread_plain = np.std([net.transform(a) for a in shifts], axis=0).mean()
    assert spread_pooled < 0.75 * spread_plain, (spread_pooled, spread_plain)  # measured 0.54x
    # pooling over all W rotations (steps of 1 px) is exactly rotation invariant
    full = sfanav.Localizer(net, n_outputs=6, rotation_pooling=W).fit(imgs[:60], xy[:60])
    Ff = full.features(timgs[:5])
    for s in (1, 7, 30):
        np.testing.assert_allclose(full.features(np.roll(timgs[:5], s, axis=2)), Ff, atol=1e-9)


def test_pooling_step_is_coprime_with_the_receptive_field_grid():
    """Pooled rotations must not all share one alignment of the network's RF grid."""
    import math

    default = sfanav.Network.from_preset("sfanav-default")  # horizontal strides 5, 3, 2, 1: period 30
    assert pooling_step(default, 350, 8) == 47  # ceil(350 / 8) = 44 shares a factor 2 with 30
    thesis = sfanav.Network.from_preset("thesis-5.2")
    period = math.prod(layer["stride"][0] for layer in thesis.config_["layers"])
    step = pooling_step(thesis, 600, 8)
    assert step >= 75 and math.gcd(step, period) == 1 and -(-600 // step) <= 8
    flat = sfanav.Network({"input": {"width": 20, "height": 4, "channels": 1},
                           "layers": [{"rf": "full", "out": 2}]})
    assert pooling_step(flat, 350, 8) == 44  # stride 1: any step


def test_rotation_pooling_parameter_is_checked(world):
    net, imgs, xy, *_ = world
    for bad, exc in (("all", ValueError), (0, ValueError), (2.5, TypeError), (True, TypeError)):
        with pytest.raises(exc, match="rotation_pooling"):
            sfanav.Localizer(net, rotation_pooling=bad).fit(imgs[:40], xy[:40])
    with pytest.raises(ValueError, match="at least 60 px wide"):
        sfanav.Localizer(net, rotation_pooling=60).fit(imgs[:40], xy[:40])
    # the thesis's quadratic readout is not pooled by default; a features-only localizer neither
    assert sfanav.Localizer(net, n_outputs=6, readout="quadratic").fit(imgs, xy).rotation_pooling_ == 1
    assert sfanav.Localizer(None, n_outputs=4).fit_features(net.transform(imgs), xy).rotation_pooling_ == 1


def test_features_api_matches_the_image_api(world, fitted):
    net, imgs, xy, timgs, txy = world
    F, Ft = fitted.features(imgs), fitted.features(timgs)  # rotation pooled, as the localizer's readout sees them
    loc = sfanav.Localizer(net, n_outputs=6).fit_features(F, xy)
    np.testing.assert_allclose(loc.predict_features(Ft), fitted.predict(timgs), atol=1e-10)
    # features-only localizer (no network)
    bare = sfanav.Localizer(None, n_outputs=4).fit_features(F, xy)
    assert bare.evaluate_features(Ft, txy)["med"] < 0.4
    with pytest.raises(ValueError, match="has no network"):
        bare.predict(timgs)


def test_save_load_round_trip(world, fitted, tmp_path):
    _, _, _, timgs, _ = world
    path = fitted.save(tmp_path / "loc.sfa")
    back = sfanav.load(path)
    assert isinstance(back, sfanav.Localizer) and isinstance(back.network, sfanav.Network)
    np.testing.assert_array_equal(back.predict(timgs), fitted.predict(timgs))
    assert back.n_outputs == 6 and back.train_metrics_ == fitted.train_metrics_
    assert back.rotation_pooling_ == 8 and back.rotation_pooling == "auto"
    assert sfanav.sfa.read_model(path)[2]["version"] == 4  # pooled features: format 4
    F = fitted.features(timgs)
    bare = sfanav.Localizer(None, n_outputs=3, ridge=0.1).fit_features(F, np.c_[F[:, 0], F[:, 1]])
    bare.save(tmp_path / "bare.sfa")
    b2 = sfanav.load(tmp_path / "bare.sfa")
    assert b2.network is None and b2.ridge == 0.1
    np.testing.assert_array_equal(b2.predict_features(F), bare.predict_features(F))
    # the positions the readout was fitted to travel with the model (the navigation field's run)
    np.testing.assert_array_equal(b2.training_positions_, np.c_[F[:, 0], F[:, 1]])
    assert back.training_positions_.shape == (len(fitted.training_positions_), 2)
    np.testing.assert_array_equal(back.training_positions_, fitted.training_positions_)
    # a file written before they were stored: loads, without them
    kind, state, _ = sfanav.sfa.read_model(tmp_path / "bare.sfa")
    state.pop("training_positions")
    sfanav.sfa.save_model(tmp_path / "old.sfa", kind, state, version=1)
    assert sfanav.load(tmp_path / "old.sfa").training_positions_ is None


def test_eta_values_and_error_curve_of_the_trained_network(world):
    net, imgs, xy, timgs, txy = world
    eta_p, eta_phi = eta_values(net.transform(imgs, rotations=True))
    # on its own training views (all rotations) the outputs have unit variance:
    # position explains nearly all of it for the slowest outputs
    assert np.all(eta_phi[:2] < 0.1), eta_phi
    assert np.all(eta_p[:2] > 0.85), eta_p
    curve = error_vs_n(net.transform(imgs), xy, net.transform(timgs), txy, ns=range(2, 7))
    assert curve.test_error[-1] < curve.test_error[0] and curve.protocol == "test-run"


def test_localizer_errors(world, fitted, tmp_path):
    net, imgs, xy, timgs, txy = world
    with pytest.raises(sfanav.NotFittedError, match="Localizer is not fitted"):
        sfanav.Localizer(net).predict(timgs)
    with pytest.raises(sfanav.NotFittedError, match="Localizer is not fitted"):
        sfanav.Localizer(net).save(tmp_path / "x.sfa")
    with pytest.raises(sfanav.NotFittedError, match="network is not fitted"):
        sfanav.Localizer(sfanav.Network(tiny_config())).fit(imgs, xy)
    with pytest.raises(ValueError, match="n_outputs=8, but the network has only 6 outputs"):
        sfanav.Localizer(net, n_outputs=8).fit(imgs, xy)
    with pytest.raises(TypeError, match="sfanav.Network or None"):
        sfanav.Localizer("net.sfa")
    with pytest.raises(ValueError, match="xy must have 2 columns"):
        sfanav.Localizer(net, n_outputs=4).fit(imgs, xy[:, :1])
    with pytest.raises(ValueError, match="features has 480 rows but xy has 479"):
        sfanav.Localizer(net, n_outputs=4).fit(imgs, xy[:-1])
    with pytest.raises(ValueError, match="this network takes 8 px high"):
        fitted.predict(np.zeros((2, 9, 48)))
    bad = timgs[:3].copy()
    bad[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        fitted.predict(bad)
    with pytest.raises(ValueError, match="fitted with 6"):
        fitted.predict_features(np.zeros((3, 5)))
    with pytest.raises(ValueError, match="fitted with 6"):
        fitted.predict_features(np.zeros((3, 4, 5)))
