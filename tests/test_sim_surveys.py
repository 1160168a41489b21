"""Surveys as robot mowers drive them, the mower's odometry and gyro, the
gyro column of a dataset and the mower-survey preset (issue 42)."""

import numpy as np
import pytest

from sfanav import Dataset, sim, write_dataset
from sfanav.sim import surveys as S
from sfanav.sim.robot import GyroNoise, OdometryNoise, Robot, simulate_gyro, simulate_odometry, wrap_angle

AREA = (12.0, 10.0)


def _steps(tr):
    return np.hypot(*np.diff(tr.poses[:, :2], axis=0).T)


def _travel_direction(tr):
    """The direction from each frame's previous to its next one (the tangent
    of a circle through equally spaced frames), inner frames."""
    d = tr.poses[2:, :2] - tr.poses[:-2, :2]
    return np.arctan2(d[:, 1], d[:, 0])


@pytest.mark.parametrize("pattern", S.SURVEY_PATTERNS)
def test_every_pattern_stays_in_the_area_faces_its_travel_and_is_spaced(pattern):
    tr = S.survey(pattern, AREA, 1.5, 0.5, n_frames=200, margin=0.5, rng=3)
    P = tr.poses
    assert (np.abs(P[:, 0]) <= 5.5 + 1e-9).all() and (np.abs(P[:, 1]) <= 4.5 + 1e-9).all()
    steps = _steps(tr)
    # frames 0.5 m apart along the path: the chord is never longer, and at most a little shorter in turns
    assert steps.max() <= 0.5 + 1e-9 and np.median(steps) == pytest.approx(0.5)
    err = np.abs(wrap_angle(P[1:-1, 2] - _travel_direction(tr)))
    if pattern == "random":  # a frame's heading is the direction it drives off in
        d = np.diff(P[:, :2], axis=0)
        np.testing.assert_allclose(wrap_angle(P[:-1, 2] - np.arctan2(d[:, 1], d[:, 0])), 0, atol=1e-9)
    else:
        assert np.median(err) < 1e-6 and err.max() < np.radians(30)
    assert np.all(np.diff(tr.times) > 0)


def test_serpentine_lanes_are_parallel_and_spaced_as_asked():
    tr = S.serpentine((30, 30), 29 / 23, 1.2)
    lane = tr.extra["lane"]
    assert sorted(set(lane[lane >= 0].tolist())) == list(range(24))
    ys = [tr.poses[lane == k, 1] for k in range(24)]
    for k, y in enumerate(ys):
        np.testing.assert_allclose(y, -14.5 + k * 29 / 23, atol=1e-9)  # straight lanes, 29/23 m apart
        heads = tr.poses[lane == k, 2]
        np.testing.assert_allclose(wrap_angle(heads - (0.0 if k % 2 == 0 else np.pi)), 0, atol=1e-9)
    assert 580 < len(tr) < 610
    np.testing.assert_allclose(tr.times * 0.4, 1.2 * np.arange(len(tr)))  # 1.2 m along the path at 0.4 m/s
    # lanes along y: the same with x and y swapped
    ty = S.serpentine((30, 30), 29 / 23, 1.2, along="y")
    np.testing.assert_allclose(ty.poses[ty.extra["lane"] == 3, 0], -14.5 + 3 * 29 / 23, atol=1e-9)


def test_serpentine_lanes_are_centred_when_the_spacing_does_not_divide():
    tr = S.serpentine((10, 10), 1.5, 0.5, margin=0.5)  # 9 m: 7 lanes span 9 m exactly
    lanes = sorted({round(float(y), 9) for y in tr.poses[tr.extra["lane"] >= 0, 1]})
    np.testing.assert_allclose(np.diff(lanes), 1.5)
    tr = S.serpentine((10, 10), 2.0, 0.5, margin=0.5)  # 5 lanes span 8 of 9 m: 0.5 m left on each side
    lanes = sorted({round(float(y), 9) for y in tr.poses[tr.extra["lane"] >= 0, 1]})
    np.testing.assert_allclose(lanes, [-4, -2, 0, 2, 4])


def test_perimeter_lap_stays_near_the_border_then_the_lanes_follow():
    tr = S.perimeter_serpentine(AREA, 1.0, 0.4, margin=0.5, turn_radius=0.5)
    lane = tr.extra["lane"]
    first = int(np.argmax(lane == 0))
    lap = tr.poses[:first, :2]
    # every lap frame within the turn radius of the border lane (0.5 m inside the border)
    gap = np.minimum(5.5 - np.abs(lap[:, 0]), 4.5 - np.abs(lap[:, 1]))
    assert gap.min() >= -1e-9 and gap.max() <= 0.5 + 1e-9 and np.median(gap) < 1e-9
    # the lap goes round: it passes every side of the area
    assert lap[:, 0].max() > 5.4 and lap[:, 0].min() < -5.4 and lap[:, 1].max() > 4.4 and lap[:, 1].min() < -4.4
    # the lanes lie one lane spacing inside the lap
    inner = tr.poses[lane >= 0, :2]
    assert np.abs(inner[:, 1]).max() <= 4.5 - 1.0 + 1e-9
    assert lane.max() >= 4


