#!/usr/bin/env python3
"""Latency and memory of the streaming localizer (``sfanav.odometry.streaming``).

    python benches/bench_live.py MODEL [--images N] [--messages M] [--odometry-rate K]
    python benches/bench_live.py --train DIR [--train-frames F] ...   # makes a default model first

1. Latency: one panorama at a time of a simulated run (the ``demo`` garden
   at the model's image size), each sent as a camera message would arrive:
   JPEG bytes (``--encoding jpeg``, decoded by
   ``sfanav.data.ros_messages.decode_compressed``) or raw RGB bytes
   (``--encoding raw``, ``np.frombuffer``), with K odometry poses per image
   pushed before it. Per image, the time from the message's bytes to the
   fused pose (decode, ``push_image``: preprocessing, network, readout,
   filter step) after the start frames; prints median, p90, p99 and max in ms.
   With ``--pair-camera-gamma``, each image also goes through a second
   localizer with the camera's gamma left in (``camera_gamma=False``; the
   default takes it out, ``sfanav.data.camera_gamma``), the two in
   alternating order, and the ratio of the median latencies is printed: the
   per-image cost of the tracker where the camera is the training run's.
2. Memory: M more images (cycled) with their odometry through the same
   object; the process's resident memory (``/proc/self/statm``) after every
   tenth of them. Prints the growth from the first tenth to the end, MB and
   KB per 1000 images.

The machine and its load matter: quote the numbers with the command, the
core count and what else ran (docs/live.md).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def make_model(root: Path, frames: int) -> Path:
    """A model trained with sfanav's defaults on a simulated demo run (350x40 RGB)."""
    from sfanav import sim
    from sfanav.app.cli import main

    root.mkdir(parents=True, exist_ok=True)
    model = root / "default.sfa"
    if not model.exists():
        sim.simulate("demo", root / "data", seed=1, max_frames=frames, progress=False)
        assert main(["train", "--dataset", str(root / "data"), "--out", str(model), "--no-progress"]) == 0
    return model


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model", nargs="?", help="model file (sfanav train); default: --train")
    ap.add_argument("--train", metavar="DIR", help="simulate and train a default model under DIR (cached)")
    ap.add_argument("--train-frames", type=int, default=200, help="frames of the training run (default 200)")
    ap.add_argument("--images", type=int, default=300, help="images timed for latency (default 300)")
    ap.add_argument("--messages", type=int, default=36000,
                    help="images for the memory phase (default 36000: an hour at 10 Hz)")
    ap.add_argument("--odometry-rate", type=int, default=5, help="odometry poses per image (default 5)")
    ap.add_argument("--encoding", choices=("jpeg", "raw"), default="jpeg")
    ap.add_argument("--json", metavar="OUT", help="also write the numbers as JSON")
    ap.add_argument("--pair-camera-gamma", action="store_true",
                    help="also time every image with the camera's gamma left in, paired (see above)")
    args = ap.parse_args()

    import cv2

    import sfanav
    from sfanav import sim
    from sfanav.data.ros_messages import decode_compressed
    from sfanav.odometry.streaming import StreamingLocalizer

    if args.model is None and args.train is None:
        ap.error("give MODEL or --train DIR")
    model = Path(args.model) if args.model else make_model(Path(args.train), args.train_frames)
    loc = sfanav.load(model)
    from sfanav.data.preprocessing import Preprocessing

    prep = Preprocessing.of_model(loc)
    w, h = prep.width, prep.height
    data = Path(args.train or "/tmp") / f"bench-live-{w}x{h}"
    if not data.exists():
        sim.simulate("demo", data, seed=7, max_frames=max(args.images, 100), camera=sim.PanoramicCamera(w, h),
                      progress=False)
    from sfanav.data.sources import open_images

    src = open_images(data)
    images = np.concatenate(list(src.batches(64)))
    odo = src.odometry
    n = len(images)
    if args.encoding == "jpeg":
        msgs = [cv2.imencode(".jpg", np.ascontiguousarray(im[:, :, ::-1]))[1] for im in images]
        decode = lambda m: decode_compressed(m, "jpeg")  # noqa: E731
    else:
        msgs = [np.ascontiguousarray(im).tobytes() for im in images]
        shape = images.shape[1:]
        decode = lambda m: np.frombuffer(m, np.uint8).reshape(shape)  # noqa: E731
    noise = loc.info.get("ekf_noise") or {"distance_noise": 0.02, "heading_noise": 0.02, "measurement_noise": 0.3,
                                          "turn_noise": 0.1}
    live = StreamingLocalizer(loc, noise)
    plain = StreamingLocalizer(loc, noise, camera_gamma=False) if args.pair_camera_gamma else None
    period, k_odo = 100_000_000, args.odometry_rate
    t_img = 1_700_000_000_000_000_000
    cycle_offset = np.zeros(3)

    def odometry_before(i: int, t: int, to=None) -> None:
        """K poses in the period before image i, interpolated from the run's odometry (cycled)."""
        j = i % n
        prev = odo[j - 1] if j else odo[0]
        for q in range(1, k_odo + 1):
            f = q / k_odo
            p = prev + f * (odo[j] - prev)
            (to or live).push_odometry(t - period + int(f * period), p + cycle_offset)

    def timed(loc_, i: int, t: int) -> tuple[float, int, bool]:
        odometry_before(i, t, loc_)
        t0 = time.perf_counter()
        out = loc_.push_image(t, decode(msgs[i % n]))
        return (time.perf_counter() - t0) * 1e3, len(out), loc_.initialized_ and len(out) == 1

    lat, lat_plain = [], []
    emitted = 0
    for i in range(args.images):
        t = t_img + i * period
        order = [(live, lat), (plain, lat_plain)] if plain is not None else [(live, lat)]
        for loc_, into in (order if i % 2 == 0 else order[::-1]):  # alternating: neither always goes first
            dt, k, ok = timed(loc_, i, t)
            if loc_ is live:
                emitted += k
            if ok:
                into.append(dt)
    lat = np.array(lat)
    res = {"model": str(model), "image": f"{w}x{h}", "encoding": args.encoding, "cores": os.cpu_count(),
           "timed_images": len(lat), "latency_ms": {"median": float(np.median(lat)), "p90": float(np.percentile(lat, 90)),
                                                    "p99": float(np.percentile(lat, 99)), "max": float(lat.max())}}
    print(f"latency, {args.encoding} {w}x{h} message -> fused pose, {len(lat)} images: median "
          f"{res['latency_ms']['median']:.2f} ms, p90 {res['latency_ms']['p90']:.2f}, p99 "
          f"{res['latency_ms']['p99']:.2f}, max {res['latency_ms']['max']:.2f}", flush=True)
    if plain is not None:
        res["latency_ms_camera_gamma_off"] = {"median": float(np.median(lat_plain)),
                                              "p90": float(np.percentile(lat_plain, 90))}
        res["camera_gamma_median_ratio"] = float(np.median(lat) / np.median(lat_plain))
        print(f"the same images with the camera's gamma left in: median {np.median(lat_plain):.2f} ms; the default "
              f"(taken out) costs {res['camera_gamma_median_ratio']:.2f}x (camera factor {live.camera_gamma.factor_:.2f})"
              if live.camera_gamma is not None else "the model holds no camera gamma reference", flush=True)

    M = args.messages
    marks = []
    t_start = time.perf_counter()
    for i in range(args.images, args.images + M):
        t = t_img + i * period
        if i % n == 0:
            cycle_offset = cycle_offset + (odo[-1] - odo[0]) * [1, 1, 0]  # keep the odometry continuous-ish
        odometry_before(i, t)
        emitted += len(live.push_image(t, decode(msgs[i % n])))
        if (i - args.images + 1) % max(1, M // 10) == 0:
            marks.append((i - args.images + 1, rss_mb()))
    wall = time.perf_counter() - t_start
    if marks:
        (n0, r0), (n1, r1) = marks[0], marks[-1]
        growth = r1 - r0
        res["memory"] = {"images": M, "odometry": M * k_odo, "rss_mb": [[a, round(b, 1)] for a, b in marks],
                         "growth_mb": growth, "kb_per_1000_images": 1024 * growth / max(1, n1 - n0) * 1000,
                         "wall_s": wall}
        print(f"memory over {M} images and {M * k_odo} odometry poses ({wall:.0f} s): RSS "
              + " ".join(f"{b:.1f}" for _, b in marks) + f" MB; growth after the first tenth {growth:+.1f} MB "
              f"({res['memory']['kb_per_1000_images']:+.1f} KB per 1000 images)")
    res["emitted"] = emitted
    res["dropped"] = dict(live.dropped_)
    res["reinitializations"] = live.n_reinitializations_
    print(f"emitted {emitted} estimates, dropped {dict(live.dropped_)}, {live.n_reinitializations_} "
          "re-initialisation(s)")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
