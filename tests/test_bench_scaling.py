"""benches/bench_scaling.py --small runs end to end (a smoke test: no timed
assertions) and reports what it promises: per size and approach a query
time and bytes, the accuracy only where the places are rendered views, the
tiled rows marked, perfect memory's bytes linear in the places, sfanav's
bytes split into network and readout, and the crossovers."""

import json
import math

import numpy as np
import pytest

from benchtools import import_bench



@pytest.fixture(scope="module")
def bench():
    bench_scaling = import_bench("bench_scaling")
    return bench_scaling


def test_bench_scaling_small(bench, tmp_path, capsys):
    out, png = tmp_path / "scaling.json", tmp_path / "scaling.png"
    assert bench.main(["--small", "--frames", "150", "--sizes", "100,150,600", "--calls", "3",
                       "--max-pm-bytes", "1", "--data", str(tmp_path / "data"), "--json", str(out),
                       "--plot", str(png)]) == 0
    printed = capsys.readouterr().out
    assert "reaches sfanav's query time" in printed
    assert png.stat().st_size > 1000
    res = json.loads(out.read_text())
    assert res["small"] and res["rendered"] == 150 and res["sizes"] == [100, 150, 600] and res["threads"] == 1
    rows = {(r["places"], r["approach"]): r for r in res["rows"]}
    assert len(rows) == 9
    for (n, name), r in rows.items():
        assert math.isfinite(r["query_ms"]) and r["query_ms"] > 0 and r["bytes"] > 0
        assert r["tiled"] == (n > 150)
        assert (r["MED"] is None) == (n > 150)
    # perfect memory stores every view: bytes exactly linear in the places; above the cache budget extrapolated
    pm = [rows[(n, "perfect memory")] for n in (100, 150, 600)]
    per_place = pm[0]["bytes"] / 100
    assert all(r["bytes"] == per_place * n for r, n in zip(pm, (100, 150, 600)))
    assert per_place == 60 * 8 * 3 + 16
    assert pm[2].get("extrapolated") and not pm[1].get("extrapolated")
    fs = [rows[(n, "Fourier signature")] for n in (100, 150, 600)]
    assert fs[2]["bytes"] == 6 * fs[0]["bytes"]
    # sfanav: model file = network + the rest; the tiled size reuses the model of all rendered views
    s = rows[(150, "sfanav default")]
    assert s["network_bytes"] + s["readout_bytes"] == s["bytes"] and s["network_bytes"] > 0
    assert rows[(600, "sfanav default")]["bytes"] == s["bytes"] and s["trained_views"] == 150
    assert set(res["crossover_places"]) == {"perfect memory", "Fourier signature"}


def test_tiles_perturb_and_shift(bench):
    X = np.full((3, 2, 4, 3), 100, np.uint8)
    xy = np.arange(6, dtype=float).reshape(3, 2)
    im, pos = bench.tiles(X, xy, 7, seed=0, span=10.0)
    assert im.shape == (7, 2, 4, 3) and im.dtype == np.uint8
    assert np.array_equal(im[:3], X)  # tile 0 is the rendered garden
    assert np.abs(im.astype(int) - 100).max() == 1
    assert np.allclose(pos[3:6], xy + [10.0, 0.0]) and np.allclose(pos[6], xy[0] + [20.0, 0.0])
    im2, pos2 = bench.tiles(X, xy, 7, seed=0, span=10.0, start=3, stop=5)
    assert np.allclose(pos2, pos[3:5])


def test_crossover(bench):
    assert bench.crossover([10, 100, 1000], [1.0, 10.0, 100.0], [10.0, 10.0, 10.0]) == pytest.approx(100.0)
    assert bench.crossover([10, 100], [1.0, 100.0], [10.0, 10.0]) == pytest.approx(10 ** 1.5)
    assert bench.crossover([10, 100], [1.0, 2.0], [10.0, 10.0]) is None
    assert bench.crossover([10, 100], [20.0, 30.0], [10.0, 10.0]) == 10.0


def test_extrapolated_query_time_never_falls(bench):
    assert bench.extrapolate_query_ms([(1000, 1.0), (2000, 2.0)], 4000) == pytest.approx(4.0)
    assert bench.extrapolate_query_ms([(100, 1.0), (150, 1.5), (2000, 5.0), (4000, 7.0)], 8000) == pytest.approx(11.0)
    # timing noise: the second size measured faster than the first -> the larger one pro rata, not negative
    assert bench.extrapolate_query_ms([(100, 0.9), (150, 0.5)], 600) == pytest.approx(2.0)
    assert bench.extrapolate_query_ms([(100, 0.5)], 600) == pytest.approx(3.0)


def test_bad_sizes(bench):
    with pytest.raises(SystemExit):
        bench.main(["--small", "--sizes", "a,b"])
    with pytest.raises(SystemExit):
        bench.main(["--small", "--sizes", "1,10"])