def test_spiral_laps_shrink_inwards():
    tr = S.spiral((12, 12), 1.0, 0.4, margin=0.5)
    lap = tr.extra["lap"]
    r = np.abs(tr.poses[:, :2]).max(axis=1)  # the square "radius"
    med = [np.median(r[lap == k]) for k in range(int(lap.max()) + 1)]
    assert len(med) >= 4
    np.testing.assert_allclose(np.diff(med), -1.0, atol=0.05)  # one lane spacing per lap
    assert r[-1] < 1.5 and r[0] == pytest.approx(5.5)


def test_crossing_covers_both_directions():
    tr = S.crossing(AREA, 1.5, 0.5)
    lane, P = tr.extra["lane"], tr.poses
    on = lane >= 0
    along_x = on & (np.abs(np.sin(P[:, 2])) < 1e-9)
    along_y = on & (np.abs(np.cos(P[:, 2])) < 1e-9)
    assert along_x.sum() > 0.3 * len(tr) and along_y.sum() > 0.3 * len(tr)
    assert (along_x | along_y).sum() == on.sum()
    # every x lane is driven before every y lane, and both passes span the area
    assert np.nonzero(along_x)[0].max() < np.nonzero(along_y)[0].min()
    assert np.ptp(P[along_y, 0]) > 9 and np.ptp(P[along_x, 1]) > 7
    # the second pass starts where the first ended (no jump)
    assert _steps(tr).max() <= 0.5 + 1e-9


def test_random_survey_stays_inside_and_off_obstacles():
    world = sim.World.generate(1, area=(12.0, 12.0), n_objects=0, obstacles=("v-wall",))
    assert world.obstacles
    tr = S.random_survey(world.area, 400, 0.4, margin=0.4, world=world, rng=5)
    P = tr.poses
    assert world.free(P[:, 0], P[:, 1], 0.4).all()
    assert len(tr) == 400 and np.allclose(_steps(tr), 0.4)
    again = S.random_survey(world.area, 400, 0.4, margin=0.4, world=world, rng=5)
    np.testing.assert_array_equal(again.poses, P)


def test_random_headings_keep_the_path():
    a = S.serpentine(AREA, 1.5, 0.5)
    b = S.serpentine(AREA, 1.5, 0.5, heading="random", rng=1)
    np.testing.assert_array_equal(a.poses[:, :2], b.poses[:, :2])
    assert np.std(np.cos(b.poses[:, 2])) > 0.5  # spread over the circle
    c = S.serpentine(AREA, 1.5, 0.5, heading="random", rng=1)
    np.testing.assert_array_equal(b.poses, c.poses)


def test_geometric_patterns_detour_around_obstacles():
    world = sim.World.generate(2, area=(10.0, 10.0), n_objects=0, obstacles=("v-wall",))
    tr = S.serpentine(world.area, 1.0, 0.3, world=world)
    assert not world.collides(tr.poses[:, 0], tr.poses[:, 1], 0.3).any()


@pytest.mark.parametrize("kwargs, match", [
    (dict(pattern="zigzag"), "unknown survey pattern"),
    (dict(pattern="serpentine", lane_spacing=0), "lane_spacing"),
    (dict(pattern="serpentine", lane_spacing=20), "one lane"),
    (dict(pattern="spiral", spacing=-1), "spacing"),
    (dict(pattern="crossing", margin=6), "margin"),
    (dict(pattern="serpentine", heading="north"), "heading"),
    (dict(pattern="perimeter-serpentine", lane_spacing=4.9), "perimeter"),
    (dict(pattern="random", n_frames=0), "n_frames"),
])
def test_bad_survey_parameters_raise(kwargs, match):
    kw = dict(area=AREA, lane_spacing=1.5, spacing=0.5)
    kw.update(kwargs)
    pattern = kw.pop("pattern")
    with pytest.raises(ValueError, match=match):
        S.survey(pattern, **kw)
    with pytest.raises(ValueError, match="area"):
        S.serpentine((10, -1))
    with pytest.raises(ValueError, match="along"):
        S.serpentine(AREA, along="z")


# ----------------------------------------------------------------- odometry


def _straight(length, step):
    n = int(round(length / step)) + 1
    x = np.arange(n) * step
    return np.column_stack([x, np.zeros(n), np.zeros(n)])


