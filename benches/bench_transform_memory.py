#!/usr/bin/env python3
"""Peak memory and time of ``Network.transform`` on one large batch.

    python benches/bench_transform_memory.py MODEL N [uint8|float32|float64]

prints one JSON line: the images' size, the peak RSS *above* the RSS just
before the call (the images are already in memory; sampled every 2 ms from
/proc/self/statm while transform runs, Linux only), the time, and a
checksum of the features (equal across builds). MODEL is a saved network
(``Network.save``) whose input the N random images match. To compare two
builds in one run, alternate processes with PYTHONPATH pointing at a copy of
the other build's ``sfanav`` package (docs/benchmarks.md)."""
import json, sys, threading, time
import numpy as np
import sfanav

def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20

model, n = sys.argv[1], int(sys.argv[2])
dtype = sys.argv[3] if len(sys.argv) > 3 else "uint8"
net = sfanav.load(model)
h, w, c = net.input_shape
rng = np.random.default_rng(0)
if dtype == "uint8":
    imgs = rng.integers(0, 256, size=(n, h, w, c), dtype=np.uint8)
else:
    imgs = (rng.random((n, h, w, c), dtype=np.float32) * 255).astype(dtype, copy=False)
net.transform(imgs[:2])  # warm-up
base = rss_mb()
peak = [base]
stop = threading.Event()
def sample():
    while not stop.is_set():
        peak[0] = max(peak[0], rss_mb())
        time.sleep(0.002)
th = threading.Thread(target=sample, daemon=True)
th.start()
t = time.perf_counter()
y = net.transform(imgs)
dt = time.perf_counter() - t
stop.set(); th.join()
print(json.dumps({"core": sfanav._core.__file__, "n": n, "dtype": dtype, "image_mb": round(imgs.nbytes / 2**20, 1),
                  "rss_before_mb": round(base, 1), "peak_extra_mb": round(peak[0] - base, 1),
                  "seconds": round(dt, 3), "ms_per_image": round(1e3 * dt / n, 3),
                  "checksum": float(np.abs(y).sum())}))
