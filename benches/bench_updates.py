#!/usr/bin/env python3
"""The cost of an online update against a retrain, as ratios measured in one run.

A simulated garden (``thesis-6.2.1-static``'s grid exploration seen by a
350x40 panoramic camera, ground truth) is cut into a base run of
``--base`` frames, then ``--runs`` further runs of ``--run`` frames each.
The sfanav default network (``sfanav.localization.recipe.default_network``,
6.2.2's recipe without robustness: horizon band, signature GP readout,
simulated rotation 5 px) is trained on the base run with a readout memory
of ``--memory-views`` views (``train_localizer(..., readout_memory=N)``).
Then, best of ``--repeats``:

* **network**: ``NetworkUpdater(net).partial_fit(run)`` (top stage
  re-solved) against ``Network.fit(base + run)`` (retrain from scratch);
* **localizer**: ``LocalizerUpdater(loc).partial_fit(run, xy)`` (network
  update + readout refitted on the memory's and the run's views) against
  ``train_localizer(base + run)``.

The run is ``--run / --base`` of the model's data (default 10 %); the
target is update / retrain <= 0.10. Then **memory as runs accumulate**:
the runs added one after the other, after each the network statistics'
bytes, the readout memory's bytes and views, the model file's bytes, and
the process's resident and peak memory (statistics bytes do not grow;
the memory is bounded by ``--memory-views``).

    python3 benches/bench_updates.py                       # 1000 + 4 x 100 frames, 350x40 (~10-15 min)
    python3 benches/bench_updates.py --small               # tiny network, 60x8, 200 + 3 x 20 frames (~20 s)
    python3 benches/bench_updates.py --json out.json

Also the MED on ``--test`` frames of the garden's test walk: the base model, the
update (with its kernel as the default policy decides, and learned again)
and the retrain.

Prints seconds and the ratios; quote the ratios (docs/updates-measured.md).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _benchlib import best, rendered_garden  # shared with the other benches (benches/ is the script's folder)


def rss_mb() -> float:
    """Resident memory of this process now (MB; Linux /proc, else the peak)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        return peak_mb()


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def garden(root: Path, n: int, small: bool, seed: int, n_test: int):
    """The first ``n`` frames of the garden's training run and ``n_test``
    evenly spaced frames of its test walk: (images, xy, test images, test
    xy, camera elevations)."""
    from sfanav.data.sources import load_run

    ds, prep = rendered_garden(root, small, seed, n, n)
    X, xy = load_run(ds.select(run="train"), prep)
    if len(X) < n:
        raise SystemExit(f"the garden's training run has {len(X)} frames, fewer than the {n} asked for")
    T, txy = load_run(ds.select(run="test"), prep)
    k = np.unique(np.linspace(0, len(T) - 1, min(n_test, len(T))).round().astype(int))
    return X[:n], xy[:n], T[k], txy[k], tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))


