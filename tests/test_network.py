"""The receptive-field network: presets, configs, fast vs naive training,
invariance end to end, persistence and bad input."""

import numpy as np
import pytest

import sfanav

TABLES = {
    # preset: [(grid w, grid h), (rf w, rf h), (stride), in_dim, out] per layer
    "thesis-5.1": [((69, 7), (10, 10), (5, 5), 300, 14), ((22, 3), (6, 3), (3, 2), 252, 16),
                   ((10, 1), (4, 3), (2, 1), 192, 16), ((1, 1), (10, 1), (1, 1), 160, 8)],
    "thesis-5.2": [((99, 9), (12, 12), (6, 6), 432, 12), ((48, 3), (5, 5), (2, 2), 300, 14),
                   ((15, 1), (6, 3), (3, 1), 252, 16), ((1, 1), (15, 1), (1, 1), 240, 8)],
    "thesis-5.3": [((101, 7), (9, 10), (4, 5), 90, 12), ((49, 2), (5, 5), (2, 2), 300, 12),
                   ((23, 1), (5, 2), (2, 1), 120, 12), ((1, 1), (23, 1), (1, 1), 276, 8)],
    # the sfanav default (issue 7): Table 5.1's geometry, wider layers, 12 outputs
    "sfanav-default": [((69, 7), (10, 10), (5, 5), 300, 20), ((22, 3), (6, 3), (3, 2), 360, 24),
                       ((10, 1), (4, 3), (2, 1), 288, 24), ((1, 1), (10, 1), (1, 1), 240, 12)],
}


@pytest.mark.parametrize("name", sorted(TABLES))
def test_presets_build_the_thesis_tables(name):
    net = sfanav.Network.from_preset(name)
    geo = net._net.geometry()
    assert len(geo) == 4
    for g, (grid, rf, stride, in_dim, out) in zip(geo, TABLES[name]):
        assert tuple(g["grid"]) == grid
        assert tuple(g["rf"]) == rf
        assert tuple(g["stride"]) == stride
        assert g["in_dim"] == in_dim
        assert g["n_out"] == out
        assert g["reduce_to"] == 23  # largest k with C(k+2, 2) - 1 <= 300
    assert "69x7" in sfanav.Network.from_preset("thesis-5.1").describe()
    assert sfanav.Network.preset_path(name).exists()


def test_preset_overrides_and_unknown_preset():
    net = sfanav.Network.from_preset("thesis-5.1", weight_sharing=False, reduce_to=10, out=6)
    geo = net._net.geometry()
    assert geo[0]["n_nodes"] == 69 * 7 and geo[0]["reduce_to"] == 10 and geo[-1]["n_out"] == 6
    with pytest.raises(ValueError, match="unknown preset"):
        sfanav.Network.from_preset("thesis-9.9")
    with pytest.raises(ValueError, match="unknown override"):
        sfanav.Network.from_preset("thesis-5.1", colour=True)


def tiny_config(width=48, height=8, channels=1, sharing=True, top_out=4):
    return {
        "input": {"width": width, "height": height, "channels": channels},
        "network": {"weight_sharing": sharing},
        "layers": [
            {"rf": [6, 4], "stride": [3, 2], "out": 8},
            {"rf": "full", "out": top_out},
        ],
    }


