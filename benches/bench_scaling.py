#!/usr/bin/env python3
"""Query time (one image, one thread) and model memory against the number of
stored places: the sfanav default against perfect memory and the Fourier
signature, with the accuracy where the places are real rendered views.

A simulated garden (``thesis-6.2.1-static``: 16x18 m, grid exploration of
~1780 frames, a 1090-frame test walk; 350x40 panoramic camera) is rendered
once. For every size n of ``--sizes``:

* **n <= the rendered frames**: n training frames evenly spaced over the
  whole exploration (the same garden at a lower density). The sfanav
  default (``sfanav.pipeline.train_localizer``), ``PerfectMemory`` and
  ``FourierSignature`` are fitted on them; MED on every ``--test-stride``-th
  test-walk frame.
* **n > the rendered frames** (tiled): perfect memory's and the Fourier
  signature's query cost and memory depend on the number of stored views,
  not on their content. The rendered views are repeated as tiles, each tile
  with a small perturbation (+-1 grey level, seeded) and its positions
  shifted by a multiple of the garden's extent. No accuracy there (the tiles
  repeat the garden). The Fourier signature's tiled signatures are computed
  chunk by chunk (``fourier_signature``) and stored in a model fitted on the
  rendered views (its ``signatures_``/``xy_``), so the tiled images are never
  all in memory. Perfect memory is fitted on the tiled images while its
  spectra stay under ``--max-pm-bytes``; above it its query time is
  extrapolated linearly from the measured sizes >= 1000 (marked
  ``"extrapolated": true``) and its bytes computed. sfanav at tiled sizes is
  the model of the largest rendered size in ``--sizes``: its network has a
  fixed size and its readout keeps at most 3000 training views
  (``SignatureGPReadout``'s ``max_train``), so a larger garden would make it
  bigger only up to that cap (not measured here).

Query time: ``predict`` of one image (the sfanav default pools 8 rotations),
median of ``--calls`` calls after 2 warm-up calls (at most ``--cell-seconds``
per cell, at least 3 calls), with one BLAS/OpenMP thread (threadpoolctl) and
one Rust thread (``sfanav.set_num_threads(1)``). Memory: perfect memory's
stored views plus positions (``bytes_per_place_ * n``) and beside it its FFT
cache; the Fourier signature's signatures; sfanav's model file (``save``),
split into the network (``network.to_bytes()``) and the rest (readout and
its stored training views).

    python3 benches/bench_scaling.py --json docs/results/benchmarks/scaling.json \\
        --plot docs/results/benchmarks/scaling.png          # full: ~15-20 min on 2 cores
    python3 benches/bench_scaling.py --small                  # tiny network, 60x8, sizes 100..1000: seconds

Prints a table and the crossovers (the smallest n at which a peer's query
time or bytes reach sfanav's, log-log interpolated); docs/benchmarks.md.
"""

from __future__ import annotations

import os

if __name__ == "__main__":  # one thread before numpy and the Rust core load
    for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS"):
        os.environ[_v] = "1"

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _benchlib import rendered_garden  # shared with the other benches (benches/ is the script's folder)

APPROACHES = ("sfanav default", "perfect memory", "Fourier signature")


def garden(root: Path, small: bool, seed: int, max_frames: int | None):
    """(train images, train xy, test images, test xy, camera elevations, prep) of the rendered garden."""
    from sfanav.data.sources import load_run

    ds, prep = rendered_garden(root, small, seed, max_frames, max_frames or "all")
    X, xy = load_run(ds.select(run="train"), prep)
    Xt, xyt = load_run(ds.select(run="test"), prep)
    return X, xy, Xt, xyt, tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))


def extrapolate_query_ms(measured: list[tuple[int, float]], n: int) -> float:
    """Perfect memory's query time at ``n`` places from its measured (places, ms): a line through the
    measurements at 1000 places or more (all of them if fewer), or, with one point or when timing noise on a
    shared machine makes the fitted line fall, the largest measurement pro rata (a scan over every stored
    view costs at least that)."""
    pts = [(m, q) for m, q in measured if m >= 1000] or list(measured)
    if len(pts) >= 2:
        slope, icpt = np.polyfit([m for m, _ in pts], [q for _, q in pts], 1)
        if slope > 0:
            return float(icpt + slope * n)
    m_last, q_last = max(pts)
    return float(q_last * n / m_last)


