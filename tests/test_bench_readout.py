"""benches/bench_readout.py --small runs end to end (a smoke test: no timed
assertions) and reports both fits' seconds and their ratio."""

import json
import math

from benchtools import import_bench



def test_bench_readout_small(tmp_path, capsys):
    bench_readout = import_bench("bench_readout")
    out = tmp_path / "bench.json"
    assert bench_readout.main(["--small", "--json", str(out)]) == 0
    assert "ratio" in capsys.readouterr().out
    res = json.loads(out.read_text())
    assert res["small"] and [r["samples"] for r in res["rows"]] == [600, 900]
    for r in res["rows"]:
        assert r["kept"] == 400
        for k in ("seconds DTC", "seconds thinned", "ratio DTC to thinned"):
            assert math.isfinite(r[k]) and r[k] > 0