def test_bad_configs_name_the_layer(tmp_path):
    cfg = tiny_config()
    cfg["layers"][0]["stride"] = [4, 2]  # (48 - 6) is not a multiple of 4
    with pytest.raises(ValueError, match="layer 1.*do not tile"):
        sfanav.Network(cfg)
    cfg = tiny_config()
    cfg["layers"][1]["rf"] = [3, 3]
    with pytest.raises(ValueError, match="layer 2"):
        sfanav.Network(cfg)
    cfg = tiny_config()
    cfg["layers"][0]["out"] = 1000
    with pytest.raises(ValueError, match="layer 1.*exceeds the expanded dim"):
        sfanav.Network(cfg)
    cfg = tiny_config()
    cfg["layers"][0]["bogus"] = 1
    with pytest.raises(ValueError, match="layer 1: unknown keys"):
        sfanav.Network(cfg)
    with pytest.raises(FileNotFoundError):
        sfanav.Network(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[input\nwidth=")
    with pytest.raises(ValueError, match="cannot parse"):
        sfanav.Network(bad)


@pytest.mark.parametrize("edit, message", [
    (lambda c: c.__setitem__("netwrok", {}), r"unknown sections or keys \['netwrok'\]"),
    (lambda c: c["input"].__setitem__("width", 48.9), r"\[input\] width must be an integer, got 48.9"),
    (lambda c: c["input"].__setitem__("channels", True), r"channels must be an integer"),
    (lambda c: c["input"].__setitem__("colour", 3), r"unknown \[input\] keys"),
    (lambda c: c.setdefault("network", {}).__setitem__("weight_sharing", "false"), "true or false"),
    (lambda c: c.setdefault("network", {}).__setitem__("max_expanded", 0), "max_expanded must be at least 1"),
    (lambda c: c["layers"][0].__setitem__("out", 4.5), "layer 1: out must be an integer"),
    (lambda c: c["layers"][1].__setitem__("degree", "2"), "layer 2: degree must be an integer"),
    (lambda c: c["layers"][0].__setitem__("reduce_to", -3), "layer 1: reduce_to must be at least 1"),
])
def test_config_values_that_used_to_be_coerced_are_refused(edit, message):
    cfg = tiny_config()
    edit(cfg)
    with pytest.raises(ValueError, match=message):
        sfanav.sfa.resolve_config(cfg)


def test_the_default_reduction_is_found_without_a_long_loop():
    from math import comb

    # a huge input and expansion budget: bisection, not 1e9 steps
    cfg = {"input": {"width": 10**6, "height": 10**6, "channels": 1}, "network": {"max_expanded": 10**18},
           "layers": [{"rf": "full", "out": 8}]}
    k = sfanav.sfa.resolve_config(cfg)["layers"][0]["reduce_to"]
    assert comb(k + 2, 2) - 1 <= 10**18 < comb(k + 3, 2) - 1
    # the thesis's budget: k = 23 (299 expanded dims) for a 300-dim input
    cfg = {"input": {"width": 10, "height": 10, "channels": 3}, "layers": [{"rf": "full", "out": 8}]}
    assert sfanav.sfa.resolve_config(cfg)["layers"][0]["reduce_to"] == 23


def test_config_file_round_trip(tmp_path):
    p = tmp_path / "net.toml"
    p.write_text(sfanav.Network.preset_path("thesis-5.3").read_text())
    assert sfanav.Network(p).config_ == sfanav.Network.from_preset("thesis-5.3").config_


# ----------------------------------------------------------------- a tiny world

LANDMARKS = np.array([[-1.0, -0.6], [1.6, -0.4], [0.4, 1.8], [-0.8, 1.5], [2.0, 1.2], [0.5, -1.4]])
HEIGHTS = np.array([0.9, 0.5, 1.2, 0.7, 1.0, 0.6])


def render(xy, heading, width=48, height=8):
    """A toy panorama at position xy (unit square) facing `heading` (rad):
    landmarks as bumps whose angular size and height shrink with distance."""
    az = 2 * np.pi * np.arange(width) / width + heading
    rows = (np.arange(height)[::-1] + 0.5) / height
    img = np.zeros((height, width))
    for (lx, ly), hgt in zip(LANDMARKS, HEIGHTS):
        d = np.hypot(lx - xy[0], ly - xy[1])
        ang = np.arctan2(ly - xy[1], lx - xy[0])
        diff = np.angle(np.exp(1j * (az - ang)))
        width_ang = 0.25 / d
        top = np.clip(hgt / d, 0, 1.5)
        vertical = 1.0 / (1.0 + np.exp((rows[:, None] - top) / 0.15))
        img += np.exp(-(diff / width_ang) ** 2)[None, :] * vertical * (1.0 / d)
    return img + 0.2 * rows[:, None]


def walk(n, seed):
    rng = np.random.default_rng(seed)
    xy = np.empty((n, 2))
    p, v = np.array([0.5, 0.5]), rng.standard_normal(2) * 0.02
    for i in range(n):
        v = 0.9 * v + 0.01 * rng.standard_normal(2)
        p = p + v
        for k in range(2):
            if not 0 <= p[k] <= 1:
                v[k] = -v[k]
                p[k] = np.clip(p[k], 0, 1)
        xy[i] = p
    heading = np.cumsum(rng.standard_normal(n) * 0.2)
    return xy, heading


def grid_run(n_lines=12, per_line=50, seed=0):
    """Boustrophedon exploration over the unit square (as the thesis's grid runs)."""
    rng = np.random.default_rng(seed)
    pts = []
    for i, y in enumerate(np.linspace(0.02, 0.98, n_lines)):
        xs = np.linspace(0.02, 0.98, per_line)
        pts += [(x, y) for x in (xs if i % 2 == 0 else xs[::-1])]
    xy = np.array(pts)
    heading = np.cumsum(rng.standard_normal(len(xy)) * 0.2)
    return xy, heading


@pytest.fixture(scope="module")
def world():
    xy, heading = grid_run()
    imgs = np.stack([render(p, h) for p, h in zip(xy, heading)])
    txy, th = walk(150, seed=2)
    timgs = np.stack([render(p, h) for p, h in zip(txy, th)])
    net = sfanav.Network(tiny_config()).fit(imgs, sfanav.Rotation(step=3), progress=False)
    return net, imgs, xy, timgs, txy


def test_fast_equals_naive():
    xy, heading = walk(60, seed=3)
    # Pixel noise keeps every node's problem well conditioned, so the two
    # paths' different summation orders stay at rounding level (on the bare
    # toy renderer the quadratic layer-1 expansion is rank deficient and
    # eigenvalues at the tolerance amplify rounding to ~1e-7).
    noise = np.random.default_rng(5).standard_normal((60, 8, 48)) * 0.05
    imgs = np.stack([render(p, h) for p, h in zip(xy, heading)]) + noise
    rot = sfanav.Rotation(step=5)
    fast = sfanav.Network(tiny_config(top_out=3)).fit(imgs, rot, progress=False)
    naive = sfanav.Network(tiny_config(top_out=3)).fit(imgs, rot, fast=False, progress=False)
    uncached = sfanav.Network(tiny_config(top_out=3)).fit(imgs, rot, cache=False, progress=False)
    np.testing.assert_allclose(fast.delta_values_, naive.delta_values_, rtol=1e-9)
    np.testing.assert_allclose(uncached.delta_values_, naive.delta_values_, rtol=1e-9)
    np.testing.assert_allclose(fast.transform(imgs[:5]), naive.transform(imgs[:5]), rtol=1e-7, atol=1e-9)


def test_transition_weight_fast_equals_naive_and_validates(tmp_path):
    xy, heading = walk(40, seed=3)
    noise = np.random.default_rng(5).standard_normal((40, 8, 48)) * 0.05
    imgs = np.stack([render(p, h) for p, h in zip(xy, heading)]) + noise
    rot = sfanav.Rotation(step=6)
    fit = lambda **kw: sfanav.Network(tiny_config(top_out=3)).fit(imgs, rot, progress=False, **kw)
    thesis = fit()
    assert thesis.transition_weight_ == 1.0
    np.testing.assert_array_equal(fit(transition_weight=1).delta_values_, thesis.delta_values_)
    fast = fit(transition_weight=8.0)
    naive = fit(transition_weight=8.0, fast=False)
    np.testing.assert_allclose(fast.delta_values_, naive.delta_values_, rtol=1e-9)
    assert not np.allclose(fast.delta_values_, thesis.delta_values_, rtol=1e-3)
    assert fast.transition_weight_ == 8.0
    fast.save(tmp_path / "tw.sfa")
    assert sfanav.load(tmp_path / "tw.sfa").transition_weight_ == 8.0
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="transition_weight"):
            fit(transition_weight=bad)
    with pytest.raises(TypeError, match="transition_weight"):
        fit(transition_weight="10")


def test_spatial_pairs_helper():
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.5], [10.0, 10.0]])
    a, b, w = sfanav.spatial_pairs(xy, radius=1.6)
    assert list(zip(a, b)) == [(0, 1), (0, 3), (1, 2)]
    np.testing.assert_array_equal(w, 1.0)
    # k = 1: every point keeps its nearest neighbour; a pair stays if either end chose it
    a, b, _ = sfanav.spatial_pairs(xy, radius=1.6, k=1)
    # (0's nearest is 1, 2's is 1, 3's is 0)
    assert list(zip(a, b)) == [(0, 1), (0, 3), (1, 2)]
    a, b, _ = sfanav.spatial_pairs(xy[[0, 3, 4]], radius=1.6, k=1)
    assert list(zip(a, b)) == [(0, 1)]
    a, b, _ = sfanav.spatial_pairs(xy, radius=1.6, min_gap=2)
    assert list(zip(a, b)) == [(0, 3)]
    _, _, w = sfanav.spatial_pairs(xy, radius=1.6, weights="gaussian", scale=1.0)
    np.testing.assert_allclose(w, np.exp(-np.array([1.0, 2.25, 1.0]) / 2))
    a, b, w = sfanav.spatial_pairs(xy, radius=0.5)
    assert len(a) == len(b) == len(w) == 0
    for kw, msg in (({"radius": 0}, "radius"), ({"radius": 1, "k": 0}, "k must"),
                    ({"radius": 1, "weights": "cosine"}, "weights")):
        with pytest.raises(ValueError, match=msg):
            sfanav.spatial_pairs(xy, **kw)
    with pytest.raises(ValueError, match="xy"):
        sfanav.spatial_pairs(xy[:, :1], radius=1)


