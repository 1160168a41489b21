"""Loop-closure detection: the three detectors behind one interface,
alignment, precision / recall / AP against ground truth, the long-term
training order, and bad input."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_network import render

import sfanav
from sfanav.loopclosure import (
    BagOfWordsDetector,
    FourierDetector,
    GroundTruthDetector,
    LoopClosures,
    align,
    arc_fraction,
    closure_precision_recall,
    correspondences,
    make_detector,
    place_major_order,
    plot_closures,
    suppress,
)


def _loop_run(n_lap=60, laps=2, seed=0, width=48):
    """A square loop driven ``laps`` times with small position jitter and
    random headings: every frame of a later lap closes with the same place
    of the first."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_lap) / n_lap
    side = np.floor(t * 4)
    f = t * 4 - side
    corners = np.array([[0.2, 0.2], [0.8, 0.2], [0.8, 0.8], [0.2, 0.8], [0.2, 0.2]])
    lap = corners[side.astype(int)] + f[:, None] * (corners[side.astype(int) + 1] - corners[side.astype(int)])
    xy = np.concatenate([lap + rng.normal(0, 0.003, lap.shape) for _ in range(laps)])
    heading = rng.uniform(-np.pi, np.pi, len(xy))
    imgs = np.stack([render(p, h, width=width) for p, h in zip(xy, heading)])
    imgs += rng.normal(0, 0.01, imgs.shape)
    return imgs, xy, heading


@settings(max_examples=30, deadline=None)
@given(st.integers(8, 64), st.integers(1, 6), st.integers(0, 200), st.booleans())
def test_align_recovers_a_roll(width, height, shift, rgb):
    rng = np.random.default_rng(width * 31 + shift)
    shape = (1, height, width, 3) if rgb else (1, height, width)
    a = rng.random(shape)
    b = np.roll(a, shift, axis=2)
    assert align(np.concatenate([a, b]), [0], [1])[0] == shift % width


def test_ground_truth_detector_finds_the_crossings():
    xy = np.array([[0, 0], [1, 0], [2, 0], [3, 0], [2, 1], [2.05, 0.0], [2, -1], [0.5, 0.0], [0.02, 0.01]], float)
    imgs = np.zeros((len(xy), 2, 8))
    lc = GroundTruthDetector(max_distance=0.1, min_gap=2).detect(imgs, positions=xy)
    assert list(zip(lc.past, lc.current)) == [(2, 5), (0, 8)]
    np.testing.assert_allclose(lc.distance, [0.05, np.hypot(0.02, 0.01)])
    assert np.all((lc.score > 0.5) & (lc.score <= 1))
    # a larger gap leaves out the closure of frames 2 and 5
    lc = GroundTruthDetector(max_distance=0.1, min_gap=4).detect(imgs, positions=xy)
    assert list(zip(lc.past, lc.current)) == [(0, 8)]
    # candidates: every frame that has frames far enough back, thresholded or not
    cand = GroundTruthDetector(max_distance=0.1, min_gap=4).candidates(imgs, positions=xy)
    assert cand.current.tolist() == [4, 5, 6, 7, 8]


def test_suppress_keeps_the_best_closure_per_pass():
    lc = LoopClosures(np.array([0, 1, 2, 3]), np.array([10, 11, 12, 30]), np.zeros(4, int),
                      np.array([0.5, 0.9, 0.7, 0.6]), np.zeros(4))
    kept = suppress(lc, 3)
    assert kept.current.tolist() == [11, 30]
    assert len(suppress(lc, 0)) == 4


def test_image_detectors_close_the_loop():
    imgs, xy, _ = _loop_run()
    # (a lap is 2.4 m in 60 frames; a random earlier frame is within 0.15 m about one time in ten)
    for det, tol, bar in ((FourierDetector(min_gap=20), 0.06, 0.8),
                          (BagOfWordsDetector(n_words=100, keypoint_size=6, grid_step=2, min_gap=20), 0.15, 0.55)):
        lc = det.detect(imgs)
        q = closure_precision_recall(lc, xy, max_distance=tol, min_gap=20)
        assert len(lc) >= 20, type(det).__name__
        assert q.precision >= bar, (type(det).__name__, q)
        assert q.recall >= 0.3, (type(det).__name__, q)
        # the shifts align the earlier panorama to the current one's heading
        err = [np.abs(np.roll(imgs[p], s, axis=1) - imgs[c]).mean() for p, c, s in zip(lc.past, lc.current, lc.shift)]
        raw = [np.abs(imgs[p] - imgs[c]).mean() for p, c in zip(lc.past, lc.current)]
        assert np.median(err) < 0.5 * np.median(raw)
    bow = BagOfWordsDetector(n_words=40, keypoint_size=4, grid_step=2, min_gap=20)
    bow.detect(imgs)
    assert bow.vocabulary_.shape == (40, 128) and bow.idf_.shape == (40,)
    H = bow.histograms(imgs[:3])
    np.testing.assert_allclose(np.linalg.norm(H, axis=1), 1.0, rtol=1e-9)



