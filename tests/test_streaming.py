"""The streaming localizer (sfanav.odometry.streaming): events in any order
within the window, odometry at any rate, one fused pose per image with its
exact stamp, and the batch ``localize --odometry`` being the same object
run over a recording."""

import csv

import numpy as np
import pytest

from sfanav.experiments.synthetic_odometry import make_odometry_run
from sfanav.odometry import OdometryEKF, increments
from sfanav.odometry.recovery import step_anomalies
from sfanav.odometry.streaming import LiveEstimate, StreamingLocalizer

BASE = 1_733_000_000_123_456_789  # ns: beyond float64's exact integers, so a float on the way would show
PERIOD = 100_000_003  # ns between images


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    from clitools import tiny_trained

    t = tiny_trained(tmp_path_factory.mktemp("live"))
    return {**t, "stamps": [BASE + k * PERIOD for k in range(len(t["images"]))]}


def _in_order(tiny, **kw):
    live = StreamingLocalizer(tiny["loc"], **kw)
    out = live.push_images(tiny["stamps"], tiny["images"])
    for t, p in zip(tiny["stamps"], tiny["odometry"]):
        out += live.push_odometry(t, p)
    return out + live.flush(), live


def test_online_filter_steps_are_the_batch_run():
    run = make_odometry_run(n_legs=4, random_state=3)
    Z = run["xy"] + 0.15 * np.random.default_rng(7).normal(size=run["xy"].shape)
    Z[40:46] += 6.0  # a divergence: the filter re-initialises
    Z[::13] = np.nan
    ekf = OdometryEKF(0.02, 0.01, 0.2, gate_probability=0.999, nis_window=6)
    batch = ekf.run(run["odometry"], Z, run["poses"][0])
    scale, jump = step_anomalies(increments(run["odometry"]))
    online = OdometryEKF(0.02, 0.01, 0.2, gate_probability=0.999, nis_window=6).start(run["poses"][0])
    steps = [online.step(p, z, scale=scale[k - 1] if k else 1.0, jump=bool(jump[k - 1]) if k else False)
             for k, (p, z) in enumerate(zip(run["odometry"], Z))]
    np.testing.assert_array_equal(np.array([s.pose for s in steps]), batch)
    np.testing.assert_array_equal(np.array([s.covariance for s in steps]), ekf.covariances_)
    assert [s.reinitialized for s in steps] == ekf.reinitialized_.tolist() and ekf.n_reinitializations_ >= 1
    assert [e for s in steps for e in s.events] == ekf.events_
    with pytest.raises(ValueError, match="start"):
        OdometryEKF().step((0, 0, 0), (0, 0))


def test_batch_localize_is_the_stream_fed_out_of_order(tiny, tmp_path):
    from sfanav.app.cli import main

    out = tmp_path / "e.csv"
    assert main(["localize", str(tiny["model"]), str(tiny["root"] / "data"), "--run", "test", "--odometry",
                 "--out", str(out), "--no-progress"]) == 0
    rows = list(csv.DictReader(open(out)))
    cli = np.array([[float(r[k]) for k in ("x", "y", "fused_x", "fused_y", "fused_heading")] for r in rows])
    ref, _ = _in_order(tiny)
    assert len(ref) == len(rows) == len(tiny["stamps"])
    np.testing.assert_allclose(np.array([np.r_[e.estimate, e.pose] for e in ref]), cli, atol=5.1e-5)

    # live: one image at a time, odometry at three times the image rate, both arriving late by up to 2.5 periods
    rng = np.random.default_rng(0)
    t, P = np.array(tiny["stamps"]), tiny["odometry"]
    events = [(int(s), 1, i) for i, s in enumerate(t)] + [(int(s), 0, P[i]) for i, s in enumerate(t)]
    for i in range(len(t) - 1):
        for f in (1 / 3, 2 / 3):  # between images: the interpolation at an image's stamp stays the image's pose
            dh = np.angle(np.exp(1j * (P[i + 1, 2] - P[i, 2])))
            events.append((int(t[i] + round(f * PERIOD)), 0, np.r_[P[i, :2] + f * (P[i + 1, :2] - P[i, :2]),
                                                                    P[i, 2] + f * dh]))
    window = int(2.5 * PERIOD)
    arrival = [s + int(rng.integers(0, window)) for s, _, _ in events]
    live = StreamingLocalizer(tiny["loc"], window_ns=window)
    got = []
    for j in np.argsort(arrival, kind="stable"):
        s, kind, payload = events[j]
        got += live.push_image(s, tiny["images"][payload]) if kind == 1 else live.push_odometry(s, payload)
    got += live.flush()
    assert not live.dropped_ and live.n_images_ == live.n_emitted_ == len(t)
    assert [e.stamp_ns for e in got] == tiny["stamps"] and all(type(e.stamp_ns) is int for e in got)
    for a, b in zip(got, ref):
        np.testing.assert_allclose(a.odometry, b.odometry, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.estimate, b.estimate, rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.pose, b.pose, rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.covariance, b.covariance, rtol=0, atol=1e-12)