def test_drift_rate_is_recovered_from_a_long_straight_run():
    P = _straight(500.0, 1.0)
    noise = OdometryNoise.mower(distance_fraction=0.02, heading_deg=0.5, drift_deg_per_m=0.1, turn_fraction=0.0)
    slopes = []
    for seed in range(10):
        odo = simulate_odometry(P, noise, rng=seed)
        slopes.append(np.polyfit(P[:, 0], np.unwrap(odo[:, 2]), 1)[0])
    assert np.degrees(np.mean(slopes)) == pytest.approx(0.1, abs=0.01)


def test_per_step_noise_statistics():
    P = _straight(4000.0, 1.2)
    noise = OdometryNoise.mower(distance_fraction=0.02, heading_deg=0.5, drift_deg_per_m=0.0)
    odo = simulate_odometry(P, noise, rng=0)
    dist = np.hypot(*np.diff(odo[:, :2], axis=0).T)
    assert np.std(dist / 1.2 - 1) == pytest.approx(0.02, rel=0.1)
    dth = np.diff(odo[:, 2])
    assert np.degrees(np.std(dth)) == pytest.approx(0.5, rel=0.1) and abs(np.mean(dth)) < 0.002


def test_turn_noise_grows_with_the_turn():
    # turns on the spot by 90 degrees: sigma = a + b * |turn|
    n = 4001
    P = np.zeros((n, 3))
    P[:, 2] = wrap_angle(np.arange(n) * np.pi / 2)
    noise = OdometryNoise.mower(0.0, heading_deg=0.2, drift_deg_per_m=0.0, turn_fraction=0.05)
    odo = simulate_odometry(P, noise, rng=1)
    err = np.diff(odo[:, 2]) - np.pi / 2
    assert np.std(err) == pytest.approx(np.radians(0.2) + 0.05 * np.pi / 2, rel=0.1)


def test_slip_events_come_at_the_asked_rate():
    P = _straight(5000.0, 1.0)
    noise = OdometryNoise.mower(0.0, 0.0, 0.0, turn_fraction=0.0, slip_rate=0.02, slip_distance=0.5)
    odo = simulate_odometry(P, noise, rng=2)
    extra = np.hypot(*np.diff(odo[:, :2], axis=0).T) - 1.0
    slipped = extra > 1e-9
    assert slipped.sum() / 5000.0 == pytest.approx(0.02, rel=0.2)  # about 100 events per 5 km
    assert np.mean(extra[slipped]) == pytest.approx(0.5, rel=0.25)
    assert np.all(np.abs(extra[~slipped]) < 1e-9)


