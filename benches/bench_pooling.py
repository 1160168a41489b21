#!/usr/bin/env python3
"""Rotation pooling's query cost, as ratios measured in one run.

The sfanav default's Localizer averages the network's outputs over 8
rotations of each panorama (``rotation_pooling="auto"``). This trains the
``sfanav-default`` network (350x40 RGB) on N synthetic panoramas (the
seeded smooth panoramas of ``bench_network.py``), then times on Q query
images, best of R repeats:

* one transform (no pooling) -- the reference;
* pooled features: ``Network.transform(rotations=True, step=pooling_step)``
  averaged (the Localizer's path; the core shares the lower layers across
  rotations);
* naive pooling: 8 ``np.roll``-ed copies, one transform each;
* the whole ``Localizer.predict`` (GP readout) with and without pooling.

    python3 benches/bench_pooling.py [--n 300] [--queries 400] [--repeats 3]

Prints seconds and the ratios to the reference; quote the ratios.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_network import make_images  # noqa: E402  (seeded synthetic panoramas)


def best(f, repeats: int) -> float:
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    return min(ts)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=300, help="training images (default: %(default)s)")
    p.add_argument("--queries", type=int, default=400, help="query images (default: %(default)s)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--k", type=int, default=8, help="rotations pooled (default: %(default)s, the default's)")
    a = p.parse_args(argv)

    import sfanav
    from sfanav.localization import pooling_step

    X = make_images(0, a.n, 40, 350, 3, seed=7)
    Q = make_images(a.n, a.n + a.queries, 40, 350, 3, seed=7)
    t = np.linspace(0, 1, a.n)
    xy = np.c_[10 * t, 5 * np.sin(6 * t)]  # any smooth path: the readout's cost, not its accuracy, is measured
    net = sfanav.Network.from_preset("sfanav-default").fit(X, sfanav.Rotation(5), progress=False)
    step = pooling_step(net, 350, a.k)
    k_eff = -(-350 // step)
    plain = sfanav.Localizer(net, readout={"kind": "gp", "n_outputs": 12}, rotation_pooling=None).fit(X, xy)
    pooled = sfanav.Localizer(net, readout={"kind": "gp", "n_outputs": 12}, rotation_pooling=a.k).fit(X, xy)
    shifts = [j * step for j in range(k_eff)]

    t_one = best(lambda: net.transform(Q), a.repeats)
    t_pool = best(lambda: net.transform(Q, rotations=True, step=step).mean(axis=1), a.repeats)
    t_naive = best(lambda: np.mean([net.transform(np.roll(Q, -s, axis=2)) for s in shifts], axis=0), a.repeats)
    t_pred = best(lambda: plain.predict(Q), a.repeats)
    t_pred_pool = best(lambda: pooled.predict(Q), a.repeats)
    # the pooled path and the naive one compute the same features
    diff = np.abs(net.transform(Q[:20], rotations=True, step=step).mean(axis=1)
                  - np.mean([net.transform(np.roll(Q[:20], -s, axis=2)) for s in shifts], axis=0)).max()

    print(f"sfanav-default network, {a.n} training / {a.queries} query panoramas 350x40x3, "
          f"K = {k_eff} rotations in steps of {step} px; best of {a.repeats}; "
          f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}")
    rows = [("one transform (reference)", t_one), (f"pooled, {k_eff} rotations (core)", t_pool),
            (f"pooled, {k_eff} rolled copies (naive)", t_naive), ("Localizer.predict, no pooling", t_pred),
            (f"Localizer.predict, {k_eff} rotations pooled", t_pred_pool)]
    for name, v in rows:
        print(f"  {name:<42} {1000 * v / a.queries:8.3f} ms/image   {v / t_one:6.2f}x reference")
    print(f"  naive / core pooled: {t_naive / t_pool:.2f}x; max |core - naive| = {diff:.2e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
