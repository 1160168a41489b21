"""benches/bench_updates.py --small runs end to end (a smoke test: no timed
assertions) and reports what it promises: update and retrain seconds, their
ratios, and bounded statistics and model file as runs accumulate."""

import json
import math

import pytest

from benchtools import import_bench



def test_bench_updates_small(tmp_path, capsys):
    bench_updates = import_bench("bench_updates")
    out = tmp_path / "bench.json"
    assert bench_updates.main(["--small", "--runs", "2", "--data", str(tmp_path / "data"), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "network" in printed and "localizer" in printed and "memory as runs accumulate" in printed
    res = json.loads(out.read_text())
    assert res["small"] and res["base"] == 200 and res["run"] == 20
    for v in list(res["seconds"].values()) + list(res["ratios"].values()):
        assert math.isfinite(v) and v >= 0
    steps = res["accumulation"]
    assert [s["images"] for s in steps] == [200, 220, 240]
    # the statistics do not grow with the images; the readout memory stays at its bound
    assert len({s["network_statistics_bytes"] for s in steps}) == 1 and steps[0]["network_statistics_bytes"] > 0
    assert all(s["readout_memory_views"] <= res["memory_views"] for s in steps)
    assert res["ratios"]["model file bytes, last over first"] < 1.01
    with pytest.raises(SystemExit):
        bench_updates.main(["--small", "--run", "-1", "--data", str(tmp_path / "data")])
