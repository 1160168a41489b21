"""The novelty of a query (sfanav.localization.novelty), stored with a model,
and the filter's measurement noise scaled by it (OdometryEKF's
measurement_scale, fuse's novelty, fuse_images, the streaming localizer)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sfanav.experiments.filter_cases import make_filter_case
from sfanav.localization.novelty import NoveltyReference
from sfanav.odometry import OdometryEKF, fuse, fuse_images, noise_for_localizer, novelty_exponent, novelty_scale
from sfanav.odometry.fusion import check_noise, noise_novelty_scale
from sfanav.odometry.streaming import StreamingLocalizer


def test_reference_scores_in_nearest_neighbour_units():
    grid = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0)), -1).reshape(-1, 2) * [1.0, 3.0]
    ref = NoveltyReference().fit(grid)
    # standardised columns: x / std(x), y / std(3 y) = y / std(y): the grid's spacing is equal in both
    assert np.allclose(ref.scale_, [grid[:, 0].std(), grid[:, 1].std()])
    assert ref.unit_ == pytest.approx(1.0 / grid[:, 0].std())
    assert np.allclose(ref.score(grid[:5]), 0.0)
    # half a spacing off a training point: 0.5; 10 spacings outside the grid along x: 10
    q = np.array([[4.5, 6.0], [19.0, 0.0]])
    assert np.allclose(ref.score(q), [0.5, 10.0])


def test_reference_state_round_trip_and_bad_input():
    rng = np.random.default_rng(1)
    F = rng.normal(size=(200, 5))
    ref = NoveltyReference().fit(F)
    back = NoveltyReference.from_state(ref.get_state())
    q = rng.normal(size=(30, 5)) * 2
    assert np.array_equal(ref.score(q), back.score(q))
    with pytest.raises(ValueError, match="at least 2"):
        NoveltyReference().fit(F[:1])
    with pytest.raises(ValueError, match="columns"):
        ref.score(q[:, :4])
    with pytest.raises(ValueError):
        ref.score(np.full((2, 5), np.nan))
    with pytest.raises(ValueError, match="not fitted"):
        NoveltyReference().score(q)
    bad = ref.get_state()
    bad["unit"] = 0.0
    with pytest.raises(ValueError, match="unit"):
        NoveltyReference.from_state(bad)
    # a constant column does not divide by zero
    assert np.isfinite(NoveltyReference().fit(np.c_[F[:, 0], np.ones(200)]).score(q[:, :2])).all()


def test_novelty_scale():
    assert novelty_scale([0.0, 1.0, 3.0, 6.0, np.nan], 2.0).tolist() == [1.0, 1.0, 1.5, 3.0, 1.0]
    for bad in ([-1.0], [np.inf]):
        with pytest.raises(ValueError, match="novelty"):
            novelty_scale(bad)
    with pytest.raises(ValueError, match="novelty_threshold"):
        novelty_scale([1.0], 0.0)


def test_novelty_scale_with_an_exponent_and_a_knee():
    v = np.array([0.5, 1.0, 4.0, 9.0, 18.0, 36.0])
    # (v / t) ** p up to the knee, then in proportion: continuous at the knee
    assert np.allclose(novelty_scale(v, 1.0, exponent=0.5, knee=9.0), [1.0, 1.0, 2.0, 3.0, 6.0, 12.0])
    assert np.allclose(novelty_scale(v, 2.0, exponent=0.0, knee=9.0), [1.0, 1.0, 1.0, 1.0, 2.0, 4.0])
    # exponent 1 is the proportional scale whatever the knee; a knee below the threshold is the threshold
    assert np.allclose(novelty_scale(v, 2.0, exponent=1.0, knee=3.0), novelty_scale(v, 2.0))
    assert np.allclose(novelty_scale(v, 2.0, exponent=0.0, knee=1.0), novelty_scale(v, 2.0))
    for kw, match in [({"exponent": 1.5}, "novelty_exponent"), ({"exponent": -0.1}, "novelty_exponent"),
                      ({"knee": 0.0}, "novelty_knee"), ({"knee": np.nan}, "novelty_knee")]:
        with pytest.raises(ValueError, match=match):
            novelty_scale(v, 1.0, **kw)


@settings(max_examples=25, deadline=None)
@given(p=st.floats(0.0, 1.0), seed=st.integers(0, 10_000))
def test_novelty_exponent_recovers_a_power_law(p, seed):
    rng = np.random.default_rng(seed)
    nov = rng.uniform(0.5, 12.0, 2000)  # 400 frames left the slope 0.25 off at p = 0 for seed 2022 (4 sd)
    err = 0.05 * nov**p * rng.exponential(1.0, 2000)  # errors of a power of the novelty, noisy
    assert novelty_exponent(err, nov) == pytest.approx(p, abs=0.2)


def test_novelty_exponent_clips_and_bad_input():
    nov = np.linspace(1.0, 8.0, 200)
    assert novelty_exponent(0.01 * nov**3, nov) == 1.0  # steeper than proportional: proportional
    assert novelty_exponent(1.0 / nov, nov) == 0.0  # precise where novel: not scaled
    assert novelty_exponent(np.ones(10), np.arange(10.0)) == 1.0  # too few frames to tell: proportional
    assert novelty_exponent(np.r_[np.nan, nov[1:] ** 0.5], nov) == pytest.approx(0.5, abs=0.02)
    with pytest.raises(ValueError, match="same length"):
        novelty_exponent(nov[:-1], nov)
    with pytest.raises(ValueError, match=">= 0"):
        novelty_exponent(-nov, nov)


def test_check_noise():
    base = {"distance_noise": 0.02, "heading_noise": 0.01, "measurement_noise": 0.3}
    full = {**base, "turn_noise": 0.1, "novelty_exponent": 0.5, "novelty_knee": 4.0}
    assert check_noise(full) == full
    for bad, match in [({**base, "gain": 1.0}, "novelty_exponent"), ({"distance_noise": 0.1}, "measurement_noise"),
                       ({**base, "measurement_noise": "x"}, "numbers"), ([1, 2], "mapping")]:
        with pytest.raises(ValueError, match=match):
            check_noise(bad)


def test_fuse_uses_the_noise_novelty_exponent():
    run = make_filter_case("clean", random_state=3)
    noise = {"distance_noise": 0.02, "heading_noise": 0.01, "measurement_noise": 0.3}
    nov = np.linspace(0.5, 6.0, len(run["estimates"]))
    # exponent 0 up to a knee above every novelty: the plain fuse; exponent 1: the proportional scale
    flat = fuse(run["odometry"], run["estimates"], {**noise, "novelty_exponent": 0.0, "novelty_knee": 10.0},
                novelty=nov)
    assert np.array_equal(flat, fuse(run["odometry"], run["estimates"], noise))
    prop = fuse(run["odometry"], run["estimates"], {**noise, "novelty_exponent": 1.0, "novelty_knee": 2.0},
                novelty=nov)
    assert np.array_equal(prop, fuse(run["odometry"], run["estimates"], noise, novelty=nov))
    assert not np.array_equal(prop, flat)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), factor=st.floats(1.0, 5.0))
def test_a_constant_measurement_scale_is_a_larger_measurement_noise(seed, factor):
    run = make_filter_case("clean", random_state=seed)
    Z = run["estimates"]
    kw = dict(distance_noise=0.02, heading_noise=0.01, gate_probability=0.999)
    a = OdometryEKF(measurement_noise=0.3 * factor, **kw).run(run["odometry"], Z, run["poses"][0])
    b = OdometryEKF(measurement_noise=0.3, **kw).run(run["odometry"], Z, run["poses"][0],
                                                      measurement_scale=np.full(len(Z), factor))
    assert np.allclose(a, b, atol=1e-9)


def test_measurement_scale_bad_input():
    run = make_filter_case("clean", random_state=0)
    ekf = OdometryEKF()
    for bad, match in [(np.full(19, 2.0), "one factor per frame"), (np.full(20, 0.5), ">= 1"),
                       (np.r_[np.nan, np.ones(19)], "finite")]:
        with pytest.raises(ValueError, match=match):
            ekf.run(run["odometry"][:20], run["estimates"][:20], run["poses"][0], measurement_scale=bad)
    ekf.start(run["poses"][0])
    with pytest.raises(ValueError, match=">= 1"):
        ekf.step(run["odometry"][0], run["estimates"][0], measurement_scale=0.9)


def test_fuse_with_novelty_below_the_threshold_is_fuse_without():
    run = make_filter_case("clean", random_state=3)
    noise = {"distance_noise": 0.02, "heading_noise": 0.01, "measurement_noise": 0.3}
    plain = fuse(run["odometry"], run["estimates"], noise)
    same = fuse(run["odometry"], run["estimates"], noise, novelty=np.full(len(plain), 0.9), novelty_threshold=1.0)
    assert np.array_equal(plain, same)


def test_fuse_follows_the_odometry_where_the_estimates_are_novel_and_wrong():
    # a stretch of estimates 4 m off and moving with the robot (what a readout extrapolating off its training
    # ground gives): without novelty the filter follows them; with their novelty it keeps to the odometry
    run = make_filter_case("clean", random_state=5)
    T, Z = run["poses"][:, :2], run["estimates"].copy()
    Z[100:140] += [4.0, 0.0]
    nov = np.ones(len(Z))
    nov[100:140] = 12.0
    noise = {"distance_noise": 0.02, "heading_noise": 0.01, "measurement_noise": 0.3}
    err = {}
    for name, kw in (("plain", {}), ("novelty", {"novelty": nov, "novelty_threshold": 1.0})):
        f = fuse(run["odometry"], Z, noise, start_pose=run["poses"][0], **kw)
        err[name] = np.hypot(*(f[100:140, :2] - T[100:140]).T).mean()
    assert err["novelty"] < 0.5 * err["plain"], err


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    from clitools import tiny_trained

    return tiny_trained(tmp_path_factory.mktemp("novelty"))


def test_a_model_keeps_its_novelty_reference(tiny, tmp_path):
    import sfanav
    from sfanav.sfa.modelfile import read_model, save_model

    loc = tiny["loc"]
    nov = loc.novelty(tiny["images"])
    assert nov.shape == (len(tiny["images"]),) and np.isfinite(nov).all() and (nov >= 0).all()
    xy, nov2 = loc.predict_with_novelty(tiny["images"])
    assert np.array_equal(xy, loc.predict(tiny["images"])) and np.allclose(nov, nov2)
    assert loc.novelty(tiny["images"][0]) == pytest.approx(nov[0])
    # a model file written before the reference existed: loads, predicts, and says why it has no novelty
    kind, state, manifest = read_model(tiny["model"])
    state.pop("novelty")
    old = save_model(tmp_path / "old.sfa", kind, state, version=int(manifest["version"]))
    old_loc = sfanav.load(old)
    assert np.array_equal(old_loc.predict(tiny["images"]), xy)
    with pytest.raises(ValueError, match="no novelty reference"):
        old_loc.novelty(tiny["images"])
    # the fused path without novelty then: the plain fuse
    est, fused = fuse_images(old_loc, tiny["images"], tiny["odometry"])
    assert np.array_equal(fused, fuse(tiny["odometry"], est, old_loc.info["ekf_noise"]))


def test_fuse_images_and_the_stream_scale_the_noise_alike(tiny):
    loc = tiny["loc"]
    est, fused = fuse_images(loc, tiny["images"], tiny["odometry"], novelty_threshold=0.5)
    nov = loc.novelty(tiny["images"])
    assert np.array_equal(fused, fuse(tiny["odometry"], est, loc.info["ekf_noise"], novelty=nov,
                                      novelty_threshold=0.5))
    stamps = [10**18 + k * 10**8 for k in range(len(est))]
    live = StreamingLocalizer(loc, novelty_threshold=0.5)
    out = live.push_images(stamps, tiny["images"])
    for t, p in zip(stamps, tiny["odometry"]):
        out += live.push_odometry(t, p)
    out += live.flush()
    assert len(out) == len(est)
    assert np.allclose(np.array([e.pose for e in out]), fused, atol=1e-9)
    ms = noise_novelty_scale(loc.info["ekf_noise"], nov, 0.5)
    assert live.n_novel_ == int((ms > 1).sum()) and live.max_measurement_scale_ == pytest.approx(ms.max())
    with pytest.raises(ValueError, match="novelty_threshold"):
        StreamingLocalizer(loc, novelty_threshold=0.0)


def test_the_noise_is_chosen_with_its_novelty_exponent(tiny):
    loc = tiny["loc"]
    noise = loc.info["ekf_noise"]  # chosen on the training run by sfanav train
    assert 0.0 <= noise["novelty_exponent"] <= 1.0 and noise["novelty_knee"] >= 1.0
    # on another run (the test run standing in for a training run): the exponent of its held-out errors, the knee
    # the held-out novelty's quantile
    F = loc.readout_features(loc.features(tiny["images"]),
                             loc.signatures(tiny["images"]) if loc.n_signature_ else None)
    xy = loc.predict(tiny["images"])
    again = noise_for_localizer(loc, F, xy, tiny["odometry"])
    assert 0.0 <= again["novelty_exponent"] <= 1.0 and again["novelty_knee"] >= 1.0
    assert noise_for_localizer(loc, F, xy, tiny["odometry"]) == again
    plain = noise_for_localizer(loc, F, xy, tiny["odometry"], novelty_threshold=None)
    assert "novelty_exponent" not in plain and "novelty_knee" not in plain