def test_spatial_pairs_fast_equals_naive_and_validate():
    xy, heading = walk(36, seed=8)
    noise = np.random.default_rng(9).standard_normal((36, 8, 48)) * 0.05
    imgs = np.stack([render(p, h) for p, h in zip(xy, heading)]) + noise
    rot = sfanav.Rotation(step=6)
    pairs = sfanav.spatial_pairs(xy, radius=0.15, k=3)
    assert len(pairs[0]) > 20
    fit = lambda **kw: sfanav.Network(tiny_config(top_out=3)).fit(imgs, rot, progress=False, **kw)
    fast = fit(pairs=pairs)
    naive = fit(pairs=pairs, fast=False)
    uncached = fit(pairs=pairs, cache=False)
    np.testing.assert_allclose(fast.delta_values_, naive.delta_values_, rtol=1e-9)
    np.testing.assert_allclose(uncached.delta_values_, naive.delta_values_, rtol=1e-9)
    assert fast.n_pairs_ == len(pairs[0])
    assert not np.allclose(fast.delta_values_, fit().delta_values_, rtol=1e-3)
    # zero-weight pairs change nothing
    zero = fit(pairs=(pairs[0], pairs[1], np.zeros(len(pairs[0]))))
    np.testing.assert_allclose(zero.delta_values_, fit().delta_values_, rtol=1e-9)
    # pairs in some layers only: all layers named == default; the top only differs; bad layers refused
    n_layers = len(sfanav.Network(tiny_config(top_out=3)).config_["layers"])
    np.testing.assert_array_equal(fit(pairs=pairs, pair_layers=range(1, n_layers + 1)).delta_values_,
                                  fast.delta_values_)
    top = fit(pairs=pairs, pair_layers=[n_layers])
    np.testing.assert_allclose(top.delta_values_, fit(pairs=pairs, pair_layers=[n_layers], fast=False).delta_values_,
                               rtol=1e-9)
    # (the tiny top can fit the same function on these few training views whatever layer 1 does, so compare
    # layer 1: untouched by top-only pairs, changed by pairs in all layers)
    first = lambda net: net._net.node_states(False)[0][0]["stages"][-1]["solution"]["delta"]
    np.testing.assert_array_equal(first(top), first(fit()))
    assert not np.allclose(first(fast), first(fit()), rtol=1e-3)
    with pytest.raises(ValueError, match="pair_layers"):
        fit(pairs=pairs, pair_layers=[n_layers + 1])
    # shifted pairs (b rolled by a random shift): fast == naive, and they change the result
    sp = sfanav.spatial_pairs(xy, radius=0.15, k=3, shifts=48, seed=1)
    assert len(sp) == 4 and sp[3].min() >= 0 and sp[3].max() < 48 and np.any(sp[3] % 48)
    shifted = fit(pairs=sp)
    np.testing.assert_allclose(shifted.delta_values_, fit(pairs=sp, fast=False).delta_values_, rtol=1e-9)
    assert not np.allclose(first(shifted), first(fast), rtol=1e-3)
    # shifts in multiples of the step are read from the field cache: same result as rolling the images
    sp6 = sfanav.spatial_pairs(xy, radius=0.15, k=3, shifts=48, shift_step=6, seed=2)
    assert np.all(sp6[3] % 6 == 0) and np.any(sp6[3])
    np.testing.assert_allclose(fit(pairs=sp6).delta_values_, fit(pairs=sp6, cache=False).delta_values_, rtol=1e-9)
    # an image paired with itself rolled is a pair, in cached passes as in streamed ones (unrolled: none)
    own = (np.array([3, 7, 7]), np.array([9, 7, 12]), np.ones(3), np.array([6, 12, 0]))
    cached, streamed = fit(pairs=own), fit(pairs=own, cache=False)
    assert cached._net.node_states(True)[-1][0]["stages"][-1]["stats"]["n_pairs"] == \
        streamed._net.node_states(True)[-1][0]["stages"][-1]["stats"]["n_pairs"]
    np.testing.assert_allclose(cached.delta_values_, streamed.delta_values_, rtol=1e-9)
    unrolled = fit(pairs=(own[0], own[1], own[2], np.array([6, 0, 0])), cache=False)
    assert not np.allclose(unrolled.delta_values_, streamed.delta_values_, rtol=1e-6)
    # a full-period shift is no shift
    full = fit(pairs=(pairs[0], pairs[1], pairs[2], np.full(len(pairs[0]), 48)), cache=False)
    np.testing.assert_allclose(full.delta_values_, uncached.delta_values_, rtol=1e-12)
    a, b, w = pairs
    with pytest.raises(ValueError, match="shifts"):
        fit(pairs=(a, b, w, np.zeros(len(a) - 1, int)))
    with pytest.raises(ValueError, match="index the 36"):
        fit(pairs=(a, b + 100, w))
    with pytest.raises(ValueError, match="finite"):
        fit(pairs=(a, b, -w))
    with pytest.raises(ValueError, match="one length"):
        fit(pairs=(a, b[:-1], w))
    with pytest.raises(TypeError, match="integer"):
        fit(pairs=(a.astype(float), b, w))
    with pytest.raises(TypeError, match="array"):
        sfanav.Network(tiny_config(top_out=3)).fit(list(imgs), rot, progress=False, pairs=pairs)