def med(loc, T, txy) -> float:
    """Median localization error (m) of ``loc`` on the test images."""
    return float(np.median(np.hypot(*(loc.predict(T) - txy).T)))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--base", type=int, default=None, help="frames of the trained model (default 1000; --small 200)")
    p.add_argument("--run", type=int, default=None, help="frames of each added run (default 100; --small 20)")
    p.add_argument("--runs", type=int, default=None, help="runs added one after the other (default 4; --small 3)")
    p.add_argument("--memory-views", type=int, default=None,
                   help="readout memory bound (default 1000; --small 200)")
    p.add_argument("--repeats", type=int, default=1, help="best of R for every timing (default %(default)s)")
    p.add_argument("--small", action="store_true", help="tiny network on 60x8 panoramas: a quick check")
    p.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "sfanav-bench-updates",
                   help="where the simulated garden is kept (default %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--test", type=int, default=None, help="test-walk frames the MEDs are measured on "
                                                            "(default 300; --small 60)")
    p.add_argument("--json", type=Path, default=None, help="also write every number and ratio here")
    a = p.parse_args(argv)
    base = a.base or (200 if a.small else 1000)
    run = a.run or (20 if a.small else 100)
    runs = a.runs or (3 if a.small else 4)
    views = a.memory_views or (200 if a.small else 1000)
    n_test = a.test or (60 if a.small else 300)
    if min(base, run, runs, views, a.repeats) < 1:
        p.error("--base, --run, --runs, --memory-views and --repeats must be positive")

    from sfanav import Rotation
    from sfanav.experiments.robustness import long_term_configuration
    from sfanav.localization.updates import LocalizerUpdater, readout_memory_bytes
    from sfanav.pipeline import train_localizer
    from sfanav.sfa.updates import NetworkUpdater, statistics_bytes

    make_net, _, recipe = long_term_configuration("sfanav default", a.small)
    t0 = time.perf_counter()
    X, xy, T, txy, elev = garden(a.data, base + runs * run, a.small, a.seed, n_test)
    print(f"garden: {len(X)} frames {X.shape[2]}x{X.shape[1]} ({time.perf_counter() - t0:.0f} s to load or simulate); "
          f"base {base}, {runs} runs of {run} ({100 * run / base:.0f} % of the base)", flush=True)
    rot = Rotation(5)

    def train(n: int):
        return train_localizer(X[:n], xy=xy[:n], network=make_net(), recipe=recipe, camera_elevation=elev,
                               rotation=rot, readout_memory=views)

    loc, t_base = best(lambda: train(base), 1)
    print(f"trained on the base run: {t_base:.1f} s", flush=True)
    XB, yB = X[base:base + run], xy[base:base + run]
    net_in = loc.network_input(X[:base + run])
    _, t_upd_net = best(lambda: NetworkUpdater(loc.trained_network()).partial_fit(net_in[base:]), a.repeats)
    _, t_re_net = best(lambda: make_net().fit(net_in, rot, progress=False), a.repeats)
    updated, t_upd_loc = best(lambda: LocalizerUpdater(loc).partial_fit(XB, yB).localizer_, a.repeats)
    relearned, t_upd_learn = best(lambda: LocalizerUpdater(loc, kernel="learn").partial_fit(XB, yB).localizer_,
                                  a.repeats)
    retrained, t_re_loc = best(lambda: train(base + run), a.repeats)
    kernel = updated.info["updates"][-1]["kernel"]
    meds = {"base": med(loc, T, txy), f"update (kernel {kernel})": med(updated, T, txy),
            "update (kernel learned)": med(relearned, T, txy), "retrain": med(retrained, T, txy)}
    res = {"command": "benches/bench_updates.py " + " ".join(argv if argv is not None else sys.argv[1:]),
           "small": a.small, "image": [int(X.shape[2]), int(X.shape[1])], "base": base, "run": run, "runs": runs,
           "memory_views": views, "repeats": a.repeats,
           "seconds": {"train_base": t_base, "update_network": t_upd_net, "retrain_network": t_re_net,
                       "update_localizer": t_upd_loc, "update_localizer_kernel_learned": t_upd_learn,
                       "retrain_localizer": t_re_loc},
           "test_frames": int(len(T)), "med_m": meds,
           "ratios": {"network update over retrain": t_upd_net / t_re_net,
                      "localizer update over retrain": t_upd_loc / t_re_loc,
                      "localizer update, kernel learned over retrain": t_upd_learn / t_re_loc,
                      "MED update over retrain": meds[f"update (kernel {kernel})"] / meds["retrain"],
                      "MED update, kernel learned over retrain": meds["update (kernel learned)"] / meds["retrain"],
                      "readout refit share of the localizer update": max(0.0, t_upd_loc - t_upd_net) / t_upd_loc}}
    print(f"\nupdate with {run} frames against retrain on {base + run} (best of {a.repeats}):")
    print(f"  network   {t_upd_net:8.2f} s / {t_re_net:8.2f} s = {t_upd_net / t_re_net:.3f}  (target <= 0.10)")
    print(f"  localizer {t_upd_loc:8.2f} s / {t_re_loc:8.2f} s = {t_upd_loc / t_re_loc:.3f}  (target <= 0.10; "
          f"kernel {kernel})")
    print(f"  localizer {t_upd_learn:8.2f} s / {t_re_loc:8.2f} s = {t_upd_learn / t_re_loc:.3f}  (kernel learned again)")
    print(f"\nMED on {len(T)} frames of the test walk (m): "
          + ", ".join(f"{k} {v:.3f}" for k, v in meds.items()))

    steps = []
    with tempfile.TemporaryDirectory() as tmp:
        model = Path(tmp) / "model.sfa"
        cur = loc
        for i in range(runs + 1):
            if i:
                s = base + (i - 1) * run
                t = time.perf_counter()
                cur = LocalizerUpdater(cur).partial_fit(X[s:s + run], xy[s:s + run]).localizer_
                dt = time.perf_counter() - t
            else:
                dt = 0.0
            cur.save(model)
            sizes = readout_memory_bytes(cur)
            steps.append({"runs_added": i, "images": base + i * run, "update_seconds": dt,
                          "network_statistics_bytes": int(statistics_bytes(cur.trained_network())),
                          "readout_memory_bytes": int(sizes["readout_memory"]),
                          "readout_memory_views": int(len(cur.readout_memory_)),
                          "model_file_bytes": model.stat().st_size, "rss_mb": rss_mb(), "peak_rss_mb": peak_mb()})
    res["accumulation"] = steps
    s0, sn = steps[0], steps[-1]
    res["ratios"].update({"statistics bytes, last over first": sn["network_statistics_bytes"]
                          / s0["network_statistics_bytes"],
                          "model file bytes, last over first": sn["model_file_bytes"] / s0["model_file_bytes"],
                          "images, last over first": sn["images"] / s0["images"]})
    print(f"\nmemory as runs accumulate (readout memory bound {views} views):")
    print(f"  {'runs':>4} {'images':>6} {'update s':>8} {'stats B':>10} {'memory B':>10} {'views':>5} "
          f"{'file B':>10} {'RSS MB':>7} {'peak MB':>7}")
    for s in steps:
        print(f"  {s['runs_added']:>4} {s['images']:>6} {s['update_seconds']:>8.2f} {s['network_statistics_bytes']:>10} "
              f"{s['readout_memory_bytes']:>10} {s['readout_memory_views']:>5} {s['model_file_bytes']:>10} "
              f"{s['rss_mb']:>7.0f} {s['peak_rss_mb']:>7.0f}")
    print(f"  images x{res['ratios']['images, last over first']:.2f}; statistics bytes "
          f"x{res['ratios']['statistics bytes, last over first']:.3f}; model file "
          f"x{res['ratios']['model file bytes, last over first']:.3f}")
    if a.json is not None:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        tmp = a.json.with_name(a.json.name + ".tmp")
        tmp.write_text(json.dumps(res, indent=1) + "\n")
        os.replace(tmp, a.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
