"""The product rows of the localization experiments on a tiny simulated
scene: the sfanav default with and without ground truth, fused where the
test run has odometry, beside the thesis configuration and the peers."""

import math

import numpy as np
import pytest

from sfanav import sim
from sfanav.experiments.product_rows import (ProductRun, product_rows, product_runs, quick_network)
from sfanav.localization.recipe import recipe_for


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    ds = sim.simulate("demo", tmp_path_factory.mktemp("scene") / "ds", 0, max_frames=50,
                      camera=sim.PanoramicCamera(60, 8), progress=False)
    return product_runs(ds, quick_network())


def _rows(res):
    names = [r["metric"] for r in res.rows]
    assert len(names) == len(set(names))
    for r in res.rows:
        assert r["thesis"] is None and math.isfinite(r["sfanav"]), r
    return {r["metric"]: r["sfanav"] for r in res.rows}


def test_rows_with_and_without_odometry(runs):
    train, (test,) = runs
    assert train.images.shape[1:] == (8, 60, 3) and train.has_odometry and test.has_odometry
    blind = ProductRun(test.images, test.xy, None, label="no odometry")
    thesis = [test.xy + [0.3, 0.4], blind.xy]
    res = product_rows(train, [test, blind], thesis=thesis, network=quick_network, recipe=recipe_for(rows="all"),
                       peer_queries=20)
    rows = _rows(res)
    assert rows["MED (m) thesis configuration"] == pytest.approx(0.5)  # a constant 0.3, 0.4 m offset
    assert rows["MAE x (%) thesis configuration"] == pytest.approx(100 * 0.3 / np.ptp(test.xy[:, 0]))
    assert rows["MED (m) thesis configuration [no odometry]"] == 0
    for sup in ("ground truth", "no ground truth"):
        for m in ("MED (m)", "MAE x (%)", "MAE y (%)"):
            assert f"{m} sfanav default [{sup}]" in rows and f"{m} sfanav default [{sup}, fused]" in rows
            assert f"{m} sfanav default [{sup}, no odometry]" in rows
            assert f"{m} sfanav default [{sup}, fused, no odometry]" not in rows  # the test run has no odometry
        assert f"MED ratio sfanav default [{sup}] / best peer" in rows
    for peer in ("perfect memory", "Fourier signature"):
        assert f"MED (m) peer {peer}" in rows and f"MED (m) peer {peer} [no odometry]" in rows
    # same images, same models: the blind copy scores as the test run without fusion
    assert rows["MED (m) sfanav default [ground truth, no odometry]"] == rows["MED (m) sfanav default [ground truth]"]
    ratio = rows["MED ratio sfanav default [no ground truth] / [ground truth]"]
    assert ratio == pytest.approx(rows["MED (m) sfanav default [no ground truth]"]
                                  / rows["MED (m) sfanav default [ground truth]"])
    assert set(res.models) == {"ground truth", "no ground truth"}
    t_gt, t_ngt = rows["training (s) sfanav default [ground truth]"], rows["training (s) sfanav default [no ground truth]"]
    assert t_gt > 0 and t_ngt > 0
    assert rows["training time ratio sfanav default [no ground truth] / [ground truth]"] == pytest.approx(t_ngt / t_gt)
    assert res.models["no ground truth"].info["supervision"] == "odometry"
    assert "ekf_noise" in res.models["no ground truth"].info


def test_no_ground_truth_rows_need_the_training_runs_odometry(runs):
    train, (test,) = runs
    res = product_rows(ProductRun(train.images, train.xy), [test], network=quick_network,
                       recipe=recipe_for(rows="all", robustness="none"), peer_queries=10)
    rows = _rows(res)
    assert not any("no ground truth" in k for k in rows)
    assert "MED (m) thesis configuration" not in rows  # none given
    assert "MED (m) sfanav default [ground truth]" in rows
    # no noise without the training run's odometry: nothing to fuse with
    assert not any("fused" in k for k in rows)
    assert set(res.models) == {"ground truth"} and "no '[no ground truth]' rows" in res.note


def test_bad_input(runs):
    train, (test,) = runs
    with pytest.raises(ValueError, match="at least one test run"):
        product_rows(train, [])
    with pytest.raises(ValueError, match="unique"):
        product_rows(train, [test, test])
    with pytest.raises(ValueError, match="shape"):
        product_rows(train, [ProductRun(test.images[:, :, :30], test.xy)])
    with pytest.raises(ValueError, match="one \\(N, 2\\) array"):
        product_rows(train, [test], thesis=[test.xy[:5]])
    with pytest.raises(ValueError, match="odometry must have shape"):
        ProductRun(test.images, test.xy, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="xy"):
        ProductRun(test.images, test.xy[:-1])
    # a run with missing odometry frames has none
    odo = test.odometry.copy()
    odo[3] = np.nan
    assert not ProductRun(test.images, test.xy, odo).has_odometry


def test_odometry_that_fixes_no_map_leaves_out_the_no_ground_truth_rows(runs):
    train, (test,) = runs
    still = np.tile(train.odometry[:1], (len(train.xy), 1))  # the odometry never moves
    res = product_rows(ProductRun(train.images, train.xy, still), [test], network=quick_network,
                       recipe=recipe_for(rows="all", robustness="none", signature=None), peer_queries=10)
    rows = _rows(res)
    assert not any("no ground truth" in k for k in rows) and "fixes no map" in res.note
    assert "MED (m) sfanav default [ground truth]" in rows


def test_a_training_runs_gyro_goes_to_the_pose_graph(runs):
    train, (test,) = runs
    assert train.gyro is None  # the demo garden has no gyro
    heading = np.unwrap(train.odometry[:, 2])  # a gyro that agrees with the wheels
    res = product_rows(ProductRun(train.images, train.xy, train.odometry, gyro=heading), [test],
                       network=quick_network, recipe=recipe_for(rows="all", robustness="none"), peer_queries=10)
    assert res.models["no ground truth"].info["gyro"] is True
    assert "MED (m) sfanav default [no ground truth]" in _rows(res)
    with pytest.raises(ValueError, match="gyro must have"):
        ProductRun(train.images, train.xy, train.odometry, gyro=heading[:-1])
    bad = heading.copy()
    bad[2] = np.nan
    assert ProductRun(train.images, train.xy, train.odometry, gyro=bad).gyro is None  # missing: none