def test_a_revisit_that_looks_identical_is_a_closure_not_an_error():
    """A static scene driven twice over the same poses renders identical panoramas: their aligned distance is
    zero up to rounding (it was slightly negative and the score left [0, 1])."""
    imgs, xy, _ = _loop_run(n_lap=40, laps=1)
    rng = np.random.default_rng(3)
    X = np.concatenate([imgs, imgs[rng.permutation(15)[:10]]])  # ten exact revisits, >= 25 frames later
    det = BagOfWordsDetector(n_words=40, keypoint_size=4, grid_step=2, min_gap=20)
    cand = det.candidates(X)
    assert np.all((cand.score >= 0) & (cand.score <= 1))
    revisit = cand.current >= len(imgs)
    assert revisit.sum() == 10
    # every revisit is matched to an identical earlier panorama (score 1: distance 0)
    np.testing.assert_array_equal(X[cand.past[revisit]], X[cand.current[revisit]])
    np.testing.assert_allclose(cand.score[revisit], 1.0, atol=1e-5)

def test_odometry_gate_and_find_loop_closures():
    imgs, xy, _ = _loop_run()
    far = xy + np.array([[5.0, 0.0]]) * (np.arange(len(xy)) >= 60)[:, None]  # odometry says: never back
    gated = FourierDetector(min_gap=20, max_odometry_distance=1.0).detect(imgs, odometry=far)
    assert np.all((gated.past >= 60) == (gated.current >= 60))  # only each lap's own end closes with its start
    old = sfanav.loopclosure.find_loop_closures(imgs, min_gap=20)
    new = FourierDetector(min_gap=20).detect(imgs)
    np.testing.assert_array_equal(old.current, new.current)


def test_average_precision_by_hand():
    # 4 frames far apart, frame 3 back at frame 0; candidates for frames 2 and 3
    xy = np.array([[0, 0], [5, 0], [10, 0], [0.05, 0]], float)
    lc = LoopClosures(np.array([1, 0]), np.array([2, 3]), np.zeros(2, int), np.array([0.9, 0.6]),
                      np.zeros(2))
    q = closure_precision_recall(lc, xy, max_distance=0.1, min_gap=1)
    # ranked: (1, 2) false at 0.9, (0, 3) true at 0.6: precision at the hit 1/2, one possible closure
    assert q.n_possible == 1 and q.precision == 0.5 and q.recall == 1.0
    assert q.average_precision == pytest.approx(0.5)
    assert q.mean_distance == pytest.approx((5 + 0.05) / 2)


def test_make_detector_and_plot(tmp_path):
    assert isinstance(make_detector("gt", max_distance=0.2), GroundTruthDetector)
    assert isinstance(make_detector("fourier"), FourierDetector)
    assert isinstance(make_detector("bow", n_words=10), BagOfWordsDetector)
    with pytest.raises(ValueError, match="unknown loop-closure detector"):
        make_detector("surf")
    imgs, xy, _ = _loop_run(n_lap=30)
    lc = GroundTruthDetector(max_distance=0.05, min_gap=10).detect(imgs, positions=xy)
    p = plot_closures(xy, lc, tmp_path / "lc.png", title="closures")
    assert p.stat().st_size > 1000


