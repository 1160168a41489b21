"""Loop-closure feedback training (thesis 6.2.1): the statistics are those
of the interleaved view sequence, the fast path equals the naive one, and
bad closures are refused."""

import numpy as np
import pytest
from test_network import render, tiny_config, walk

import sfanav


def _images(n=40, seed=3, ramp=True):
    xy, heading = walk(n, seed=seed)
    noise = np.random.default_rng(seed + 2).standard_normal((n, 8, 48)) * 0.05
    imgs = np.stack([render(p, h) for p, h in zip(xy, heading)]) + noise
    if ramp:  # a light ramp through the run: what the closures should teach the network to ignore
        imgs = imgs * np.linspace(0.7, 1.3, n)[:, None, None]
    return imgs


CLOSURES = (np.array([2, 5, 9]), np.array([30, 35, 20]), np.array([7, 0, 13]))


def _fit(imgs, rot=sfanav.Rotation(step=6), config=None, **kw):
    return sfanav.Network(config or tiny_config(top_out=3)).fit(imgs, rot, progress=False, **kw)


def _first_stage_stats(net):
    st = net._net.node_states(True)[0][0]["stages"][0]["stats"]
    d = int(st["dim"])
    W = float(st["weight_sum"])
    mean = np.asarray(st["shift"]) + np.asarray(st["sum"]) / W
    return W, mean, float(st["pair_weight_sum"]), np.asarray(st["sdd"]).reshape(d, d)


