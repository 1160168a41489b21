#!/usr/bin/env python3
"""Throughput and peak memory of ``sfanav import`` on bags this script writes itself (docs/ros.md): N
panoramas of 600x60 RGB at 10 Hz with odometry at 50 Hz and ground truth at 10 Hz (offset by 13 ms, so both
are interpolated), as a ROS 1 bag of raw rgb8 images and as a ROS 2 MCAP file of JPEG images. The frames are
the demo garden's renders (100 of them, each shifted by a few columns and given sensor noise so that no two
compress alike). Every import runs in its own process (``sfanav import``, as a user runs it) whose peak
resident memory comes from ``os.wait4``; a smaller bag beside the big one shows whether memory grows with
the bag.

    PYTHONPATH=python python3 scripts/investigations/rosbag_import.py --frames 5000
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sfanav import sim
from sfanav.data import BagWriter, Dataset

ap = argparse.ArgumentParser()
ap.add_argument("--frames", type=int, default=5000, help="images in the big bags (default 5000)")
ap.add_argument("--small", type=int, default=1000, help="images in the small bags (default 1000)")
ap.add_argument("--workdir", default=None, help="folder for the bags and datasets (default: a temporary one)")
ap.add_argument("--keep", action="store_true", help="keep the bags and datasets")
a = ap.parse_args()

work = Path(a.workdir or tempfile.mkdtemp(prefix="sfanav-bags-"))
work.mkdir(parents=True, exist_ok=True)
T0 = 1_700_000_000.0  # an epoch time, as a robot's clock gives

print(f"rendering the demo garden's frames (600x60) in {work}", file=sys.stderr)
renders = sim.simulate("demo", work / "sim", 0, max_frames=50, camera=sim.PanoramicCamera(600, 60),
                       progress=False, overwrite=True).load_images()
rng = np.random.default_rng(0)


def frame(i):
    img = np.roll(renders[i % len(renders)], 3 * (i // len(renders)), axis=1).astype(np.int16)
    return np.clip(img + rng.integers(-3, 4, img.shape), 0, 255).astype(np.uint8)


def write_bag(path, n, fmt):
    t = T0 + np.arange(n) / 10.0
    with BagWriter(path, overwrite=True) as bag:
        for i in range(n):
            for k in range(5):  # odometry at 50 Hz
                s = t[i] + k / 50.0
                bag.add_odometry("/odom", s, (0.01 * (s - T0), 0.002 * (s - T0), 0.001 * (s - T0)))
            bag.add_pose("/ground_truth", t[i] + 0.013, (0.01 * (t[i] - T0), 0.0, 0.0))
            bag.add_image("/camera/image_raw" if fmt == "raw" else "/camera/image_raw/compressed", t[i], frame(i),
                          fmt=fmt)
    return path


def size(p):
    p = Path(p)
    return sum(f.stat().st_size for f in p.rglob("*") if f.is_file()) if p.is_dir() else p.stat().st_size


# ``sfanav import`` in a fresh process that reports, on its last stderr line, the time main() took and its
# peak resident memory: VmHWM of /proc/self/status belongs to the process's own address space (getrusage's
# ru_maxrss would also count the forking parent's memory, folded in at exec)
RUNNER = """
import sys, time
from sfanav.app.cli import main
t = time.perf_counter()
code = main(sys.argv[1:])
dt = time.perf_counter() - t
hwm = next(ln.split()[1] for ln in open("/proc/self/status") if ln.startswith("VmHWM:"))
print(f"@@ {dt} {int(hwm) / 1024}", file=sys.stderr)
sys.exit(code)
"""


def run_import(bag, topic, out):
    cmd = [sys.executable, "-c", RUNNER, "import", str(bag), "--image-topic", topic, "--odom-topic", "/odom",
           "--pose-topic", "/ground_truth", "--outside", "drop", "--out", str(out), "--overwrite", "--no-progress"]
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"sfanav {' '.join(cmd[3:])} failed:\n{proc.stderr}")
    _, main_s, rss = proc.stderr.strip().splitlines()[-1].split()
    return wall, float(main_s), float(rss), proc.stdout.strip()


rows = []
for fmt, name, topic in (("raw", "ros1-raw.bag", "/camera/image_raw"),
                         ("jpeg", "ros2-jpeg.mcap", "/camera/image_raw/compressed")):
    for n in (a.small, a.frames):
        bag = work / f"{n}-{name}"
        t = time.perf_counter()
        write_bag(bag, n, fmt)
        print(f"wrote {bag.name} ({size(bag) / 2**20:.0f} MiB) in {time.perf_counter() - t:.0f} s", file=sys.stderr)
        out = work / f"ds-{n}-{fmt}"
        wall, main_s, rss, msg = run_import(bag, topic, out)
        ds = Dataset(out)
        assert len(ds) >= n - 1, msg
        rows.append((name, n, size(bag) / 2**20, len(ds) / main_s, main_s, wall, rss, size(out) / 2**20))
        print(f"  {msg}: {len(ds) / main_s:.0f} frames/s, peak RSS {rss:.0f} MiB", file=sys.stderr)
        shutil.rmtree(out)
        bag.unlink() if bag.is_file() else shutil.rmtree(bag)

print(f"\n{os.cpu_count()} cores, Python {sys.version.split()[0]}\n")
print("| bag | images | bag size (MiB) | import (frames/s) | import (s) | command wall (s) | peak RSS (MiB) "
      "| dataset (MiB) |")
print("|---|---:|---:|---:|---:|---:|---:|---:|")
for name, n, bs, fps, main_s, wall, rss, ds_size in rows:
    print(f"| {name} | {n} | {bs:.0f} | {fps:.0f} | {main_s:.1f} | {wall:.1f} | {rss:.0f} | {ds_size:.0f} |")
if not a.keep and a.workdir is None:
    shutil.rmtree(work)
