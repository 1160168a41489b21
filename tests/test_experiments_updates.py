"""The online-update experiments (6.2.2-online, 6.2.2-seasons-online) as
quick smoke runs: rows present and finite (or flagged), the first model
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
    assert {"6.2.2-online", "6.2.2-seasons-online"} <= set(experiments.names())


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


def test_622_seasons_online_quick(out):
    res = experiments.run("6.2.2-seasons-online", out, quick=True, progress=False)
    rows = _rows(res, out)
    assert "MED (m) after 3 recordings [updated]" in rows
    # season by season: the batch run trained on the recordings in their numbered order, spring first
    assert res.details["batch"].details["permutations"]["sfanav default"] == [list(range(10))]
    upd = np.asarray(res.details["curves"]["updated"])
    assert upd.shape == (1, 3) and np.isfinite(upd).all()


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