def three_layer_config():
    return {
        "input": {"width": 48, "height": 8, "channels": 1},
        "layers": [
            {"rf": [6, 4], "stride": [3, 2], "out": 6},
            {"rf": [5, 2], "stride": [2, 1], "out": 5},
            {"rf": "full", "out": 3},
        ],
    }


def test_cache_policy_streams_what_does_not_fit_and_changes_nothing():
    xy, heading = walk(40, seed=4)
    noise = np.random.default_rng(6).standard_normal((40, 8, 48)) * 0.05
    imgs = np.stack([render(p, h) for p, h in zip(xy, heading)]) + noise
    rot = sfanav.Rotation(step=3)
    cached = sfanav.Network(three_layer_config()).fit(imgs, rot, cache=True, progress=False)
    assert [keep for _, keep, _ in cached.cache_plan_] == [True, True]
    # A budget between the two fields' sizes: layer 2's input (the larger
    # layer-1 field) is streamed, layer 3's input is cached.
    sizes = [b for _, _, b in cached.cache_plan_]
    assert sizes[0] > sizes[1] > 0
    auto = sfanav.Network(three_layer_config()).fit(imgs, rot, cache="auto", cache_limit=(sizes[0] + sizes[1]) / 2, progress=False)
    assert [keep for _, keep, _ in auto.cache_plan_] == [False, True]
    none = sfanav.Network(three_layer_config()).fit(imgs, rot, cache="auto", cache_limit=0, progress=False)
    assert [keep for _, keep, _ in none.cache_plan_] == [False, False]
    for net in (auto, none):
        np.testing.assert_allclose(net.delta_values_, cached.delta_values_, rtol=1e-9)
    with pytest.raises(ValueError, match="cache must be"):
        sfanav.Network(three_layer_config()).fit(imgs, rot, cache="sometimes", progress=False)
    with pytest.raises(ValueError, match="cache_limit"):
        sfanav.Network(three_layer_config()).fit(imgs, rot, cache_limit=-1, progress=False)


