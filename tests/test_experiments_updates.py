"""The online-update experiments (6.2.2-online, 6.2.2-seasons-online,
6.2.1-changes-online) as quick smoke runs: rows present and finite (or flagged), the first model
identical to the batch one, the last updated model within a generous
factor of the batch place-major training; bad arguments refused."""

import json
import math

import numpy as np
import pytest

from sfanav import experiments


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    return tmp_path_factory.mktemp("online")  # one simulated dataset per preset for the whole module


def _rows(result, out):
    d = json.loads((out / f"{result.experiment}.json").read_text())
    assert d["experiment"] == result.experiment and len(d["rows"]) == len(result.rows)
    names = [r["metric"] for r in result.rows]
    assert len(names) == len(set(names)), "metric names must be unique"
    for r in result.rows:
        assert set(r) >= {"metric", "thesis", "sfanav"}
        if r["sfanav"] is None:
            assert r.get("flag"), r  # withheld only with a reason
        else:
            assert math.isfinite(r["sfanav"]), r
    for p in result.plots:
        assert __import__("pathlib").Path(p).exists(), p
    return {r["metric"]: r for r in result.rows}


def test_registered():
    assert {"6.2.2-online", "6.2.2-seasons-online", "6.2.1-changes-online"} <= set(experiments.names())


def test_622_online_quick(out):
    res = experiments.run("6.2.2-online", out, quick=True, progress=False)
    rows = _rows(res, out)
    for k, rec in ((1, "1 recording"), (2, "2 recordings"), (3, "3 recordings")):
        for label in ("updated", "batch place-major", "perfect memory"):
            assert f"MED (m) after {rec} [{label}]" in rows
        assert f"MED (m) after {rec}, last recording held out [updated]" in rows
        if k > 1:
            assert rows[f"update time / retrain time after {rec}"]["sfanav"] > 0
    c = res.details["curves"]
    upd, batch = np.asarray(c["updated"]), np.asarray(c["batch place-major"])
    assert upd.shape == batch.shape == (1, 3) and np.isfinite(upd).all() and np.isfinite(batch).all()
    # one recording: the updatable model is 6.2.2's batch model (the readout memory changes nothing)
    np.testing.assert_allclose(upd[:, 0], batch[:, 0], rtol=1e-9)
    # after the last update within a generous factor of the batch place-major training (quick: tiny network)
    assert upd[0, -1] < 10 * batch[0, -1]
    assert 0 < rows["updated / batch MED after 3 recordings"]["sfanav"] < 10
    assert "own run" in res.notes and any(p.endswith("6.2.2-online-error-vs-recordings.png") for p in res.plots)
    # the online peer on the same stream: IncSFA's top stage, the readout chosen again over the recordings
    from sfanav.experiments.updates import LABEL_INCSFA

    inc = np.asarray(c[LABEL_INCSFA])
    assert inc.shape == (1, 3) and np.isfinite(inc).all() and LABEL_INCSFA in res.notes
    assert rows[f"update time / retrain time after 2 recordings [{LABEL_INCSFA}]"]["sfanav"] > 0
    assert f"MED (m) after 3 recordings, last recording held out [{LABEL_INCSFA}]" in rows


def test_622_seasons_online_quick(out):
    res = experiments.run("6.2.2-seasons-online", out, quick=True, progress=False)
    rows = _rows(res, out)
    assert "MED (m) after 3 recordings [updated]" in rows
    # season by season: the batch run trained on the recordings in their numbered order, spring first
    assert res.details["batch"].details["permutations"]["sfanav default"] == [list(range(10))]
    upd = np.asarray(res.details["curves"]["updated"])
    assert upd.shape == (1, 3) and np.isfinite(upd).all()


def test_621_changes_online_quick(out):
    from sfanav.experiments.updates import CHANGES_LABELS, LABEL_INCSFA

    res = experiments.run("6.2.1-changes-online", out, quick=True, progress=False)
    rows = _rows(res, out)
    expected = [f"MED (m) on the test walk [{label}]" for label in CHANGES_LABELS]
    for tag in ("", " [updated, every layer]", f" [{LABEL_INCSFA}]"):
        expected += [f"update time / retrain time{tag}", f"updated / stale MED{tag}", f"updated / retrained MED{tag}"]
    expected += ["stale / retrained MED",
                 f"mean canonical correlation with the exact top stage on A's views [{LABEL_INCSFA}]"]
    assert [r["metric"] for r in res.rows] == expected
    med = res.details["med"]
    assert set(med) == set(CHANGES_LABELS) and all(math.isfinite(v) and v > 0 for v in med.values())
    assert rows["update time / retrain time"]["sfanav"] > 0
    ratio = rows["updated / retrained MED"]["sfanav"]
    assert ratio is None or ratio == pytest.approx(med["updated"] / med["retrained"])
    # the updates made new models: the stale one is the model trained on A
    models = res.details["models"]
    assert models["updated"] is not models["stale"] and models["stale"].readout_memory_ is not None
    assert models["updated"].info["updates"][-1]["n_images"] == len(res.details["dataset"].select(run="B")) // 4
    # perfect memory of A + B stores B's views of the changed garden as well
    assert len(models["perfect memory A + B"].xy_) > len(models["perfect memory A"].xy_)
    assert [r["change"] for r in res.details["changes"]].count("added") == 5
    # the online peer: IncSFA learned A's then B's top-stage sequence, the readout refitted on A's and B's views
    peer, info = models[LABEL_INCSFA], res.details["incsfa"]
    n_b = len(res.details["dataset"].select(run="B")) // 4
    n_views = models["stale"].readout_memory_.n_seen + n_b
    assert peer.n_runs_ == 2 and info["readout_views"] == len(models["updated"].readout_memory_) == n_views
    assert peer.node_.n_components == models["stale"].trained_network().n_outputs_ and info["degree"] == 2
    assert len(info["agreement_a"]) == info["passes"] and all(0 <= a <= 1 for a in info["agreement_a"])
    assert rows[f"update time / retrain time [{LABEL_INCSFA}]"]["sfanav"] > 0 and LABEL_INCSFA in res.notes
    assert "garden-changes" in res.notes and res.plots[0].endswith("6.2.1-changes-online-med.png")


def test_bad_arguments(out):
    from sfanav.experiments.robustness import long_term_configuration, run_622
    from sfanav.experiments.updates import run_online

    with pytest.raises(ValueError, match="preset must be one of"):
        run_online(out, quick=True, seed=0, progress=False, preset="thesis-6.2.1-static")
    with pytest.raises(ValueError, match="orders must be permutations"):
        run_622(out, quick=True, seed=0, progress=False, configs=("sfanav default",), max_sets=2,
                orders=[[0, 0, 1, 2, 3, 4, 5, 6, 7, 8]])
    with pytest.raises(ValueError, match="config must be one of"):
        long_term_configuration("no such config", True)
