"""``sfanav demo``: the whole pipeline on the built-in simulator.

Generates the ``demo`` garden (8x8 m: a grid exploration run and a test
walk), trains the :data:`DEMO_NETWORK` preset under simulated rotation,
localizes the test walk, evaluates (metrics with both protocols, eta,
error vs n, the two baselines) and writes the dataset, the model, the
estimates, plots and a report. The printed table puts the thesis's section
5.1.1 figures (its simulator experiment) beside the demo's.
"""

from __future__ import annotations

import csv
import json
import shutil
import time
from pathlib import Path
from typing import Any

from .._progress import Log, stderr_log
from ..data.preprocessing import Preprocessing
from ..data.sources import load_run
from ..experiments import ExperimentResult
from ..localization.evaluation import evaluate, evaluation_rows
from ..localization.training import fit_localizer
from ..sfa.network import Network, Rotation

DEMO_NETWORK = "thesis-5.2"
"""Network preset of the demo: Table 5.2, 600x60 RGB, the size the demo garden is rendered at."""


THESIS_5_1_1: dict[str, Any] = {
    "MAE x (%) (random splits)": 1.83,
    "MAE y (%) (random splits)": 1.68,
    "max eta_phi (outputs 1-8)": 0.17,
    "eta_phi s1": 0.00,
    "eta_phi s8": 0.17,
    "min eta_p (outputs 1-8)": 1.0,
    "best n (random splits)": 8,
}
"""The thesis's section 5.1.1 figures (simulator: 30x30 grid, Table 5.1 network), by row name."""


_OUTPUTS = ("dataset", "model.sfa", "test-estimates.csv", "report.md", "demo.json", "firing_maps.png",
            "trajectory.png", "error_vs_n.png", "eta.png")


def _tiny_network() -> Network:
    return Network({
        "input": {"width": 60, "height": 8, "channels": 3},
        "network": {"precision": "mixed"},
        "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 8}, {"rf": "full", "out": 8}],
    })


def run_demo(out: str | Path = "sfanav-demo", *, seed: int = 0, overwrite: bool = False, quick: bool = False,
             progress: bool = True, log: Log = stderr_log) -> ExperimentResult:
    """Runs the demo into ``out`` and returns its table (rows with the
    thesis's 5.1.1 values where it has one). ``quick``: a seconds-long smoke
    run on tiny images with a small network (for tests)."""
    from .. import sim

    t_start = time.perf_counter()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} exists and is not a directory")
    clash = [name for name in _OUTPUTS if (out / name).exists()]
    if clash and not overwrite:
        raise FileExistsError(f"{out} holds an earlier demo ({', '.join(clash[:3])}, ...); pass --overwrite "
                              "or choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    if overwrite and (out / "dataset").exists():
        shutil.rmtree(out / "dataset")
    timings: dict[str, float] = {}

    # 1. simulate
    t0 = time.perf_counter()
    camera = sim.PanoramicCamera(60, 8) if quick else None
    ds = sim.simulate("demo", out / "dataset", seed, max_frames=40 if quick else None, camera=camera,
                      progress=progress)
    timings["simulate"] = time.perf_counter() - t0
    log(f"simulated {len(ds)} images in {timings['simulate']:.1f} s")

    # 2. train
    t0 = time.perf_counter()
    net = _tiny_network() if quick else Network.from_preset(DEMO_NETWORK, precision="mixed")
    prep = Preprocessing.for_network(net)
    train, test = ds.select(run="train"), ds.select(run="test")
    X_train, xy_train = load_run(train, prep, log=log)
    X_test, xy_test = load_run(test, prep, log=log)
    rotation = Rotation(step=5)
    loc = fit_localizer(net, X_train, xy_train, rotation=rotation, n_outputs=8, readout="quadratic", prep=prep,
                        progress=progress,
                        info={"dataset": str(out / "dataset"), "run": "train",
                              "network": "tiny" if quick else DEMO_NETWORK})
    loc.save(out / "model.sfa")
    timings["train"] = time.perf_counter() - t0
    log(f"trained on {len(X_train)} images in {timings['train']:.1f} s (network fit {loc.info['fit_seconds']:.1f} s)")

    # 3. localize the test walk
    t0 = time.perf_counter()
    xy_est = loc.predict(X_test)
    with open(out / "test-estimates.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "x", "y"])
        for fr, (x, y) in zip(test.frames, xy_est):
            w.writerow([int(fr), f"{x:.4f}", f"{y:.4f}"])
    timings["localize"] = time.perf_counter() - t0

    # 4. evaluate, plots, report
    t0 = time.perf_counter()
    ev = evaluate(loc, X_test, xy_test, train_images=X_train, train_xy=xy_train, out=out,
                  title="sfanav demo", log=log, report=False)
    timings["evaluate"] = time.perf_counter() - t0
    rows = evaluation_rows(ev, thesis=THESIS_5_1_1)
    wall = time.perf_counter() - t_start
    rows.append({"metric": "wall time (s)", "thesis": None, "sfanav": round(wall, 1)})
    notes = (
        f"Demo garden (8x8 m, seed {seed}): {len(X_train)} training images (grid run), {len(X_test)} test images "
        f"(random walk), {prep.describe()}; network {'tiny (quick)' if quick else DEMO_NETWORK} in mixed "
        f"precision, rotation step {rotation.step} px, regression on n = 8 outputs.\n"
        "Plain rows: regression fitted on the training run, error on the test walk (honest). '(random "
        "splits)': the thesis 5.1.1 protocol, 50/50 splits of the test walk, 100 repeats (optimistic). The "
        "thesis column is its 5.1.1 simulator experiment (a 30x30 grid, Table 5.1 network), for orientation, "
        "not a like-for-like target.\n"
        f"Wall time {wall:.0f} s: simulate {timings['simulate']:.0f} s, train {timings['train']:.0f} s, "
        f"localize {timings['localize']:.1f} s, evaluate and plots {timings['evaluate']:.0f} s."
    )
    result = ExperimentResult("demo", rows, [str(p) for _, p in ev.plots], notes)
    from ..localization.evaluation import write_evaluation_report

    ev.report = write_evaluation_report(ev, out / "report.md", title="sfanav demo", text=notes.split("\n"))
    result.write_json(out / "demo.json")
    (out / "timings.json").write_text(json.dumps({k: round(v, 2) for k, v in timings.items()} | {"wall": round(wall, 2)}, indent=2) + "\n")
    log(f"wrote {out / 'dataset'}, {out / 'model.sfa'}, {out / 'test-estimates.csv'}, {ev.report} and "
        f"{len(ev.plots)} plots; wall time {wall:.0f} s")
    return result