def test_default_odometry_is_unchanged_by_the_new_terms():
    P = S.serpentine(AREA, 1.5, 0.5).poses
    a = simulate_odometry(P, OdometryNoise(), rng=4)
    b = simulate_odometry(P, OdometryNoise(distance_fraction=0.0, step_heading_sigma=0.0, turn_fraction=0.0), rng=4)
    np.testing.assert_array_equal(a, b)
    c = simulate_odometry(P, OdometryNoise.mower(), rng=4)
    np.testing.assert_array_equal(c, simulate_odometry(P, OdometryNoise.mower(), rng=4))
    assert not np.array_equal(c, simulate_odometry(P, OdometryNoise.mower(), rng=5))
    perfect = simulate_odometry(P, OdometryNoise.mower(0, 0, 0, turn_fraction=0), rng=0)
    np.testing.assert_allclose(perfect[:, :2], P[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(perfect[:, 2] - P[:, 2]), 0, atol=1e-9)


def test_bad_noise_parameters_raise():
    with pytest.raises(ValueError, match="distance_fraction"):
        OdometryNoise.mower(distance_fraction=-0.1)
    with pytest.raises(ValueError, match="step_heading_sigma"):
        OdometryNoise.mower(heading_deg=float("nan"))
    with pytest.raises(TypeError, match="turn_fraction"):
        OdometryNoise(turn_fraction="0.1")
    with pytest.raises(ValueError, match="angle_random_walk"):
        GyroNoise(angle_random_walk=-1)
    with pytest.raises(ValueError, match="bias"):
        GyroNoise(bias=float("inf"))
    with pytest.raises(TypeError, match="gyro"):
        Robot(gyro={"bias": 0})
    with pytest.raises(ValueError, match="no gyro"):
        Robot().gyro_headings(np.zeros((2, 3)), [0, 1])
    with pytest.raises(ValueError, match="times"):
        simulate_gyro(np.zeros((3, 3)), [0, 1])
    with pytest.raises(ValueError, match="decrease"):
        simulate_gyro(np.zeros((3, 3)), [0, 2, 1])


# ----------------------------------------------------------------- gyro


def test_gyro_statistics():
    tr = S.spiral((10, 10), 1.0, 0.5)
    true = np.unwrap(tr.poses[:, 2])
    np.testing.assert_allclose(simulate_gyro(tr.poses, tr.times, GyroNoise.none()), true, atol=1e-9)
    # a bias alone: a heading error growing as bias * t
    g = simulate_gyro(tr.poses, tr.times, GyroNoise(0.0, 0.001, 0.0))
    np.testing.assert_allclose(g - true, 0.001 * tr.times, atol=1e-9)
    # the angle random walk: the error's spread after t is arw * sqrt(t)
    t = np.arange(2001) * 1.0
    P = np.zeros((2001, 3))
    ends = [simulate_gyro(P, t, GyroNoise(0.01, 0.0, 0.0), rng=s)[-1] for s in range(200)]
    assert np.std(ends) == pytest.approx(0.01 * np.sqrt(2000), rel=0.15)


def test_gyro_column_round_trip(tmp_path):
    tr = S.serpentine((6, 6), 1.5, 0.5)
    n = len(tr)
    gyro = Robot(gyro=GyroNoise()).gyro_headings(tr.poses, tr.times, rng=0)
    imgs = (np.zeros((4, 8), np.uint8) for _ in range(n))
    ds = write_dataset(tmp_path / "d", imgs, tr.poses, timestamps=tr.times, gyro=gyro)
    np.testing.assert_array_equal(ds.gyro, gyro)  # exact: repr floats
    assert ds.gyro.dtype == float and ds.metadata["units"]["gyro_heading"] == "rad"
    np.testing.assert_array_equal(ds.subset([0, 5]).gyro, gyro[[0, 5]])
    plain = write_dataset(tmp_path / "p", (np.zeros((4, 8), np.uint8) for _ in range(2)), np.zeros((2, 3)))
    assert plain.gyro is None and "gyro_heading" not in plain.metadata["units"]


def test_gyro_column_is_validated(tmp_path):
    imgs = [np.zeros((4, 8), np.uint8)] * 3
    with pytest.raises(ValueError, match="gyro must be 3 numbers"):
        write_dataset(tmp_path / "a", iter(imgs), np.zeros((3, 3)), gyro=[0.0, 1.0])
    with pytest.raises(ValueError, match="finite"):
        write_dataset(tmp_path / "b", iter(imgs), np.zeros((3, 3)), gyro=[0.0, np.nan, 1.0])
    with pytest.raises(ValueError, match="not both"):
        write_dataset(tmp_path / "c", iter(imgs), np.zeros((3, 3)), gyro=[0.0] * 3, extra={"gyro_heading": [0] * 3})
    write_dataset(tmp_path / "d", iter(imgs), np.zeros((3, 3)), gyro=[0.0, 0.1, 0.2])
    csv = tmp_path / "d" / "frames.csv"
    lines = csv.read_text().splitlines()
    lines[2] = lines[2].rsplit(",", 1)[0] + ","  # an empty gyro cell
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match="line 3: column 'gyro_heading' is empty"):
        Dataset(tmp_path / "d")
    lines[2] = lines[2] + "inf"
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match="line 3"):
        Dataset(tmp_path / "d")


# ----------------------------------------------------------------- preset


def test_mower_survey_preset(tmp_path):
    p = sim.presets.get("mower-survey")
    world = sim.recording.preset_world("mower-survey", 0)
    runs = {r.name: r.trajectory(world, np.random.default_rng(0)) for r in p.runs(np.random.default_rng(0))}
    assert {"serpentine", "perimeter-serpentine", "spiral", "crossing", "random",
            "serpentine-random-heading"} <= set(runs)
    assert int(runs["serpentine"].extra["lane"].max()) + 1 == 24
    for name in ("serpentine", "perimeter-serpentine", "spiral", "crossing", "random"):
        assert 550 <= len(runs[name]) <= 650, name
        assert np.median(_steps(runs[name])) == pytest.approx(1.2)
    robot = p.robot()
    assert robot.gyro is not None and np.degrees(robot.noise.heading_drift) == pytest.approx(0.1)
    assert robot.noise.distance_fraction == 0.02 and np.degrees(robot.noise.step_heading_sigma) == pytest.approx(0.5)
    ds = sim.simulate("mower-survey", tmp_path / "a", seed=3, max_frames=2, progress=False,
                      camera=sim.PanoramicCamera(24, 4))
    assert ds.gyro is not None and np.isfinite(ds.gyro).all() and len(ds.gyro) == len(ds) == 16
    assert ds.metadata["robot"]["gyro_noise"]["bias"] > 0
    for run in set(ds.runs):  # each run's gyro starts at its true heading
        sub = ds.select(run=run)
        assert sub.gyro[0] == pytest.approx(sub.poses[0, 2])