def test_the_start_frames_wait_then_every_image_is_emitted_at_once(tiny):
    live = StreamingLocalizer(tiny["loc"], start_frames=5)
    emitted = []
    for k in range(8):
        live.push_odometry(tiny["stamps"][k], tiny["odometry"][k])
        emitted.append(len(live.push_image(tiny["stamps"][k], tiny["images"][k])))
    assert emitted == [0, 0, 0, 0, 5, 1, 1, 1] and live.initialized_


def test_on_estimate_reports_each_single_image_estimate_at_once(tiny):
    """on_estimate fires when an image's estimate is computed, also for the
    start frames the fused poses wait for, with the values the LiveEstimate
    carries later; a processed stamp pushed again is not reported twice."""
    seen = []
    live = StreamingLocalizer(tiny["loc"], start_frames=5, on_estimate=lambda t, z: seen.append((t, z)))
    out = []
    for k in range(8):
        live.push_odometry(tiny["stamps"][k], tiny["odometry"][k])
        out += live.push_image(tiny["stamps"][k], tiny["images"][k])
        assert [t for t, _ in seen] == tiny["stamps"][: k + 1]  # at once, before the fused pose of the start frames
    out += live.push_image(tiny["stamps"][7], tiny["images"][7])  # a processed stamp again: dropped, not reported
    assert len(seen) == 8 and live.dropped_["duplicate"] + live.dropped_["late"] == 1
    for e, (t, z) in zip(out, seen):
        assert e.stamp_ns == t and np.array_equal(e.estimate, z)
    with pytest.raises(TypeError, match="on_estimate"):
        StreamingLocalizer(tiny["loc"], on_estimate=3)


def test_late_and_duplicate_events_are_dropped_and_counted(tiny):
    s, img, P = tiny["stamps"], tiny["images"], tiny["odometry"]
    live = StreamingLocalizer(tiny["loc"], start_frames=3)
    for k in range(6):
        live.push_odometry(s[k], P[k])
        live.push_image(s[k], img[k])
    assert live.push_image(s[2], img[2]) == [] and live.dropped_["late"] == 1
    assert live.push_odometry(s[1], P[1]) == [] and live.dropped_["late"] == 2
    live.push_image(s[5], img[5])
    live.push_odometry(s[5], P[5])
    assert live.dropped_["duplicate"] == 2 and live.n_emitted_ == 6
    # within the window nothing is late: the events are put back in order
    live = StreamingLocalizer(tiny["loc"], start_frames=3, window_ns=3 * PERIOD)
    out = []
    for k in (1, 0, 3, 2, 5, 4):
        out += live.push_odometry(s[k], P[k]) + live.push_image(s[k], img[k])
    out += live.flush()
    assert not live.dropped_ and [e.stamp_ns for e in out] == s[:6]


def test_odometry_before_and_after_an_image(tiny):
    s, img = tiny["stamps"], tiny["images"]
    live = StreamingLocalizer(tiny["loc"], start_frames=2)
    assert live.push_image(s[0], img[0]) == []  # no odometry yet: it waits
    live.push_odometry(s[1], (0.0, 0.0, np.pi - 0.1))
    assert live.dropped_["before_odometry"] == 1  # the odometry starts after it
    assert live.push_image(s[3], img[3]) == []  # odometry only before it: it waits
    out = live.push_odometry(s[5], (4.0, 2.0, -np.pi + 0.3))  # the heading crosses +-pi: +0.4 rad in 4 periods
    assert out == [] and not live.initialized_  # two images needed for the start pose
    out = live.push_image(s[4], img[4]) + live.flush()
    assert [e.stamp_ns for e in out] == [s[3], s[4]]
    np.testing.assert_allclose(out[0].odometry, [2.0, 1.0, np.pi + 0.1], atol=1e-9)
    np.testing.assert_allclose(out[1].odometry, [3.0, 1.5, np.pi + 0.2], atol=1e-9)
    assert all(isinstance(e, LiveEstimate) and e.pose is not None and e.covariance.shape == (3, 3) for e in out)
    live.push_image(s[9], img[9])  # no odometry after it ever comes
    assert live.flush() == [] and live.dropped_["no_odometry"] == 1


