#!/usr/bin/env python3
"""Distributed training on Dask: ratios, bytes and driver memory from one run.

Trains one network (default ``thesis-5.2``, 600x60 RGB, step 5) on N seeded
synthetic panoramas (``bench_network.make_images``) written as ``.npy``
shards, one per partition (the workers read them from disk, as on a
cluster with a shared file system), and measures in one run:

* the distributed fit (``sfanav.sfa.distributed.fit``) on a Dask
  ``LocalCluster`` of 1 worker and of 2 workers (processes, 1 Dask thread
  and 1 Rust thread each, started without Dask's MALLOC_TRIM_THRESHOLD_ as
  docs/distributed.md recommends; ``--dask-malloc-default`` also times 1
  worker with it), and their ratio;
* beside them, the single-process ``Network.fit`` on the same images with 1
  Rust thread: the default (field cache up to 1 GB) and ``cache=False``
  (the distributed fit has no field cache: every pass recomputes the lower
  layers);
* per layer and pass: the bytes shipped (the network's checked bytes
  scattered to every worker, and the statistics one partition returns:
  ``len(to_bytes())`` of what the fit ships), the time of the map (the
  partition tasks and the merge tree), of the driver's serial merge and
  solve, and of serializing the network;
* the driver's peak memory: its resident set sampled every 20 ms during
  each distributed fit (the LocalCluster's scheduler runs in the driver
  process) and ``ru_maxrss``;
* the per-image cost per layer: the map seconds of a layer's passes with 1
  worker per image (each pass streams its partition through the solved
  lower layers).

Every time is the best of ``--repeats`` fits (default 1).

With ``--estimate``, it extrapolates the measured per-image cost per layer,
bytes and driver times to a larger run on a cluster (assumptions as
options; docs/distributed.md).

    python3 benches/bench_distributed.py                     # thesis-5.2, 160 images, 4 partitions
    python3 benches/bench_distributed.py --estimate --dask-malloc-default --json out.json
    python3 benches/bench_distributed.py --n 96 --preset sfanav-default --json out.json

Prints seconds and ratios; quote the ratios (the machine is shared and noisy).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import resource
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_network import make_images  # seeded synthetic panoramas

SHAPES = {"thesis-5.1": (40, 350, 3), "thesis-5.2": (60, 600, 3), "thesis-5.3": (40, 409, 1),
          "sfanav-default": (40, 350, 3)}


def rss_bytes() -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


@contextlib.contextmanager
def peak_rss(dt: float = 0.02):
    """Yields a dict whose "start" and "peak" are this process's resident
    set when the block starts and its largest value while the block runs
    (sampled every ``dt`` seconds)."""
    mem = {"start": rss_bytes(), "peak": 0}
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            mem["peak"] = max(mem["peak"], rss_bytes())
            stop.wait(dt)

    t = threading.Thread(target=sample, daemon=True)
    t.start()
    try:
        yield mem
    finally:
        stop.set()
        t.join()
        mem["peak"] = max(mem["peak"], rss_bytes())


def make_shards(folder: Path, n: int, shape: tuple[int, int, int], parts: int, seed: int) -> list[str]:
    """N images as ``parts`` contiguous .npy shards (generated shard by shard)."""
    h, w, c = shape
    edges = [round(i * n / parts) for i in range(parts + 1)]
    paths = []
    for i in range(parts):
        p = folder / f"shard{i:03d}.npy"
        np.save(p, make_images(edges[i], edges[i + 1], h, w, c, seed))
        paths.append(str(p))
    return paths


def network(sfanav, preset: str, precision: str):
    return (sfanav.Network.from_preset(preset) if precision == "preset"
            else sfanav.Network.from_preset(preset, precision=precision))


def distributed_run(sfanav, n_workers: int, paths: list[str], a: argparse.Namespace,
                    malloc_default: bool = False) -> dict:
    import warnings

    import dask
    from distributed import Client, LocalCluster
    from sfanav.sfa.distributed import fit

    # docs/distributed.md: without Dask's MALLOC_TRIM_THRESHOLD_ in the workers, unless asked to keep it
    cfg = {} if malloc_default else {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
    leak = os.environ.get("MALLOC_TRIM_THRESHOLD_")
    with dask.config.set(cfg):
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=50)
    if leak is None:
        os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)  # the nanny sets it in this process too
    client = Client(cluster)
    warnings.filterwarnings("ignore", message="the Dask workers run with MALLOC_TRIM_THRESHOLD_")
    try:
        client.run(sfanav.set_num_threads, 1)  # 1 Rust thread per worker (imports sfanav there too)
        best: tuple[float, list[dict]] | None = None
        with peak_rss() as mem:
            for _ in range(a.repeats):
                passes: list[dict] = []
                t = time.perf_counter()
                fit(network(sfanav, a.preset, a.precision), paths, sfanav.Rotation(a.step), client=client,
                    batch_size=a.batch_size, on_pass=passes.append)
                t = time.perf_counter() - t
                if best is None or t < best[0]:
                    best = (t, passes)
        seconds, passes = best
    finally:
        client.close()
        cluster.close()
    return {"workers": n_workers, "malloc_default": malloc_default, "seconds": seconds, "passes": passes,
            "driver_rss_start": mem["start"],
            "driver_rss_peak": mem["peak"], "driver_maxrss_so_far": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            * 1024}


def single_run(sfanav, paths: list[str], a: argparse.Namespace, cache) -> float:
    images = [np.load(p, mmap_mode="r") for p in paths]
    sfanav.set_num_threads(1)
    out = []
    for _ in range(a.repeats):
        t = time.perf_counter()
        network(sfanav, a.preset, a.precision).fit(images, sfanav.Rotation(a.step), cache=cache,
                                                    batch_size=a.batch_size, progress=False)
        out.append(time.perf_counter() - t)
    sfanav.set_num_threads(0)
    return min(out)


def per_layer(passes: list[dict], n: int) -> list[dict]:
    layers = sorted({p["layer"] for p in passes})
    out = []
    for layer in layers:
        ps = [p for p in passes if p["layer"] == layer]
        out.append({
            "layer": layer + 1,
            "passes": len(ps),
            "ms_per_image": 1e3 * sum(p["map_seconds"] for p in ps) / n,
            "network_MB_per_pass": [p["network_bytes"] / 1e6 for p in ps],
            "statistics_MB_per_partition": [p["statistics_bytes"] / 1e6 for p in ps],
            "driver_solve_s": [p["solve_seconds"] for p in ps],
            "serialize_s": [p["serialize_seconds"] for p in ps],
        })
    return out


def estimate(layers: list[dict], a: argparse.Namespace, workers: int) -> dict:
    """Time to train ``a.target_images`` images on ``workers`` workers of
    ``a.cores`` cores, added up pass by pass, nothing overlapped:

    * compute: one single-threaded partition task per core at a time,
      ``a.partitions_per_core`` equal partitions per core, each image at
      the measured 1-thread cost of its layer and pass (the layer's
      measured cost split evenly over its passes);
    * reading: every pass reads every image (``a.image_bytes``) from a
      shared file system that delivers ``a.storage`` GB/s in all;
    * transfers: the network's bytes to every worker and the statistics
      of every partition, all through one link of ``a.bandwidth`` Gbit/s;
    * the driver: the measured merge, solve and serialization per pass."""
    slots = workers * a.cores
    parts = slots * a.partitions_per_core
    bw = a.bandwidth * 1e9 / 8  # bytes/s
    compute = read = ship = driver = 0.0
    for lay in layers:
        for k in range(lay["passes"]):
            c = lay["ms_per_image"] / 1e3 / lay["passes"]
            compute += -(-parts // slots) * (a.target_images / parts) * c
            read += a.target_images * a.image_bytes / (a.storage * 1e9)
            ship += (workers * lay["network_MB_per_pass"][k] + parts * lay["statistics_MB_per_partition"][k]) * 1e6 / bw
            driver += lay["driver_solve_s"][k] + lay["serialize_s"][k]
    total = compute + read + ship + driver
    return {"workers": workers, "cores_per_worker": a.cores, "partitions": parts, "hours": total / 3600,
            "compute_s": compute, "read_s": read, "transfer_s": ship, "driver_s": driver}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=160, help="training images (default: %(default)s)")
    p.add_argument("--preset", default="thesis-5.2", choices=sorted(SHAPES), help="network (default: %(default)s)")
    p.add_argument("--precision", default="preset", choices=("preset", "double", "mixed"),
                   help="statistics precision (default: the preset's)")
    p.add_argument("--partitions", type=int, default=4, help=".npy shards = partitions (default: %(default)s)")
    p.add_argument("--step", type=int, default=5, help="rotation step, px (default: %(default)s)")
    p.add_argument("--batch-size", type=int, default=16)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--repeats", type=int, default=1, help="best of R for every time (default: %(default)s)")
    p.add_argument("--no-single", action="store_true", help="skip the single-process reference fits")
    p.add_argument("--dask-malloc-default", action="store_true",
                   help="also run 1 worker with Dask's default MALLOC_TRIM_THRESHOLD_=65536 (the ratio it costs)")
    p.add_argument("--estimate", action="store_true", help="extrapolate to --target-images on 8 and 32 workers")
    p.add_argument("--target-images", type=int, default=60000, help="(default: %(default)s: 10 x 6000)")
    p.add_argument("--cores", type=int, default=8, help="cores per worker for --estimate (default: %(default)s)")
    p.add_argument("--partitions-per-core", type=int, default=4, help="for --estimate (default: %(default)s)")
    p.add_argument("--bandwidth", type=float, default=10.0,
                   help="Gbit/s of the driver's link, for --estimate (default: %(default)s)")
    p.add_argument("--storage", type=float, default=1.0,
                   help="GB/s the shared file system delivers in all, for --estimate (default: %(default)s)")
    p.add_argument("--image-bytes", type=int, default=600 * 60 * 3,
                   help="bytes per stored image, for --estimate (default: %(default)s, 600x60 RGB uint8)")
    p.add_argument("--json", metavar="OUT", help="write every number to OUT")
    a = p.parse_args(argv)

    import sfanav

    shape = SHAPES[a.preset]
    print(f"sfanav {sfanav.__version__}, python {platform.python_version()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.2f}")
    print(f"{a.preset} ({shape[1]}x{shape[0]}x{shape[2]}, precision {a.precision}), {a.n} images, step {a.step}, "
          f"{a.partitions} partitions (.npy shards), best of {a.repeats}")
    out: dict = {"args": vars(a)}
    with tempfile.TemporaryDirectory() as tmp:
        paths = make_shards(Path(tmp), a.n, shape, a.partitions, a.seed)
        runs = [distributed_run(sfanav, w, paths, a) for w in (1, 2)]
        single = {}
        if not a.no_single:
            single["default"] = single_run(sfanav, paths, a, "auto")
            single["no cache"] = single_run(sfanav, paths, a, False)
        dask_default = distributed_run(sfanav, 1, paths, a, malloc_default=True) if a.dask_malloc_default else None
    out["distributed"] = runs
    out["dask_malloc_default"] = dask_default
    out["single"] = single
    t1, t2 = runs[0]["seconds"], runs[1]["seconds"]
    print("\ntimes (s)")
    print(f"  distributed, 1 worker   {t1:8.1f}")
    print(f"  distributed, 2 workers  {t2:8.1f}")
    for k, v in single.items():
        print(f"  {'single process, ' + k:23s} {v:8.1f}   (1 thread)")
    print("ratios")
    print(f"  1 worker / 2 workers                  {t1 / t2:6.2f}   (speed-up from the second worker)")
    if dask_default is not None:
        print(f"  1 worker, Dask's MALLOC_TRIM_THRESHOLD_=65536 / 1 worker   {dask_default['seconds'] / t1:6.2f}")
    if single:
        print(f"  1 worker / single process (default)   {t1 / single['default']:6.2f}")
        print(f"  1 worker / single process (no cache)  {t1 / single['no cache']:6.2f}   (Dask and partition overhead)")
        print(f"  2 workers / single process (default)  {t2 / single['default']:6.2f}")
    layers = per_layer(runs[0]["passes"], a.n)
    out["layers"] = layers
    print("\nper layer (1 worker)   ms/image  network MB per pass  statistics MB per partition  driver solve s"
          "   serialize s")
    for lay in layers:
        print(f"  layer {lay['layer']}            {lay['ms_per_image']:8.1f}  "
              f"{' / '.join(f'{x:.2f}' for x in lay['network_MB_per_pass']):>19}  "
              f"{' / '.join(f'{x:.2f}' for x in lay['statistics_MB_per_partition']):>27}  "
              f"{' / '.join(f'{x:.3f}' for x in lay['driver_solve_s']):>14}  "
              f"{' / '.join(f'{x:.3f}' for x in lay['serialize_s'])}")
    shipped = sum(p["network_bytes"] * r["workers"] + p["statistics_bytes"] * a.partitions
                  for r in runs[1:] for p in r["passes"])
    print(f"  bytes shipped by the 2-worker fit (network to each worker + statistics of each partition): "
          f"{shipped / 1e6:.1f} MB over {len(runs[1]['passes'])} passes")
    for r in runs:
        print(f"driver memory, {r['workers']} worker(s): RSS {r['driver_rss_start'] / 1e6:.0f} MB at the start, "
              f"peak {r['driver_rss_peak'] / 1e6:.0f} MB during the fit (+{(r['driver_rss_peak'] - r['driver_rss_start']) / 1e6:.0f} MB);"
              f" ru_maxrss {r['driver_maxrss_so_far'] / 1e6:.0f} MB")
    if a.estimate:
        out["estimate"] = [estimate(layers, a, w) for w in (8, 32)]
        print(f"\nestimate: {a.target_images} images, {a.cores} cores per worker, {a.partitions_per_core} partitions per "
              f"core, {a.bandwidth:g} Gbit/s link, {a.storage:g} GB/s storage, {a.image_bytes} bytes per image, the "
              "1-thread per-image cost measured above")
        for e in out["estimate"]:
            print(f"  {e['workers']:3d} workers: {e['hours'] * 60:6.1f} min  (compute {e['compute_s']:.0f} s, reading "
                  f"{e['read_s']:.0f} s, transfers {e['transfer_s']:.1f} s, driver {e['driver_s']:.1f} s; "
                  f"{e['partitions']} partitions)")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
