"""Odometry increments, dead reckoning and line segmentation (thesis 5.3.1)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sfanav.odometry import Lines, dead_reckon, increments, lines_from_labels, lines_from_odometry, segment_lines, wrap_angle


def square_walk(side_steps=20, turn_steps=5, step=0.2, laps=1):
    """Drive a square: straight legs, turns of +90 degrees on the spot."""
    steps = []
    for _ in range(4 * laps):
        steps += [(step, 0.0)] * side_steps + [(0.0, np.pi / 2 / turn_steps)] * turn_steps
    return np.array(steps)


def test_increments_and_dead_reckoning_invert_each_other():
    rng = np.random.default_rng(0)
    U = np.c_[rng.normal(0.1, 0.08, 300), rng.normal(0, 0.2, 300)]  # includes reversing steps
    P = dead_reckon(U, (1.0, -2.0, 3.0))
    assert P.shape == (301, 3) and np.allclose(P[0], (1.0, -2.0, 3.0))
    np.testing.assert_allclose(increments(P), U, atol=1e-12)
    # headings given wrapped give the same increments
    Pw = P.copy()
    Pw[:, 2] = wrap_angle(Pw[:, 2])
    np.testing.assert_allclose(increments(Pw), U, atol=1e-12)
    # an arc: quarter circle of radius 2 in 10 steps
    Q = dead_reckon(np.tile([np.pi / 10, np.pi / 20], (10, 1)))
    np.testing.assert_allclose(Q[-1], (2.0, 2.0, np.pi / 2), atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(0.01, 3.0))
def test_increments_with_direction_reproduce_any_odometry(seed, scale):
    # arbitrary poses: sideways slides, turns on the spot before or after driving, reversing, standing still
    rng = np.random.default_rng(seed)
    P = np.c_[np.cumsum(scale * rng.normal(size=(40, 2)), axis=0), rng.uniform(-np.pi, np.pi, 40)]
    P[5] = P[4]  # standing still
    P[9, :2] = P[8, :2]  # a turn on the spot
    U = increments(P, direction=True)
    assert U.shape == (39, 3) and np.all(np.abs(U[:, 2]) <= np.pi / 2 + 1e-12)
    np.testing.assert_allclose(U[:, :2], increments(P), atol=1e-12)  # the first two columns are the arc's
    Q = dead_reckon(U, P[0])
    np.testing.assert_allclose(Q[:, :2], P[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(Q[:, 2] - P[:, 2]), 0.0, atol=1e-9)


def test_a_turn_on_the_spot_then_a_step_is_off_the_arc():
    P = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, np.pi / 2]])  # quarter turn, then 2 m: a mower's lane change
    U = increments(P, direction=True)
    np.testing.assert_allclose(U[0, 1:], [np.pi / 2, np.pi / 4], atol=1e-12)
    arc = dead_reckon(U[:, :2])[-1]
    assert np.hypot(arc[0], arc[1] - 2.0) > 1.4  # the arc model misses by 2 sin(pi / 4)
    np.testing.assert_allclose(dead_reckon(U)[-1], [0.0, 2.0, np.pi / 2], atol=1e-12)
    with pytest.raises(ValueError, match="steps must have shape"):
        dead_reckon(np.zeros((3, 4)))


def test_segment_lines_on_a_square():
    P = dead_reckon(square_walk(), (0.0, 0.0, 0.0))
    lines = segment_lines(P)
    assert lines.n_lines == 4 and lines.n_points == 84
    np.testing.assert_allclose(lines.lengths(), 4.0)
    np.testing.assert_allclose(lines.relative_angles, np.pi / 2)
    np.testing.assert_allclose(lines.headings, wrap_angle(np.arange(4) * np.pi / 2), atol=1e-12)
    np.testing.assert_allclose(lines.origins, [[0, 0], [4, 0], [4, 4], [0, 4]], atol=1e-12)
    on = lines.mask
    assert np.isnan(lines.distances[~on]).all() and (lines.labels[~on] == -1).all()
    np.testing.assert_allclose(lines.distances[lines.labels == 1], np.arange(21) * 0.2, atol=1e-12)
    assert "4 lines" in repr(lines)
    # transits: turns of 90 degrees on the spot; each next origin 4 m ahead in the line's frame
    np.testing.assert_allclose(lines.transit_lengths, 0.0, atol=1e-12)
    np.testing.assert_allclose(lines.transit_turns, np.pi / 2)
    np.testing.assert_allclose(lines.transits(), [[4.0, 0.0]] * 3, atol=1e-12)
    np.testing.assert_allclose(lines.path_lengths(), 4.0)


def test_lines_from_odometry_matches_segmentation():
    P = dead_reckon(square_walk(), (1.0, 2.0, 0.3))
    seg = segment_lines(P)
    known = lines_from_odometry(seg.labels, P)
    for name in ("distances", "relative_angles", "headings", "origins", "transit_lengths", "transit_turns"):
        np.testing.assert_allclose(np.nan_to_num(getattr(known, name)), np.nan_to_num(getattr(seg, name)), atol=1e-12)
    lab = seg.labels.copy()
    with pytest.raises(ValueError, match="must match"):
        lines_from_odometry(lab[:-1], P)
    bad = lab.copy()
    bad[5] = 1  # line 1 interrupts line 0
    with pytest.raises(ValueError, match="not contiguous"):
        lines_from_odometry(bad, P)
    swapped = np.where(lab == 0, 1, np.where(lab == 1, 0, lab))
    with pytest.raises(ValueError, match="driving order"):
        lines_from_odometry(swapped, P)
    with pytest.raises(ValueError, match="no line"):
        lines_from_odometry(np.full(len(P), -1), P)
    with pytest.raises(ValueError, match="transit_turns must be >= 0"):
        lines_from_labels(lab, seg.distances, transit_turns=-np.ones(3))


def test_segment_lines_thresholds_and_noise():
    rng = np.random.default_rng(1)
    U = square_walk(laps=2)
    Un = U + np.c_[0.002 * rng.normal(size=len(U)), 0.005 * rng.normal(size=len(U))]
    lines = segment_lines(dead_reckon(Un), dt=0.5)  # auto thresholds follow the noise and the time step
    assert lines.n_lines == 8
    np.testing.assert_allclose(lines.relative_angles, np.pi / 2, atol=0.1)
    # a min_points above the leg length finds nothing, with the thresholds in the message
    with pytest.raises(ValueError, match="no line found.*min_points"):
        segment_lines(dead_reckon(Un), min_points=50)
    with pytest.raises(ValueError, match="no line found"):
        segment_lines(dead_reckon(Un), max_turn_rate=0.0)
    with pytest.raises(ValueError, match="never moves"):
        segment_lines(np.zeros((10, 3)))


def test_bad_odometry_inputs():
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        increments(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="at least 2 rows"):
        segment_lines(np.zeros((1, 3)))
    with pytest.raises(ValueError, match="NaN"):
        increments(np.array([[0, 0, 0], [np.nan, 0, 0.0]]))
    with pytest.raises(ValueError, match="dt must be positive"):
        segment_lines(dead_reckon(square_walk()), dt=0.0)
    with pytest.raises(ValueError, match="start_pose"):
        dead_reckon(np.zeros((3, 2)), (0.0, 0.0))


def test_lines_from_labels_checks():
    lines = lines_from_labels([0, 0, 0, -1, 1, 1, 1], [0, 1, 2, np.nan, 0, 1, 2], [0.5])
    assert isinstance(lines, Lines) and lines.n_lines == 2 and list(lines.sizes()) == [3, 3]
    with pytest.raises(ValueError, match="one value per sample"):
        lines_from_labels([0, 0, 1], [0, 1])
    with pytest.raises(ValueError, match="without gaps"):
        lines_from_labels([0, 0, 2, 2], [0, 1, 0, 1])
    with pytest.raises(ValueError, match="relative_angles must have shape"):
        lines_from_labels([0, 0, 1, 1], [0, 1, 0, 1], [0.1, 0.2])
    with pytest.raises(ValueError, match="NaN or infinity"):
        lines_from_labels([0, 0, 1, 1], [0, np.nan, 0, 1])
    with pytest.raises(TypeError, match="integers"):
        lines_from_labels([0, 0.5], [0, 1])