def query_ms(model, Xq: np.ndarray, calls: int, cell_seconds: float) -> float:
    """Median wall time (ms) of ``model.predict`` on one image, cycling through Xq."""
    for i in range(2):
        model.predict(Xq[i % len(Xq)][None])
    ts: list[float] = []
    start = time.perf_counter()
    for i in range(calls):
        t = time.perf_counter()
        model.predict(Xq[i % len(Xq)][None])
        ts.append(time.perf_counter() - t)
        if len(ts) >= 3 and time.perf_counter() - start > cell_seconds:
            break
    return 1e3 * float(np.median(ts))


def tiles(X: np.ndarray, xy: np.ndarray, n: int, seed: int, span: float, start: int = 0, stop: int | None = None):
    """Views start..stop of an n-place tiled map: view k is rendered view k % len(X)
    of tile k // len(X), perturbed by +-1 grey level, its position shifted by tile * span along x."""
    stop = n if stop is None else stop
    k = np.arange(start, stop)
    src, tile = k % len(X), k // len(X)
    imgs = X[src].astype(np.int16)
    rng = np.random.default_rng(seed + start)
    moved = (tile > 0).reshape((-1,) + (1,) * (imgs.ndim - 1))  # tile 0 is the rendered garden itself
    imgs += moved * rng.integers(-1, 2, imgs.shape, dtype=np.int16)
    lo, hi = np.iinfo(X.dtype).min, np.iinfo(X.dtype).max
    pos = xy[src] + np.stack([tile * span, np.zeros(len(k))], axis=1)
    return np.clip(imgs, lo, hi).astype(X.dtype), pos


def model_bytes(loc) -> tuple[int, int]:
    """(model file bytes, network bytes) of a fitted localizer."""
    with tempfile.TemporaryDirectory(prefix="sfanav-bench-") as tmp:
        path = loc.save(Path(tmp) / "model.sfa")
        total = path.stat().st_size
    return int(total), len(loc.network.to_bytes())