def _reference_stats(imgs, closures, weights, step, rf=(6, 4), stride=(3, 2)):
    """Layer 1's patch statistics of the thesis's sequence, formed view by
    view: every image's rotated views in order; an image with a closure
    shows A'_0, C_0, A'_1, C_1, ... (A' its aligned partner), mixed with its
    plain rotation by the closure's weight."""
    n, h, width = imgs.shape
    k_views = -(-width // step)
    rw, rh = rf
    grid = [(r, j) for r in range((h - rh) // stride[1] + 1) for j in range((width - rw) // stride[0] + 1)]

    def patches(img, k):
        view = np.roll(img, -k * step, axis=1)
        return np.stack([view[r * stride[1]:r * stride[1] + rh, j * stride[0]:j * stride[0] + rw].ravel()
                         for r, j in grid])

    partner = {int(c): (np.roll(imgs[p], int(s), axis=1), w) for p, c, s, w in zip(*closures, weights)}
    samples, pairs = [], []  # (patches, weight), (a, b, weight)
    tail = None
    for i in range(n):
        C = [patches(imgs[i], k) for k in range(k_views)]
        samples += [(c, 1.0) for c in C]
        w = partner[i][1] if i in partner else 0.0
        A = [patches(partner[i][0], k) for k in range(k_views)] if i in partner else None
        if tail is not None:
            pairs.append((tail, C[0], 1.0 - w))
            if A is not None:
                pairs.append((tail, A[0], w))
        for k in range(k_views - 1):
            pairs.append((C[k], C[k + 1], 1.0 - w))
        if A is not None:
            samples += [(a, w) for a in A]
            pairs += [(A[k], C[k], w) for k in range(k_views)]
            pairs += [(C[k], A[k + 1], w) for k in range(k_views - 1)]
        tail = C[-1]
    W = sum(w * len(x) for x, w in samples)
    mean = sum(w * x.sum(axis=0) for x, w in samples) / W
    pw = sum(w * len(a) for a, _, w in pairs if w > 0)
    sdd = sum(w * (b - a).T @ (b - a) for a, b, w in pairs if w > 0)
    return W, mean, pw, sdd


@pytest.mark.parametrize("weights", [np.ones(3), np.array([0.3, 1.0, 0.0])])
def test_feedback_statistics_are_those_of_the_interleaved_sequence(weights):
    imgs = _images(12)
    closures = (np.array([1, 0, 3]), np.array([9, 6, 11]), np.array([7, 0, 13]))
    for fast in (True, False):
        net = _fit(imgs, loop_closures=closures, closure_weights=weights, fast=fast)
        got = _first_stage_stats(net)
        want = _reference_stats(imgs, closures, weights, step=6)
        assert got[0] == pytest.approx(want[0], rel=1e-12)
        np.testing.assert_allclose(got[1], want[1], rtol=1e-10)
        assert got[2] == pytest.approx(want[2], rel=1e-12)
        np.testing.assert_allclose(got[3], want[3], rtol=1e-9, atol=1e-9 * np.abs(want[3]).max())
    assert net.n_loop_closures_ == 3


@pytest.mark.parametrize("case", ["step6", "step5", "window", "uint8", "mixed"])
def test_feedback_fast_equals_naive(case):
    imgs = _images(40)
    rot, config = sfanav.Rotation(step=6), tiny_config(top_out=3)
    if case == "step5":  # the step does not divide the stride or the period
        rot = sfanav.Rotation(step=5)
    elif case == "window":
        rot, config = sfanav.Rotation(step=4, window=0.75), tiny_config(width=36, top_out=3)
    elif case == "uint8":
        imgs = np.clip(imgs * 100, 0, 255).astype(np.uint8)
    weights = np.array([0.5, 1.0, 0.8])
    kw = dict(rot=rot, config=config, loop_closures=CLOSURES, closure_weights=weights)
    if case == "mixed":
        config = {**config, "network": {"weight_sharing": True, "precision": "mixed"}}
        kw["config"] = config
    fast, naive, streamed = _fit(imgs, **kw), _fit(imgs, fast=False, **kw), _fit(imgs, cache=False, **kw)
    if case == "mixed":
        # f32 products: the first layer's statistics agree to f32 accuracy; the solves downstream
        # amplify that rounding chaotically on this tiny, ill-conditioned network, so the
        # top node's delta values are not compared
        for a, b in ((fast, naive), (streamed, naive)):
            sa, sb = (n._state(True)["nodes"][0][0]["stages"][0]["stats"] for n in (a, b))
            for key in ("sxx", "sdd", "sum", "sum_d"):
                x, y = np.asarray(sa[key]), np.asarray(sb[key])
                assert np.abs(x - y).max() <= 1e-6 * np.abs(y).max(), key
            for key in ("weight_sum", "pair_weight_sum"):
                assert sa[key] == pytest.approx(sb[key], rel=1e-12), key
        assert np.isfinite(fast.delta_values_).all()
    else:
        np.testing.assert_allclose(fast.delta_values_, naive.delta_values_, rtol=1e-9)
        np.testing.assert_allclose(streamed.delta_values_, naive.delta_values_, rtol=1e-9)
    plain = _fit(imgs, rot=rot, config=config)
    assert not np.allclose(fast.delta_values_, plain.delta_values_, rtol=1e-3)


def test_zero_weights_are_no_feedback_and_shifts_wrap():
    imgs = _images(40)
    plain = _fit(imgs)
    zero = _fit(imgs, loop_closures=CLOSURES, closure_weights=np.zeros(3))
    np.testing.assert_allclose(zero.delta_values_, plain.delta_values_, rtol=1e-9)
    past, cur, shift = CLOSURES
    a = _fit(imgs, loop_closures=(past, cur, shift))
    b = _fit(imgs, loop_closures=(past, cur, shift + 48))  # a full turn is no shift
    np.testing.assert_array_equal(a.delta_values_, b.delta_values_)


def test_feedback_without_weight_sharing_matches_naive():
    imgs = _images(16)
    cfg = tiny_config(sharing=False, top_out=3)
    closures = (np.array([2, 5, 9]), np.array([12, 15, 10]), np.array([7, 0, 13]))
    kw = dict(config=cfg, loop_closures=closures, closure_weights=[1.0, 0.4, 0.7])
    fast, naive = _fit(imgs, **kw), _fit(imgs, fast=False, **kw)
    np.testing.assert_allclose(fast.delta_values_, naive.delta_values_, rtol=1e-9)
    assert not np.allclose(fast.delta_values_, _fit(imgs, config=cfg).delta_values_, rtol=1e-3)


class _Scored:
    def __init__(self, past, current, shift, score=None):
        self.past, self.current, self.shift, self.score = past, current, shift, score


def test_scores_weight_the_closures():
    imgs = _images(40)
    scored = _Scored(*CLOSURES, score=np.array([0.5, 1.0, 0.8]))
    a = _fit(imgs, loop_closures=scored, closure_weights="score")
    b = _fit(imgs, loop_closures=CLOSURES, closure_weights=[0.5, 1.0, 0.8])
    np.testing.assert_array_equal(a.delta_values_, b.delta_values_)
    with pytest.raises(ValueError, match="score"):
        _fit(imgs, loop_closures=_Scored(*CLOSURES), closure_weights="score")


@pytest.mark.parametrize("closures, weights, err, msg", [
    ("gt", None, TypeError, "loop_closures must be"),
    ((np.array([1.0]), np.array([5]), np.array([0])), None, ValueError, "past must be a 1-D array of integers"),
    ((np.array([1, 2]), np.array([5]), np.array([0])), None, ValueError, "one length"),
    ((np.array([1]), np.array([50]), np.array([0])), None, ValueError, "index the 40 training images"),
    ((np.array([-1]), np.array([5]), np.array([0])), None, ValueError, "index the 40"),
    ((np.array([5]), np.array([5]), np.array([0])), None, ValueError, "with itself"),
    ((np.array([1, 2]), np.array([5, 5]), np.array([0, 0])), None, ValueError, "more than one closure"),
    (CLOSURES, [1.0, 2.0, 0.5], ValueError, r"\[0, 1\]"),
    (CLOSURES, [1.0, np.nan, 0.5], ValueError, r"\[0, 1\]"),
    (CLOSURES, [1.0], ValueError, "one value per closure"),
    (CLOSURES, "confidence", ValueError, "closure_weights must be"),
    (None, [1.0], ValueError, "closure_weights needs loop_closures"),
])
def test_bad_closures_are_refused(closures, weights, err, msg):
    imgs = _images(40)
    with pytest.raises(err, match=msg):
        _fit(imgs, loop_closures=closures, closure_weights=weights)


def test_feedback_needs_an_image_array():
    imgs = _images(12)
    with pytest.raises(TypeError, match="as an array"):
        _fit(lambda: iter([imgs]), loop_closures=(np.array([0]), np.array([5]), np.array([0])))


def test_no_closures_is_plain_training():
    imgs = _images(20)
    empty = (np.zeros(0, int), np.zeros(0, int), np.zeros(0, int))
    np.testing.assert_array_equal(_fit(imgs, loop_closures=empty).delta_values_, _fit(imgs).delta_values_)
