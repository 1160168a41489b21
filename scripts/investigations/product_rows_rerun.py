#!/usr/bin/env python3
"""An experiment's product rows rerun alone, spliced into its committed results JSON (issue 44): when only the
product's recipe changed, the thesis-configuration and feedback rows of a 20-30 min experiment need no rerun.

    sfanav simulate --preset thesis-6.2.1-light --seed 0 --out runs/light       # the experiment's own scene
    PYTHONPATH=python python3 scripts/investigations/product_rows_rerun.py \\
        docs/results/experiments/6.2.1-light.json runs/light OUT.json --why "feedback chosen by the recipe"

Runs :func:`sfanav.experiments.product_rows.scene_rows` on the dataset (what the experiment runs for its product
rows, without the thesis configuration's estimates), replaces every committed row of the same metric with the new
one, keeps the others (the thesis configuration's, the experiment's own variants), adds new product rows, and
prepends a note naming the rerun. OUT may be the committed JSON itself.

5.4 (landmarks) computes its product rows on panoramas it unwarps itself with the dataset's own camera
(sfanav.experiments.landmarks.read_frames at 350x40 over its PANORAMA_ELEVATION): ``--unwarp`` does the same, and
also sets the row 'MED (m) whole image [sfanav default]' (the same training call on the same images) to the product's
ground-truth MED.

    sfanav simulate --preset thesis-5.4-landmarks --seed 0 --out runs/landmarks
    PYTHONPATH=python python3 scripts/investigations/product_rows_rerun.py \\
        docs/results/experiments/5.4.json runs/landmarks OUT.json --unwarp --why "..."
"""

from __future__ import annotations

import argparse
import datetime
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from sfanav import sim
from sfanav.data import Dataset
from sfanav.experiments.landmarks import PANORAMA_ELEVATION
from sfanav.experiments.product_rows import ProductResult, ProductRun, configuration, product_rows, scene_rows


def unwarped_rows(ds: Dataset, seed: int, peer_queries: int, log: Callable[[str], None]) -> ProductResult:
    """5.4's product rows: the omnidirectional frames unwarped with the dataset's camera to the network's input."""
    make_net, recipe = configuration(False)
    h, w, _ = make_net().input_shape
    cam = sim.camera_from_dict(ds.metadata["camera"])

    def run(name: str) -> ProductRun:
        part = ds.select(run=name)
        P = np.concatenate([np.stack([cam.unwarp(img, w, h, PANORAMA_ELEVATION) for img in batch])
                            for batch in part.images(batch_size=32)])
        log(f"{name}: {len(P)} frames unwarped to {P.shape[1:]}")
        return ProductRun(P, part.poses[:, :2].copy(), part.odometry)

    return product_rows(run("train"), [run("test")], network=make_net, recipe=recipe,
                        camera_elevation=PANORAMA_ELEVATION, peer_queries=peer_queries, seed=seed, log=log)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("results", help="the experiment's committed results JSON")
    ap.add_argument("dataset", help="the experiment's dataset (sfanav simulate with its preset and seed)")
    ap.add_argument("out")
    ap.add_argument("--why", required=True, help="what changed in the recipe (goes into the note)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--peer-queries", type=int, default=1000,
                    help="test images the peers answer (the experiment's: 1000, 400 in 5.3.x)")
    ap.add_argument("--also", nargs=2, action="append", default=[], metavar=("RESULTS", "OUT"),
                    help="splice the same product rows into another experiment's results too (5.3.1-real and "
                         "5.3.2 share their scene and product rows)")
    ap.add_argument("--label", default=None, help="the test run's label in the rows (5.2: 'indoor I', 'indoor II')")
    ap.add_argument("--unwarp", action="store_true", help="5.4: omnidirectional frames unwarped as 5.4 does")
    a = ap.parse_args()
    json.loads(Path(a.results).read_text())  # readable before the long run
    t0 = time.perf_counter()
    log = lambda s: print(s, flush=True)  # noqa: E731
    if a.unwarp:
        product = unwarped_rows(Dataset(a.dataset), a.seed, a.peer_queries, log)
        gt = next(r for r in product.rows if r["metric"] == "MED (m) sfanav default [ground truth]")
        product.rows.append({**gt, "metric": "MED (m) whole image [sfanav default]", "thesis": None,
                             "configuration": "sfanav default"})
    else:
        product = scene_rows(Dataset(a.dataset), quick=False, seed=a.seed, peer_queries=a.peer_queries,
                             labels=None if a.label is None else [a.label], log=log)
    secs = time.perf_counter() - t0
    note = (f"Product rows rerun on {datetime.date.today().isoformat()} ({a.why}; "
            f"scripts/investigations/product_rows_rerun.py, {secs:.0f} s): every 'sfanav default' and 'peer' row is "
            "from that rerun, the thesis-configuration rows and the experiment's own variants from the run below.")
    for src, dst in [(a.results, a.out), *a.also]:
        old = json.loads(Path(src).read_text())
        new = {r["metric"]: r for r in product.rows}
        rows = [new.pop(r["metric"], r) for r in old["rows"]]
        rows += list(new.values())
        out = {**old, "rows": rows, "notes": note + "\n" + old.get("notes", "")}
        tmp = Path(dst).with_suffix(".tmp")
        tmp.write_text(json.dumps(out, indent=2) + "\n")
        tmp.replace(dst)
    for r in product.rows:
        if r["metric"].startswith(("MED (m)", "MED ratio", "revisit")):
            print(f"{r['metric']}: {r['sfanav']}")


if __name__ == "__main__":
    main()