def test_loop_closures_validate_and_round_trip(tmp_path):
    lc = LoopClosures(np.array([1, 2]), np.array([5, 9]), np.array([3, 0]), np.array([0.5, 1.0]), np.array([1., 2.]))
    np.savez(tmp_path / "lc.npz", **lc.to_arrays())
    back = LoopClosures.from_arrays(np.load(tmp_path / "lc.npz", allow_pickle=False))
    for k, v in lc.to_arrays().items():
        np.testing.assert_array_equal(getattr(back, k), v)
    assert len(lc.select(np.array([True, False]))) == 1
    bad = [((np.array([5]), np.array([1]), [0], [1.0], [0.0]), "before its current"),
           ((np.array([1]), np.array([5]), [0], [1.5], [0.0]), r"\[0, 1\]"),
           ((np.array([1.0]), np.array([5]), [0], [1.0], [0.0]), "integers"),
           ((np.array([1, 2]), np.array([5]), [0], [1.0], [0.0]), "one length"),
           ((np.array([1]), np.array([5]), [0], [np.nan], [0.0]), "finite")]
    for args, msg in bad:
        with pytest.raises(ValueError, match=msg):
            LoopClosures(*args)
    with pytest.raises(ValueError, match="lack"):
        LoopClosures.from_arrays({"past": [1]})


def test_bad_detector_input():
    imgs = np.zeros((10, 4, 16))
    xy = np.zeros((10, 2))
    with pytest.raises(ValueError, match="needs positions"):
        GroundTruthDetector().detect(imgs)
    with pytest.raises(ValueError, match="positions has 9 rows"):
        GroundTruthDetector().detect(imgs, positions=xy[:9])
    with pytest.raises(ValueError, match="NaN"):
        GroundTruthDetector().detect(imgs, positions=np.full((10, 2), np.nan))
    with pytest.raises(ValueError, match="max_distance must be > 0"):
        GroundTruthDetector(max_distance=0).detect(imgs, positions=xy)
    with pytest.raises(ValueError, match="min_gap must be at least 1"):
        FourierDetector(min_gap=-3).detect(imgs)
    with pytest.raises(ValueError, match="n_words must be at least 2"):
        BagOfWordsDetector(n_words=1).detect(imgs)
    with pytest.raises(ValueError, match="shape"):
        FourierDetector().detect(np.zeros((4, 4)))
    with pytest.raises(ValueError, match="no vocabulary"):
        BagOfWordsDetector().histograms(imgs)


def test_long_term_order_and_correspondences():
    assert place_major_order([np.array([0, 1, 2]), np.array([0, 1, 2])]).tolist() == [0, 3, 1, 4, 2, 5]
    # a recording that starts later on the loop: its frames go to their places
    order = place_major_order([np.array([0, 1, 2]), np.array([1, 2, 0])])
    assert order.tolist() == [0, 5, 1, 3, 2, 4]
    ref = np.array([[0, 0], [1, 0], [2, 0]], float)
    assert correspondences(ref, ref[::-1] + 0.1).tolist() == [2, 1, 0]
    odo = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], float)
    np.testing.assert_allclose(arc_fraction(odo), [0, 0.25, 0.5, 0.75, 1.0])
    assert correspondences(arc_fraction(odo), np.array([0.26, 0.9])).tolist() == [1, 4]
    with pytest.raises(ValueError, match="both"):
        correspondences(ref, np.array([0.5]))
    with pytest.raises(ValueError, match="does not move"):
        arc_fraction(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="1-D integer"):
        place_major_order([np.array([0.5])])


def test_detected_closures_train_the_network():
    imgs, xy, _ = _loop_run(n_lap=40)
    lc = FourierDetector(min_gap=20).detect(imgs)
    assert len(lc) > 5
    cfg = {"input": {"width": 48, "height": 8, "channels": 1},
           "layers": [{"rf": [6, 4], "stride": [3, 2], "out": 8}, {"rf": "full", "out": 3}]}
    rot = sfanav.Rotation(step=6)
    net = sfanav.Network(cfg).fit(imgs, rot, progress=False, loop_closures=lc, closure_weights="score")
    assert net.n_loop_closures_ == len(lc)
    plain = sfanav.Network(cfg).fit(imgs, rot, progress=False)
    assert not np.allclose(net.delta_values_, plain.delta_values_, rtol=1e-3)


def test_normalised_fourier_signatures_survive_a_light_ramp():
    imgs, xy, _ = _loop_run()
    dim = imgs * np.linspace(0.4, 1.4, len(imgs))[:, None, None]
    plain = closure_precision_recall(FourierDetector(min_gap=20).detect(dim), xy, max_distance=0.06, min_gap=20)
    norm = closure_precision_recall(FourierDetector(min_gap=20, normalize=True).detect(dim), xy, max_distance=0.06,
                                    min_gap=20)
    assert norm.recall > plain.recall + 0.3, (plain, norm)
    assert norm.precision >= 0.8, norm