def test_a_stream_that_never_moves_emits_estimates_without_a_fused_pose(tiny):
    live = StreamingLocalizer(tiny["loc"], start_frames=3)
    for k in range(4):
        live.push_odometry(tiny["stamps"][k], (1.0, 2.0, 0.0))
        live.push_image(tiny["stamps"][k], tiny["images"][k])
    out = live.flush()
    assert live.n_emitted_ == 4 and out[-1].pose is None and "do not move" in live.init_error_


def test_bad_input_names_the_stamp(tiny):
    live = StreamingLocalizer(tiny["loc"])
    s, img = tiny["stamps"], tiny["images"]
    live.push_image(s[0], img[0])
    with pytest.raises(ValueError, match=f"image at stamp {s[1]} ns has shape \\(8, 30, 3\\)"):
        live.push_image(s[1], img[1][:, :30])
    with pytest.raises(ValueError, match=f"odometry at stamp {s[2]} ns"):
        live.push_odometry(s[2], (0.0, np.nan, 0.0))
    with pytest.raises(TypeError, match="integer number of nanoseconds"):
        live.push_image(float(s[3]), img[3])
    with pytest.raises(TypeError, match="integer number of nanoseconds"):
        live.push_odometry(True, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="one stamp each"):
        live.push_images(s[:2], img[:3])
    with pytest.raises(ValueError, match="noise must give"):
        StreamingLocalizer(tiny["loc"], {"distance_noise": 0.1})
    with pytest.raises(ValueError, match="window_ns"):
        StreamingLocalizer(tiny["loc"], window_ns=-1)
    live.push_odometry(np.int64(s[0]), (0.0, 0.0, 0.0))  # NumPy integers are stamps too


def test_buffers_stay_bounded(tiny):
    live = StreamingLocalizer(tiny["loc"], max_odometry=50, max_pending=4)
    for k in range(300):  # odometry alone: the kept poses stop at max_odometry
        live.push_odometry(BASE + k, (0.01 * k, 0.0, 0.0))
    assert live.dropped_["odometry_overflow"] == 250
    for k in range(6):  # images after every odometry: they wait, the oldest beyond max_pending dropped
        live.push_image(BASE + 1000 + k, tiny["images"][k])
    assert live.dropped_["no_odometry"] == 2


def test_batch_localize_of_a_run_that_never_moves_is_one_usage_error(tiny, tmp_path, capsys):
    import shutil

    from clitools import assert_one_line_error, run

    ds = tmp_path / "still"
    shutil.copytree(tiny["root"] / "data", ds)
    rows = list(csv.DictReader(open(ds / "frames.csv")))
    for r in rows:
        r["odom_x"], r["odom_y"], r["odom_heading"] = "1.0", "2.0", "0.0"
    with open(ds / "frames.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    code, _, err = run(capsys, "localize", tiny["model"], ds, "--run", "test", "--odometry", "--out",
                       tmp_path / "e.csv", "--no-progress")
    assert_one_line_error(code, err.splitlines()[-1], "no start pose", "do not move")
    assert not (tmp_path / "e.csv").exists()


def test_step_anomalies_against_a_given_nominal_step():
    steps = np.array([[1.0, 0.0], [5.0, 0.0], [30.0, 0.0]])
    scale, jump = step_anomalies(steps, nominal=1.0)
    assert scale.tolist() == [1.0, 5.0, 30.0] and jump.tolist() == [False, False, True]
    scale, jump = step_anomalies(steps)  # the median of these three steps instead: 5 m
    assert scale.tolist() == [1.0, 1.0, 6.0] and jump.tolist() == [False, False, False]
    assert not step_anomalies(steps, nominal=0.0)[1].any()
    with pytest.raises(ValueError, match="nominal"):
        step_anomalies(steps, nominal=-1.0)