def test_outputs_are_orientation_invariant_and_encode_position(world):
    net, imgs, xy, timgs, txy = world
    y = net.transform(timgs)
    yr = net.transform(timgs, rotations=True)  # (N, K, n)
    assert yr.shape == (150, 16, 4)
    # eta_phi: variance over rotations at one place / variance over everything.
    eta_phi = yr.var(axis=1).mean(axis=0) / yr.reshape(-1, 4).var(axis=0)
    assert np.all(eta_phi[:2] < 0.1), eta_phi
    # A quadratic regression of the slowest outputs recovers the position.
    tr = net.transform(imgs)
    feats = lambda z: sfanav.expand(z, 2)
    A = np.c_[feats(tr), np.ones(len(tr))]
    W, *_ = np.linalg.lstsq(A, xy, rcond=None)
    pred = np.c_[feats(y), np.ones(len(y))] @ W
    err = np.abs(pred - txy).mean(axis=0)
    assert np.all(err < 0.15), err  # the area is 1 x 1 (chance level: about 0.33)


def test_single_image_in_single_row_out(world):
    net, imgs, *_ = world
    np.testing.assert_array_equal(net.transform(imgs[3]), net.transform(imgs[3:4])[0])


def test_rotations_match_rolled_images(world):
    net, imgs, *_ = world
    yr = net.transform(imgs[:3], rotations=True, step=3)
    for k in (0, 5, 11):
        np.testing.assert_allclose(yr[:, k], net.transform(np.roll(imgs[:3], -3 * k, axis=2)), atol=1e-9)