def crossover(sizes, peer, ref) -> float | None:
    """Smallest n at which peer(n) >= ref(n), log-log interpolated between sizes; None if never."""
    pts = [(n, p, r) for n, p, r in zip(sizes, peer, ref) if p is not None and r is not None]
    for i, (n, p, r) in enumerate(pts):
        if p >= r:
            if i == 0:
                return float(n)
            n0, p0, r0 = pts[i - 1]
            d0, d1 = np.log(p0 / r0), np.log(p / r)
            f = d0 / (d0 - d1) if d1 != d0 else 1.0
            return float(np.exp(np.log(n0) + f * (np.log(n) - np.log(n0))))
    return None


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for name, colour in zip(APPROACHES, ("C0", "C1", "C2")):
        rows = [r for r in res["rows"] if r["approach"] == name]
        for ax, key in zip(axes, ("query_ms", "bytes")):
            meas = [(r["places"], r[key]) for r in rows if not r.get("extrapolated")]
            ax.plot(*zip(*meas), "o-", color=colour, label=name)
            ext = [(r["places"], r[key]) for r in rows if r.get("extrapolated")]
            if ext:
                ax.plot(*zip(*([meas[-1]] + ext)), "o--", color=colour, mfc="none",
                        label=f"{name} (extrapolated)" if key == "query_ms" else None)
    extra = (("perfect memory", "C1", lambda r: r["bytes"] + r["cache_bytes"], "perfect memory with its FFT cache"),
             ("sfanav default", "C0", lambda r: r["network_bytes"], "sfanav network alone"))
    for name, colour, value, label in extra:
        rows = [r for r in res["rows"] if r["approach"] == name]
        axes[1].plot([r["places"] for r in rows], [value(r) for r in rows], ":", color=colour, label=label)
    axes[1].legend(fontsize=8)
    for ax, label in zip(axes, ("query time, one image, one thread (ms)", "model memory (bytes)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("stored places")
        ax.set_ylabel(label)
        ax.axvline(res["rendered"], color="grey", lw=0.8, ls=":")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{res['image'][0]}x{res['image'][1]} panoramas; right of the dotted line: tiled views")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", default=None,
                   help="comma-separated place counts (default 100,300,1000,3000,10000,30000,100000; --small 100,300,1000)")
    p.add_argument("--small", action="store_true", help="tiny network on 60x8 panoramas, 300 rendered frames: seconds")
    p.add_argument("--frames", type=int, default=None, help="rendered frames per run (default: all; --small 300)")
    p.add_argument("--test-stride", type=int, default=None, help="every k-th test-walk frame (default 4; --small 3)")
    p.add_argument("--calls", type=int, default=30, help="timed single-image queries per cell (default %(default)s)")
    p.add_argument("--cell-seconds", type=float, default=10.0, help="time cap per cell (default %(default)s)")
    p.add_argument("--max-pm-bytes", type=float, default=2.5e9,
                   help="largest perfect-memory FFT cache fitted (default 2.5e9); above it: extrapolated")
    p.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "sfanav-bench-scaling",
                   help="where the simulated garden is kept (default %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--plot", type=Path, default=None, help="write the log-log PNG here")
    a = p.parse_args(argv)
    try:
        sizes = sorted({int(s) for s in (a.sizes or ("100,300,1000" if a.small else
                                                     "100,300,1000,3000,10000,30000,100000")).split(",")})
    except ValueError:
        p.error(f"--sizes must be comma-separated integers, got {a.sizes!r}")
    frames = a.frames or (300 if a.small else None)
    stride = a.test_stride or (3 if a.small else 4)
    if sizes[0] < 2 or min(a.calls, stride, frames or 1) < 1 or a.cell_seconds <= 0:
        p.error("--sizes must be >= 2; --calls, --test-stride, --frames and --cell-seconds positive")

    from threadpoolctl import threadpool_limits

    import sfanav
    from sfanav.experiments.robustness import long_term_configuration
    from sfanav.localization.baselines import FourierSignature, PerfectMemory, fourier_signature
    from sfanav.localization.error_metrics import euclidean_errors
    from sfanav.pipeline import train_localizer

    t_all = time.perf_counter()
    X, xy, Xt, xyt, elev = garden(a.data, a.small, a.seed, frames)
    Xt, xyt = Xt[::stride], xyt[::stride]
    n_real = len(X)
    span = float(np.ptp(xy[:, 0])) + 2.0
    print(f"garden: {n_real} training frames, {len(Xt)} test frames, {X.shape[2]}x{X.shape[1]} "
          f"({time.perf_counter() - t_all:.0f} s to load or render)", flush=True)
    make_net, _, recipe = long_term_configuration("sfanav default", True) if a.small else (None, None, None)

    def train(Xn, yn):
        if a.small:
            return train_localizer(Xn, xy=yn, network=make_net(), recipe=recipe, camera_elevation=elev)
        return train_localizer(Xn, xy=yn, camera_elevation=elev)

    rows: list[dict] = []
    sfa_last: dict | None = None
    pm_measured: list[tuple[int, float]] = []
    pm_cache_per_place = None
    with threadpool_limits(limits=1):
        sfanav.set_num_threads(1)
        try:
            for n in sizes:
                real = n <= n_real
                if real:
                    idx = np.unique(np.linspace(0, n_real - 1, n).round().astype(int))
                    Xn, yn = X[idx], xy[idx]
                    t = time.perf_counter()
                    loc = train(Xn, yn)
                    t_train = time.perf_counter() - t
                    total, net_b = model_bytes(loc)
                    sfa_last = {"query_ms": query_ms(loc, Xt, a.calls, a.cell_seconds), "bytes": total,
                                "network_bytes": net_b, "readout_bytes": total - net_b, "trained_views": len(idx),
                                "MED": float(euclidean_errors(loc.predict(Xt), xyt).mean()), "train_s": t_train}
                    rows.append({"places": n, "approach": "sfanav default", "tiled": False, **sfa_last})
                elif sfa_last is not None:
                    rows.append({"places": n, "approach": "sfanav default", "tiled": True,
                                 **{**sfa_last, "MED": None, "train_s": None}})
                # Fourier signature
                if real:
                    fs = FourierSignature(min(15, X.shape[2] // 2 + 1)).fit(Xn, yn)
                else:
                    fs = FourierSignature(min(15, X.shape[2] // 2 + 1)).fit(X, xy)
                    sigs, pos = [], []
                    for s in range(0, n, 2000):
                        im, ps = tiles(X, xy, n, a.seed, span, s, min(n, s + 2000))
                        sigs.append(fourier_signature(im, fs.n_coefficients).reshape(len(im), *fs.signatures_.shape[1:]))
                        pos.append(ps)
                    fs.signatures_, fs.xy_ = np.concatenate(sigs), np.concatenate(pos)
                    fs.n_places_ = n
                rows.append({"places": n, "approach": "Fourier signature", "tiled": not real,
                             "query_ms": query_ms(fs, Xt, a.calls, a.cell_seconds),
                             "bytes": int(fs.bytes_per_place_) * n,
                             "MED": float(euclidean_errors(fs.predict(Xt), xyt).mean()) if real else None})
                del fs
                # perfect memory
                bpp = int(np.prod(X.shape[1:])) * X.dtype.itemsize + 16
                cache_est = (pm_cache_per_place or 0) * n
                if real or cache_est <= a.max_pm_bytes:
                    if real:
                        Xp, yp = Xn, yn
                    else:  # filled chunk by chunk: no int16 copy of the whole tiled map
                        Xp, yp = np.empty((n,) + X.shape[1:], X.dtype), np.empty((n, 2))
                        for s in range(0, n, 2000):
                            Xp[s:s + 2000], yp[s:s + 2000] = tiles(X, xy, n, a.seed, span, s, min(n, s + 2000))
                    pm = PerfectMemory().fit(Xp, yp)
                    del Xp
                    pm_cache_per_place = pm.cache_bytes_ / n
                    ms = query_ms(pm, Xt, a.calls, a.cell_seconds)
                    pm_measured.append((n, ms))
                    rows.append({"places": n, "approach": "perfect memory", "tiled": not real, "query_ms": ms,
                                 "bytes": int(pm.bytes_per_place_) * n, "cache_bytes": int(pm.cache_bytes_),
                                 "MED": float(euclidean_errors(pm.predict(Xt), xyt).mean()) if real else None})
                    del pm
                else:
                    rows.append({"places": n, "approach": "perfect memory", "tiled": True, "extrapolated": True,
                                 "query_ms": extrapolate_query_ms(pm_measured, n), "bytes": bpp * n,
                                 "cache_bytes": int(cache_est), "MED": None})
                for r in rows[-3:]:
                    med = "" if r.get("MED") is None else f"  MED {r['MED']:.3f} m"
                    print(f"{n:>7} places  {r['approach']:<18} {r['query_ms']:9.3f} ms  {r['bytes'] / 1e6:10.3f} MB"
                          f"{'  (extrapolated)' if r.get('extrapolated') else ''}{'  (tiled)' if r['tiled'] else ''}"
                          f"{med}", flush=True)
        finally:
            sfanav.set_num_threads(0)

    def col(name, key):
        by = {r["places"]: r[key] for r in rows if r["approach"] == name}
        return [by.get(n) for n in sizes]

    cross = {peer: {key: crossover(sizes, col(peer, key), col("sfanav default", key)) for key in ("query_ms", "bytes")}
             for peer in ("perfect memory", "Fourier signature")}
    for peer, c in cross.items():
        print(f"{peer} reaches sfanav's query time at {c['query_ms'] and round(c['query_ms'])} places, "
              f"its bytes at {c['bytes'] and round(c['bytes'])} places")
    res = {"command": "benches/bench_scaling.py " + " ".join(argv if argv is not None else sys.argv[1:]),
           "small": a.small, "image": [int(X.shape[2]), int(X.shape[1])], "channels": int(X.shape[3]) if X.ndim == 4 else 1,
           "rendered": n_real, "test_frames": len(Xt), "sizes": sizes, "cores": os.cpu_count(), "threads": 1,
           "rows": rows, "crossover_places": cross, "wall_s": time.perf_counter() - t_all}
    if a.json:
        from sfanav._files import write_text_atomic

        a.json.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(a.json, json.dumps(res, indent=2) + "\n")
    if a.plot:
        plot(res, a.plot)
    print(f"wall {res['wall_s']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
