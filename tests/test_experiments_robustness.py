"""The robustness experiments of thesis 6.2 as quick smoke runs: each
produces its rows (thesis values beside), its JSON and plots."""

import json
import math

from sfanav import experiments


def _rows(result, out):
    d = json.loads((out / f"{result.experiment}.json").read_text())
    assert d["experiment"] == result.experiment and len(d["rows"]) == len(result.rows)
    names = [r["metric"] for r in result.rows]
    assert len(names) == len(set(names)), "metric names must be unique"
    for r in result.rows:
        if isinstance(r["sfanav"], float):
            assert math.isfinite(r["sfanav"]) or r["metric"].startswith("closures' mean"), r
    for p in result.plots:
        assert __import__("pathlib").Path(p).exists(), p
    return {r["metric"]: r for r in result.rows}


PRODUCT = [f"{m} {c}" for m in ("MED (m)", "MAE x (%)", "MAE y (%)") for c in (
    "thesis configuration", "sfanav default [ground truth]", "sfanav default [ground truth, fused]",
    "sfanav default [no ground truth]", "sfanav default [no ground truth, fused]", "peer perfect memory",
    "peer Fourier signature")] + [
    "MED ratio sfanav default [ground truth] / best peer", "MED ratio sfanav default [no ground truth] / best peer",
    "MED ratio sfanav default [no ground truth, fused] / best peer",
    "MED ratio sfanav default [no ground truth] / [ground truth]"]
"""The product rows beside the thesis configuration and the peers (the scenes have odometry in every run)."""


def _product(rows):
    missing = [m for m in PRODUCT if m not in rows]
    assert not missing, missing
    assert all(isinstance(rows[m]["sfanav"], float) for m in PRODUCT)


def test_registered():
    assert {"6.2.1-static", "6.2.1-light", "6.2.1-gain", "6.2.1-dynamic", "6.2.1-bow", "6.2.2", "6.2.2-seasons"} <= set(
        experiments.names())


def test_621_light_quick(tmp_path):
    res = experiments.run("6.2.1-light", tmp_path, quick=True, progress=False)
    rows = _rows(res, tmp_path)
    assert rows["MED (m) standard [thesis config]"]["thesis"] == 2.4
    assert rows["MED (m) feedback gt [thesis config]"]["thesis"] == 0.46
    assert rows["loop closures (gt)"]["sfanav"] > 0  # the quick run's closures are far apart, but there
    assert "MED (m) perfect memory" in rows and "MED (m) feedback gt [sfanav default]" in rows
    _product(rows)
    assert rows["MED (m) thesis configuration"]["sfanav"] == rows["MED (m) standard [thesis config]"]["sfanav"]


def test_621_bow_and_622_quick(tmp_path):
    rows = _rows(experiments.run("6.2.1-bow", tmp_path, quick=True, progress=False), tmp_path)
    assert rows["average precision at 0.1 m, all candidates (bow)"]["thesis"] == 0.52
    assert "MED (m) feedback bow weighted [thesis config]" in rows
    _product(rows)
    res = experiments.run("6.2.2", tmp_path, quick=True, progress=False)
    rows = _rows(res, tmp_path)
    assert "MED (m), 1 training set [thesis config]" in rows
    assert len(res.details["curves"]["thesis config"][0]) == 3
    held = res.details["curves"]["thesis config, last recording held out"][0]
    assert len(held) == 3 and all(v > 0 for v in held)  # a second curve: every k on the same unseen recording
    assert "MED (m), 3 training sets [thesis config, last recording held out]" in rows
    assert any("6.2.2-trajectory-thesis-config" in p for p in res.plots)  # Fig. 6.18b
    assert "without simulated rotation" in res.notes
    # the product rows on the first permutation's split: no single run's odometry in the joined training set
    for m in ("MED (m) thesis configuration", "MED (m) sfanav default [ground truth]", "MED (m) peer perfect memory",
              "MED (m) peer Fourier signature", "MED ratio sfanav default [ground truth] / best peer"):
        assert math.isfinite(rows[m]["sfanav"]), m
    assert not any("no ground truth" in m or "fused" in m for m in rows)


def test_622_seasons_quick(tmp_path):
    res = experiments.run("6.2.2-seasons", tmp_path, quick=True, progress=False)
    rows = _rows(res, tmp_path)
    assert rows["MED (m), 1 training set [thesis config]"]["thesis"] == 6.13  # the real recordings (Fig. 6.20a)
    assert "over a year" in res.notes
    # the recordings deviate from each other by a few cm: perfect memory is no longer exact
    assert 0.0 < rows["MED (m), 3 training sets [perfect memory, all conditions' views]"]["sfanav"] < 1.0


def test_621_configs_checked(tmp_path):
    import pytest

    from sfanav.experiments.robustness import run_621, run_622

    with pytest.raises(ValueError, match="configs must be"):
        run_621(tmp_path, "light", quick=True, seed=0, progress=False, configs=("no such config",))
    with pytest.raises(ValueError, match="configs must be"):
        run_621(tmp_path, "light", quick=True, seed=0, progress=False, configs=())
    with pytest.raises(ValueError, match="by must be"):
        run_622(tmp_path, quick=True, seed=0, progress=False, by="heading")
