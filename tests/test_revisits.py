"""The revisit ratio that decides loop-closure feedback (sfanav.loopclosure.revisits), and the training recipe's
``feedback`` policy (sfanav.pipeline.train_localizer)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sfanav.loopclosure import GroundTruthDetector
from sfanav.loopclosure.revisits import (FEEDBACK_RATIO, FEEDBACK_RATIO_LEARNED, MIN_REVISITS, RevisitChange,
                                         revisit_change, revisit_pairs)


def _loop(n=400, laps=2, radius=3.0):
    """A circle driven ``laps`` times, each lap 3 cm further out (revisits 3 cm apart)."""
    t = np.linspace(0, 2 * np.pi * laps, n, endpoint=False)
    r = radius + 0.03 * np.floor(t / (2 * np.pi))
    return np.c_[np.cos(t), np.sin(t)] * r[:, None]


def test_a_position_code_gives_one_and_a_time_code_needs_feedback():
    xy = _loop()
    c, s = np.cos(0.5), np.sin(0.5)
    place = np.c_[xy, xy @ np.array([[c, -s], [s, c]])]  # as fast in every direction (module docstring)
    rc = revisit_change(place, xy)
    assert rc.n_revisits > MIN_REVISITS and 0.8 < rc.ratio < 1.25 and not rc.needs_feedback()
    assert rc.step == pytest.approx(np.median(np.hypot(*np.diff(xy, axis=0).T)), rel=1e-12)
    assert rc.revisit_distance == pytest.approx(0.03, abs=1e-6)
    timed = np.c_[np.linspace(0, 20, len(xy)), place]  # the slowest feature: the run's time (a rising light)
    rc = revisit_change(timed, xy)
    assert rc.ratio > 5 * FEEDBACK_RATIO and rc.needs_feedback()
    assert rc.to_dict()["n_revisits"] == rc.n_revisits


def test_only_the_slowest_features_count():
    """A faster feature that tells a pass from the next (the direction of travel in a closed room) is not what
    feedback is for: beyond ``n_features`` it is not compared."""
    xy = _loop()
    lap = (np.arange(len(xy)) >= len(xy) // 2).astype(float)
    F = np.c_[xy, xy[:, ::-1] * 0.5, lap * 10]
    assert not revisit_change(F, xy).needs_feedback()
    assert revisit_change(F, xy, n_features=5).needs_feedback()


def test_revisits_are_the_ground_truth_detectors_closures():
    rng = np.random.default_rng(0)
    xy = _loop(300, 3) + rng.normal(0, 0.02, (300, 2))
    cur, past = revisit_pairs(xy, max_distance=0.1, min_gap=40)
    lc = GroundTruthDetector(max_distance=0.1, min_gap=40).detect(np.zeros((len(xy), 2, 8)), positions=xy)
    np.testing.assert_array_equal(cur, lc.current)
    np.testing.assert_array_equal(past, lc.past)
    assert (cur - past >= 40).all()


def test_given_pairs_replace_the_positions_revisits():
    xy = _loop()
    timed = np.c_[np.linspace(0, 20, len(xy)), xy]
    cur, past = revisit_pairs(xy)
    assert revisit_change(timed, xy, pairs=(cur, past)).ratio == pytest.approx(revisit_change(timed, xy).ratio)
    near = np.arange(10, 60), np.arange(9, 59)  # neighbours in time: the time code hardly differs there
    assert not revisit_change(timed, xy, pairs=near).needs_feedback()
    with pytest.raises(ValueError, match="pairs must be"):
        revisit_change(timed, xy, pairs=(cur, past[:-1]))
    with pytest.raises(ValueError, match="pairs must index"):
        revisit_change(timed, xy, pairs=(cur, past + len(xy)))


def test_too_few_revisits_decide_nothing():
    xy = np.c_[np.linspace(0, 10, 200), np.zeros(200)]  # one straight pass: no place seen twice
    rc = revisit_change(np.c_[xy[:, :1], np.linspace(0, 50, 200)], xy)
    assert rc.n_revisits == 0 and np.isnan(rc.ratio) and not rc.needs_feedback()
    assert rc.to_dict()["ratio"] is None
    still = np.zeros((200, 2))  # never moves: every frame a revisit, no step to scale by
    rc = revisit_change(np.random.default_rng(1).normal(size=(200, 3)), still)
    assert np.isnan(rc.ratio) and not rc.needs_feedback()


@settings(max_examples=25, deadline=None)
@given(scale=st.floats(0.01, 100), shift=st.floats(-50, 50), seed=st.integers(0, 1000))
def test_the_ratio_ignores_feature_scales_and_where_the_map_lies(scale, shift, seed):
    rng = np.random.default_rng(seed)
    xy = _loop(240, 2) + rng.normal(0, 0.01, (240, 2))
    F = np.c_[xy, np.sin(xy[:, 0]), np.linspace(0, rng.uniform(0, 5), 240)]
    base = revisit_change(F, xy)
    moved = revisit_change(F * np.r_[scale, 1.0, 1 / scale, scale] + 3.0, xy + shift)
    assert moved.ratio == pytest.approx(base.ratio, rel=1e-6)


def test_bad_input_is_refused():
    xy = _loop(100)
    with pytest.raises(ValueError, match="must match"):
        revisit_change(np.zeros((99, 3)), xy)
    with pytest.raises(ValueError, match="features"):
        revisit_change(np.full((100, 3), np.nan), xy)
    with pytest.raises(ValueError, match="positions"):
        revisit_change(np.zeros((100, 3)), np.zeros((100, 3, 1)))
    with pytest.raises(ValueError, match="max_distance"):
        revisit_pairs(xy, max_distance=0)
    with pytest.raises(ValueError, match="min_gap"):
        revisit_pairs(xy, min_gap=0)
    with pytest.raises(ValueError, match="n_features"):
        revisit_change(np.zeros((100, 3)), xy, n_features=0)


# ------------------------------------------------------------------------------------------------ the recipe
CONFIG = {"input": {"width": 60, "height": 8, "channels": 3}, "network": {"precision": "double"},
          "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 10}, {"rf": "full", "out": 10}]}


def tiny_loop_run(n=160):
    """A tiny synthetic run that drives a circle twice: images (n, 8, 60, 3) uint8 and positions."""
    xy = _loop(n, 2, 2.0)
    rng = np.random.default_rng(0)
    cols = np.arange(60)
    X = np.empty((n, 8, 60, 3), np.uint8)
    for i, (x, y) in enumerate(xy):
        row = 120 + 60 * np.sin(cols / 60 * 2 * np.pi + x) + 30 * np.cos(cols / 20 + y)
        X[i] = np.clip(row[None, :, None] + rng.normal(0, 2, (8, 60, 3)), 0, 255).astype(np.uint8)
    return X, xy


@pytest.fixture(scope="module")
def tiny_run():
    return tiny_loop_run()


def _train(X, xy, monkeypatch, ratio, *, learned=False, **kw):
    """train_localizer with the revisit measure replaced by ``ratio`` and the bag of words by ground-truth
    closures; ``learned``: without ground truth, the pose graph's map replaced by the ground truth (the policy's
    threshold is what is tested, not the map)."""
    import sfanav.pipeline as pipeline
    from sfanav import Network, Rotation
    from sfanav.localization.recipe import recipe_for

    calls = []

    def measured(F, positions):
        calls.append(len(F))
        return RevisitChange(ratio, 40, 0.05, 0.2, 1.0)

    class Detector:
        def detect(self, images):
            return GroundTruthDetector(max_distance=0.2, min_gap=20).detect(images, positions=xy)

    monkeypatch.setattr(pipeline, "revisit_change", measured)
    monkeypatch.setattr(pipeline, "make_detector", lambda kind: Detector())
    maps = []
    if learned:
        def mapped(network, images, odometry, *, method, timestamps, gyro, readout_memory, pose_graph,
                   loop_closures, learned, **fit_kw):
            maps.append(learned)  # the map the recipe hands over (None: learn one)
            loc = pipeline.fit_localizer(network, images, xy, readout_memory=readout_memory,
                                         loop_closures=loop_closures, **fit_kw)
            loc.learned_positions_ = learned if learned is not None else object()
            return loc

        monkeypatch.setattr(pipeline, "fit_localizer_from_odometry", mapped)
        heading = np.arctan2(*np.gradient(xy, axis=0).T[::-1])
        kw = {"odometry": np.c_[xy, heading], "supervision": "odometry", **kw}
    else:
        kw = {"xy": xy, **kw}
    log = []
    loc = pipeline.train_localizer(X, network=Network(CONFIG), rotation=Rotation(step=6),
                                   recipe=recipe_for(config=True, readout="quadratic", robustness="none"),
                                   log=log.append, filter_noise=False, **kw)
    if learned:
        log.append(maps)
    return loc, calls, log


def test_auto_feedback_trains_again_with_closures_when_the_code_changes(tiny_run, monkeypatch):
    X, xy = tiny_run
    loc, calls, log = _train(X, xy, monkeypatch, 10.0, feedback="auto")
    assert calls == [len(X)]
    assert loc.info["feedback"]["closures"] == "bow" and loc.info["feedback"]["count"] > 0
    assert loc.info["loop_closures"] == loc.info["feedback"]["count"]  # the network trained with them
    assert loc.info["revisit change"]["ratio"] == 10.0
    assert any("training again" in line for line in log)


def test_auto_feedback_keeps_the_first_model_when_the_code_holds(tiny_run, monkeypatch):
    X, xy = tiny_run
    loc, calls, log = _train(X, xy, monkeypatch, 1.0, feedback="auto")
    assert calls == [len(X)] and "feedback" not in loc.info and loc.info["loop_closures"] == 0
    assert any("no feedback needed" in line for line in log)


def test_learned_positions_send_a_lower_ratio_to_feedback(tiny_run, monkeypatch):
    """Between the two thresholds: ground-truth positions keep the first model, learned ones train again."""
    X, xy = tiny_run
    ratio = (FEEDBACK_RATIO + FEEDBACK_RATIO_LEARNED) / 2
    loc, _, _ = _train(X, xy, monkeypatch, ratio, feedback="auto")
    assert "feedback" not in loc.info and loc.info["revisit change"]["threshold"] == FEEDBACK_RATIO
    loc, calls, log = _train(X, xy, monkeypatch, ratio, feedback="auto", learned=True)
    assert calls == [len(X)] and loc.info["feedback"]["closures"] == "bow"
    # the second training keeps the first one's learned map rather than learning one from its features
    first, again = log.pop()
    assert first is None and again is not None and loc.learned_positions_ is again
    assert loc.info["feedback"]["map"] == "the first training's"
    assert any("keeping the positions the first training learned" in str(line) for line in log)
    assert loc.info["revisit change"]["threshold"] == FEEDBACK_RATIO_LEARNED < FEEDBACK_RATIO
    assert any(f"above {FEEDBACK_RATIO_LEARNED:g}" in str(line) for line in log)
    loc, _, _ = _train(X, xy, monkeypatch, FEEDBACK_RATIO_LEARNED * 0.9, feedback="auto", learned=True)
    assert "feedback" not in loc.info


def test_a_code_changing_too_much_learns_the_map_again(tiny_run, monkeypatch):
    """Above FIRST_MAP_MAX_RATIO the first network's map is not kept: the second training learns its own."""
    from sfanav.pipeline import FIRST_MAP_MAX_RATIO

    X, xy = tiny_run
    loc, calls, log = _train(X, xy, monkeypatch, FIRST_MAP_MAX_RATIO * 1.5, feedback="auto", learned=True)
    assert calls == [len(X)] and log.pop() == [None, None]
    assert loc.info["feedback"]["map"] == "learned again"
    assert any("learning the positions again" in str(line) for line in log)
    loc, _, _ = _train(X, xy, monkeypatch, FIRST_MAP_MAX_RATIO * 1.5, feedback="auto")
    assert loc.info["feedback"]["map"] == "ground truth"


def test_feedback_none_and_other_recipes_never_measure(tiny_run, monkeypatch):
    X, xy = tiny_run
    for kw in ({"feedback": "none"}, {}):  # {}: a config-file recipe is not the sfanav default's
        loc, calls, _ = _train(X, xy, monkeypatch, 10.0, **kw)
        assert calls == [] and "revisit change" not in loc.info and "feedback" not in loc.info


def test_feedback_is_checked_before_training(tiny_run):
    from sfanav.pipeline import train_localizer

    X, xy = tiny_run
    with pytest.raises(ValueError, match="feedback must be one of"):
        train_localizer(X, xy=xy, feedback="always")