def test_individual_nodes_train(world):
    _, imgs, *_ = world
    net = sfanav.Network(tiny_config(sharing=False, top_out=3)).fit(imgs[:80], sfanav.Rotation(step=6), progress=False)
    assert net._net.geometry()[0]["n_nodes"] == 15 * 3
    assert net.transform(imgs[:4]).shape == (4, 3)


def test_save_load_round_trip(world, tmp_path):
    net, imgs, *_ = world
    net.save(tmp_path / "net.sfa")
    back = sfanav.load(tmp_path / "net.sfa")
    assert isinstance(back, sfanav.Network)
    np.testing.assert_array_equal(back.transform(imgs[:10]), net.transform(imgs[:10]))
    np.testing.assert_array_equal(back.delta_values_, net.delta_values_)


def test_streaming_sources_agree(world, tmp_path):
    _, imgs, *_ = world
    sub = imgs[:60]
    rot = sfanav.Rotation(step=6)
    ref = sfanav.Network(tiny_config(top_out=3)).fit(sub, rot, progress=False)
    np.save(tmp_path / "imgs.npy", sub)
    for src in (list(sub), lambda: iter(sub), str(tmp_path / "imgs.npy")):
        other = sfanav.Network(tiny_config(top_out=3)).fit(src, rot, batch_size=7, progress=False)
        # the batch size changes only the order of the sums (the statistics agree to 1e-12);
        # the top node's small delta values amplify that rounding
        np.testing.assert_allclose(other.delta_values_, ref.delta_values_, rtol=1e-6)
        np.testing.assert_allclose(other.transform(sub[:5]), ref.transform(sub[:5]), rtol=1e-6, atol=1e-6)
    with pytest.raises(TypeError, match="one-shot iterator"):
        sfanav.Network(tiny_config()).fit((im for im in sub), rot, progress=False)


def test_window_narrower_than_panorama():
    xy, heading = walk(80, seed=4)
    imgs = np.stack([render(p, h, width=60) for p, h in zip(xy, heading)])
    net = sfanav.Network(tiny_config(width=30, top_out=3))  # (30 - 6) % 3 == 0
    net.fit(imgs, sfanav.Rotation(step=5, window=0.5), progress=False)
    assert net.transform(imgs[:2]).shape == (2, 3)
    with pytest.raises(ValueError, match="50% window of 60-px panoramas is 30 px"):
        sfanav.Network(tiny_config(width=48)).fit(imgs, sfanav.Rotation(window=0.5), progress=False)


