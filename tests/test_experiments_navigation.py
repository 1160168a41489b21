"""The navigation experiments (thesis chapter 7) in their quick smoke
versions: registered, the required rows for both descents, finite values,
plots written, JSON round trip."""

import json
import math

import pytest

from sfanav import experiments

NAMES = ("7.1-open", "7.1-obstacle", "7.2.1", "7.2.2")


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("nav-experiments")
    # 7.2.1 reuses 7.1-open's cached network (same out directory)
    return out, {name: experiments.run(name, out, quick=True, seed=0, progress=False) for name in NAMES}


def test_registered():
    names = experiments.names()
    for name in NAMES:
        assert name in names
        assert experiments.get(name).title


def _rows(result):
    return {r["metric"]: r for r in result.rows}


def _check_values(result):
    rows = _rows(result)
    for metric, r in rows.items():
        v = r["sfanav"]
        assert isinstance(v, float), metric
        if metric.startswith("success") or ": success" in metric:
            assert 0.0 <= v <= 1.0, metric
        elif "efficiency" in metric and "direct path" not in metric:
            # defined over successful runs: NaN only when no run succeeded
            success = metric.replace("efficiency vs any-angle shortest path", "success").replace(
                "time efficiency, optimal / path time", "success").replace("efficiency", "success")
            if success in rows and rows[success]["sfanav"] == 0.0:
                continue
            assert math.isfinite(v) and v > 0, metric
        elif "transition point" in metric:
            assert math.isnan(v) or v >= 0, metric
        else:
            assert math.isfinite(v), metric


@pytest.mark.parametrize("name", ["7.1-open", "7.1-obstacle"])
def test_71_rows_for_both_descents(results, name):
    out, res = results
    r = res[name]
    rows = _rows(r)
    thesis = {"7.1-open": (0.98, 0.94), "7.1-obstacle": (0.88, 0.76)}[name]
    assert rows["success (thesis rule)"]["thesis"] == thesis[0]
    assert rows["efficiency (thesis rule)"]["thesis"] == thesis[1]
    for d in ("thesis rule", "robust descent", "thesis rule, coordinate SFA", "robust descent, coordinate SFA",
              "thesis rule, metric cost", "thesis rule, geodesic metric cost", "metric descent",
              "metric descent + geodesic field", "thesis rule, sfanav default network, n = 2",
              "thesis rule, sfanav default network, n = 8 weighted", "robust descent, sfanav default network, n = 2",
              "robust descent, sfanav default network, n = 8 weighted",
              "thesis rule, graph SFA of the run (ideal slow features, n = 2)",
              "thesis rule, geodesic cost of the run (true positions)",
              "thesis rule, metric cost, tracked positions", "thesis rule, geodesic metric cost, tracked positions",
              "metric descent + geodesic field, no ground truth",
              "robust descent, perfect memory homing (rotational image difference)"):
        assert f"success ({d})" in rows and f"efficiency ({d})" in rows
    assert rows["loop closures kept (no ground truth)"]["sfanav"] >= 0
    assert rows["position code: RMS of x, y from s1-s2 (m)"]["sfanav"] > 0
    assert rows["position code: RMS of x, y from s1-s8 (m), sfanav default network"]["sfanav"] > 0
    if name == "7.1-obstacle":
        assert "efficiency vs any-angle shortest path (robust descent)" in rows
    _check_values(r)
    assert "QUICK" in r.notes and "trials" in r.notes
    assert len(r.plots) == 15 and all((out / p).exists() or __import__("os").path.exists(p) for p in r.plots)
    saved = json.loads((out / f"{name}.json").read_text())
    assert saved["experiment"] == name and len(saved["rows"]) == len(r.rows)
    assert "thesis rule" in r.table() and "robust descent" in r.table()


def test_721_rows_for_every_n_weighting_and_descent(results):
    out, res = results
    r = res["7.2.1"]
    rows = _rows(r)
    for n in range(2, 9):
        for mode in ("raw", "weighted"):
            for d in ("thesis rule", "robust descent", "thesis rule, coordinate SFA", "robust descent, coordinate SFA"):
                assert f"n={n} {mode}: success ({d})" in rows
                assert f"n={n} {mode}: efficiency ({d})" in rows
    assert rows["n=2 raw: success (thesis rule)"]["thesis"] == 0.98
    assert rows["n=8 raw: success (thesis rule)"]["thesis"] == 0.16
    assert rows["n=3 weighted: efficiency (thesis rule)"]["thesis"] == 0.92
    assert rows["n=8 weighted: success (robust descent)"]["thesis"] is None
    _check_values(r)
    assert "beta" in r.notes and len(r.plots) == 4


def test_722_rows(results):
    out, res = results
    r = res["7.2.2"]
    rows = _rows(r)
    for kind in ("halfplane", "disc"):
        for d in ("thesis rule", "robust descent"):
            assert f"{kind}: success ({d})" in rows
            assert f"{kind}: time efficiency, optimal / path time ({d})" in rows
        assert math.isfinite(rows[f"{kind}: time efficiency of the direct path"]["sfanav"])
    assert "halfplane: transition point error m (robust descent)" in rows
    _check_values(r)
    assert len(r.plots) == 8


def test_image_trials_from_the_environment(monkeypatch):
    from sfanav.experiments import navigation_scenes as NS

    monkeypatch.delenv(NS.IMAGE_TRIALS_ENV, raising=False)
    assert NS.image_trials(50) == 50
    monkeypatch.setenv(NS.IMAGE_TRIALS_ENV, "12")
    assert NS.image_trials(50) == 12
    assert NS.image_trials(8) == 8  # never more than the experiment's own count
    for bad in ("0", "-3", "many"):
        monkeypatch.setenv(NS.IMAGE_TRIALS_ENV, bad)
        with pytest.raises(ValueError, match=NS.IMAGE_TRIALS_ENV):
            NS.image_trials(50)


def test_cache_names_follow_the_scene():
    from sfanav.experiments import navigation_scenes as NS

    a, b = NS.scene("open", 0, quick=True), NS.scene("open", 0, quick=True)
    cfg = NS.network_config(True)
    assert NS.cache_name(a, a.name, 0, cfg) == NS.cache_name(b, b.name, 0, cfg)
    patchy = NS.scene("open", 0, quick=True, lawn="patchy")
    assert a.world.ground != patchy.world.ground
    assert NS.cache_name(a, a.name, 0, cfg) != NS.cache_name(patchy, patchy.name, 0, cfg)
    assert NS.cache_name(a, a.name, 0, cfg) != NS.cache_name(a, a.name, 0, {**cfg, "layers": []})
    assert NS.cache_name(a, a.name, 0, cfg).startswith("quick-open-seed0-")


def test_fresh_noise_gives_every_arm_the_same_odometry_noise():
    """Scene.fresh_noise restarts the simulator's odometry noise: the same
    moves after it give the same odometry, whatever ran before."""
    from sfanav.experiments import navigation_scenes as NS

    sc = NS.scene("open", quick=True)

    def drive():
        sim = sc.fresh_noise()
        sim.reset((0.0, 0.0, 0.0))
        for _ in range(5):
            sim.step(0.2, 0.1, 1.0)
        return sim.odometry_pose.copy(), sim.pose.copy()

    (o1, p1), (o2, p2) = drive(), drive()
    assert (o1 == o2).all() and (p1 == p2).all()
    assert abs(o1 - p1).max() > 0  # the odometry is noisy
