#!/usr/bin/env python3
"""The gardens suite in parts: what `sfanav experiment gardens-suite` measures,
run garden by garden (one JSON per garden, written atomically, so two
processes can share the two cores and an interrupted run keeps what it
finished), then merged into the suite's table, ratios and plot.

    PYTHONPATH=python python3 scripts/investigations/gardens_suite_parts.py OUT open-lawn inner ...
    PYTHONPATH=python python3 scripts/investigations/gardens_suite_parts.py OUT --merge

Seeds are the gardens' indices, as in the experiment (``--seed 0``)."""

import json
import sys
import time
from pathlib import Path

import numpy as np

from sfanav._threads import one_blas_thread
from sfanav.experiments import gardens_suite as gs


def run(out: Path, names: list[str]) -> None:
    all_names = gs.gardens()
    (out / "per-garden").mkdir(parents=True, exist_ok=True)
    for g in names:
        t0 = time.time()
        points: dict[str, np.ndarray] = {}
        with one_blas_thread():
            res = gs.run_garden(out, g, all_names.index(g), quick=False, progress=True, points=points)
        tmp = out / "per-garden" / f"{g}.json.tmp"
        tmp.write_text(json.dumps(res, default=float))
        tmp.rename(out / "per-garden" / f"{g}.json")
        np.savez_compressed(out / "per-garden" / f"{g}-points.npz", **points)
        print(f"{g} done in {time.time() - t0:.0f} s", flush=True)


def merge(out: Path) -> None:
    results = {g: json.loads((out / "per-garden" / f"{g}.json").read_text()) for g in gs.gardens()
               if (out / "per-garden" / f"{g}.json").exists()}
    table = {g: gs.ratios(r) for g, r in results.items()}
    md = gs._markdown(results, table)
    lines = [md, ""]
    for m in gs.RATIO_METRICS:
        allv = [v[m] for g in table for v in table[g].values()]
        lines.append(f"ratio default / best peer, {m}: worst {max(allv):.2f}, median {np.median(allv):.2f}")
    per_garden_worst = {g: max(max(c.values()) for c in table[g].values()) for g in table}
    lines.append("worst ratio per garden: " + ", ".join(f"{g} {v:.2f}" for g, v in per_garden_worst.items()))
    t_ratio = {f"{g} {tr}": r["training (s)"]["sfanav default"] / r["training (s)"]["thesis config"]
               for g, res in results.items() for tr, r in res.items()}
    lines.append("training time default / thesis config: worst " + f"{max(t_ratio.values()):.2f}, median "
                 f"{np.median(list(t_ratio.values())):.2f}")
    for part in gs.ABLATIONS + ("sfanav default",):
        v = [res[tr]["methods"][part][te]["MED (m)"] / min(res[tr]["methods"][p][te]["MED (m)"] for p in gs.PEERS)
             for res in results.values() for tr in res for te in gs.TEST_RUNS]
        lines.append(f"MED ratio to the best peer, {part}: worst {max(v):.2f}, median {np.median(v):.2f}")
    text = "\n".join(lines) + "\n"
    (out / "gardens-suite.md").write_text(text)
    (out / "gardens-suite-results.json").write_text(json.dumps({"results": results, "ratios": table}, default=float))
    gs.plot_ratios(table, out / "gardens-suite-ratios.png")
    print(text)


if __name__ == "__main__":
    out = Path(sys.argv[1])
    if sys.argv[2:] == ["--merge"]:
        merge(out)
    else:
        run(out, sys.argv[2:])