def test_bad_images(world):
    net, imgs, *_ = world
    with pytest.raises(ValueError, match="this network takes 8 px high"):
        net.transform(np.zeros((2, 9, 48)))
    with pytest.raises(ValueError, match="channel"):
        net.transform(np.zeros((2, 8, 48, 3)))
    bad = imgs[:20].copy()
    bad[7, 2, 3] = np.nan
    with pytest.raises(ValueError, match="image 7 contains NaN"):
        sfanav.Network(tiny_config()).fit(bad, progress=False)
    with pytest.raises(ValueError, match="NaN"):
        net.transform(bad[5:9])
    with pytest.raises(ValueError, match="no training images"):
        sfanav.Network(tiny_config()).fit(np.zeros((0, 8, 48)), progress=False)
    with pytest.raises(sfanav.NotFittedError):
        sfanav.Network(tiny_config()).transform(imgs[:1])
    with pytest.raises(ValueError, match="Rotation.step"):
        sfanav.Rotation(step=0)


def _position_error(net, imgs, xy, timgs, txy):
    tr, y = net.transform(imgs), net.transform(timgs)
    A = np.c_[sfanav.expand(tr, 2), np.ones(len(tr))]
    W, *_ = np.linalg.lstsq(A, xy, rcond=None)
    pred = np.c_[sfanav.expand(y, 2), np.ones(len(y))] @ W
    return np.abs(pred - txy).mean(axis=0)


def test_mixed_precision_network_is_as_good_as_double(world):
    net, imgs, xy, timgs, txy = world
    cfg = tiny_config()
    cfg["network"]["precision"] = "mixed"
    mixed = sfanav.Network(cfg).fit(imgs, sfanav.Rotation(step=3), progress=False)
    assert mixed.config_["mixed_precision"] and not net.config_["mixed_precision"]
    err_d = _position_error(net, imgs, xy, timgs, txy)
    err_m = _position_error(mixed, imgs, xy, timgs, txy)
    assert np.all(err_m < 0.15) and np.all(err_m < 1.5 * err_d), (err_m, err_d)
    yr = mixed.transform(timgs, rotations=True)
    eta_phi = yr.var(axis=1).mean(axis=0) / yr.reshape(-1, yr.shape[2]).var(axis=0)
    assert eta_phi[:2].mean() < 0.15, eta_phi
    assert not sfanav.Network.from_preset("thesis-5.2").config_["mixed_precision"]
    assert sfanav.Network.from_preset("thesis-5.2", precision="mixed").config_["mixed_precision"]


@pytest.mark.parametrize("step", [0, -2, 2.5, True, "5"])
def test_transform_refuses_a_rotation_step_that_is_not_a_positive_integer(step):
    cfg = tiny_config()
    net = sfanav.Network(cfg)
    rng = np.random.default_rng(0)
    imgs = rng.integers(0, 255, (30, cfg["input"]["height"], cfg["input"]["width"]), dtype=np.uint8)
    if cfg["input"].get("channels", 1) == 3:
        imgs = np.repeat(imgs[..., None], 3, axis=3)
    net.fit(imgs, rotation=sfanav.Rotation(step=8), progress=False)
    with pytest.raises(ValueError, match="step must be a positive whole number"):
        net.transform(imgs[:2], rotations=True, step=step)
    assert net.transform(imgs[:2], rotations=True, step=np.int64(8)).shape[1] == -(-cfg["input"]["width"] // 8)


def test_training_does_not_depend_on_the_thread_count():
    imgs = np.random.default_rng(3).random((40, 8, 48)).cumsum(0)
    ref = sfanav.Network(tiny_config()).fit(imgs, sfanav.Rotation(step=4), progress=False)
    try:
        for n in (1, 3):
            sfanav.set_num_threads(n)
            net = sfanav.Network(tiny_config()).fit(imgs, sfanav.Rotation(step=4), progress=False)
            np.testing.assert_array_equal(net.transform(imgs), ref.transform(imgs))
            np.testing.assert_array_equal(net.transform(imgs, rotations=True), ref.transform(imgs, rotations=True))
    finally:
        sfanav.set_num_threads(0)
