#!/usr/bin/env python3
"""sfanav network benchmark: ratios measured in one run.

1. Training time of ``Network.from_preset("thesis-5.1")`` on 624 images and of
   ``"thesis-5.2"`` on N images (default 1000), fast path, simulated rotation
   with step 5 over the whole panorama. Reported as seconds and ms/image, and
   extrapolated linearly to the issue's setting: 5900 images of 600x60 with 120
   shifts, target < 5 minutes on this 2-core machine.
2. Fast vs naive: the naive path (roll every image by k*step, run the network
   per view) on a small subset; the ratio naive / fast per image is measured
   on the same subset with the same preset.
3. MDP 3.6 hinet: the same network in MDP (switchboards, CloneLayers of
   SFA -> quadratic expansion -> SFA flow nodes), trained by ``Flow.train`` on
   the naively rotated views of the same subset. Ratio MDP / sfanav-fast per
   image; target >= 20x. MDP runs in its own venv (NumPy 1.23), in a
   subprocess with a timeout.
4. Peak resident memory of a fresh subprocess that only does the thesis-5.2
   training on N images (``resource.getrusage``), split into the image array
   and the training's working set, and extrapolated to 5900 images; target
   < 4 GB.
5. Single-image latency: ``set_num_threads(1)``, ``transform`` of one 600x60
   RGB image, median over 50 calls (target < 5 ms); and batch throughput.

Every process generates the same seeded synthetic panoramas itself (nothing
large is passed between processes); a fingerprint of the images is compared
across processes. Quote the printed ratios, not the seconds: the machines are
shared and noisy.

This file is also the worker script: the subprocesses run it with the hidden
``--_worker {train,mdp}`` option. The MDP venv runs it under NumPy 1.23, so it
must stay importable there and must not import sfanav at module level.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _benchlib import (  # noqa: E402  (shared with the other bench script)
    OPENBLAS_OVERRIDES,
    blas_info,
    blas_summary,
    default_mdp_venv,
    delta_mdp_to_sfanav_factor,
    ensure_mdp_venv,
)

# --------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------

DEFAULT_SEED = 20261124
DEFAULT_STEP = 5
DEFAULT_N51 = 624  # thesis Table 5.1 setting (indoor run)
DEFAULT_N52 = 1000
DEFAULT_SUBSET = 8
DEFAULT_SUBSET_PRESET = "thesis-5.2"
QUICK_N51 = 128
QUICK_N52 = 64
QUICK_SUBSET = 6
QUICK_SUBSET_PRESET = "thesis-5.1"
DEFAULT_MDP_TIMEOUT = 1800.0  # seconds
DEFAULT_LATENCY_CALLS = 50
DEFAULT_BATCH = 64  # images per transform call for the throughput figure

# The target setting: 5900 panoramas of 600x60 RGB, 120 shifts (step 5).
TARGET_IMAGES = 5900
TARGET_TRAIN_MIN = 5.0  # minutes, thesis-5.2 at 5900 images, fast path (double precision)
TARGET_MDP_RATIO = 20.0  # MDP / sfanav-fast training time per image
TARGET_PEAK_GB = 4.0  # peak resident set at 5900 images
TARGET_LATENCY_MS = 5.0  # one 600x60 image, one thread

PRESET_SHAPES = {  # (height, width, channels) of the panoramas (window = 100 %)
    "thesis-5.1": (40, 350, 3),
    "thesis-5.2": (60, 600, 3),
    "thesis-5.3": (40, 409, 1),
}


# --------------------------------------------------------------------------
# data (identical in every process for a given seed and shape)
# --------------------------------------------------------------------------


def make_images(start: int, stop: int, h: int, w: int, c: int, seed: int) -> np.ndarray:
    """Synthetic smooth panoramas ``start..stop`` of a seeded run, (n, h, w, c) float32.

    Image i, channel ch: offset + sum over F = 6 low frequencies f = 1..6 (periodic
    in the width, as a panorama is) of ``amp_i[f, ch] * rows[f, ch](y) *
    sin(2 pi f x / w + phase_i[f, ch])`` plus white noise (sigma 0.02). The
    amplitudes (~1/f) and phases drift slowly with the image index (a robot
    moving along a path), and each frequency's amplitude is modulated over the
    rows by a low-frequency sinusoid. Values lie roughly in [-2, 3].

    Every image depends only on (seed, shape, i): any range can be generated
    independently. Uses only default_rng(...).uniform/standard_normal (the same
    stream in NumPy 1.23 and 2.x), sin/cos and einsum, so processes with
    different NumPy versions agree up to rounding.
    """
    n_freq = 6
    g = np.random.default_rng([seed, h, w, c])
    amp0 = g.uniform(0.2, 1.0, (n_freq, c)) / np.arange(1, n_freq + 1)[:, None]
    amp_mod = g.uniform(0.1, 0.5, (n_freq, c))
    amp_period = g.uniform(50.0, 400.0, (n_freq, c))  # images
    amp_phase = g.uniform(0.0, 2.0 * np.pi, (n_freq, c))
    drift = g.uniform(0.1, 1.0, (n_freq, c)) * 2.0 * np.pi / 100.0  # phase drift per image
    phase0 = g.uniform(0.0, 2.0 * np.pi, (n_freq, c))
    row_freq = g.uniform(0.5, 2.0, (n_freq, c))
    row_phase = g.uniform(0.0, 2.0 * np.pi, (n_freq, c))
    row_depth = g.uniform(0.2, 0.8, (n_freq, c))
    offset = g.uniform(0.3, 0.7, c)

    f = np.arange(1, n_freq + 1, dtype=np.float64)
    x = np.arange(w, dtype=np.float64)
    s_fx = np.sin(2.0 * np.pi * np.outer(f, x) / w)  # (F, W)
    c_fx = np.cos(2.0 * np.pi * np.outer(f, x) / w)
    y = np.arange(h, dtype=np.float64)[:, None, None]
    rows = 1.0 + row_depth[None] * np.sin(2.0 * np.pi * row_freq[None] * y / h + row_phase[None])  # (H, F, C)

    out = np.empty((stop - start, h, w, c), dtype=np.float32)
    for j, i in enumerate(range(start, stop)):
        amp = amp0 * (1.0 + amp_mod * np.sin(2.0 * np.pi * i / amp_period + amp_phase))
        ph = phase0 + drift * i
        # img[y, x, c] = sum_f rows[y, f, c] * amp[f, c] * sin(2 pi f x / w + ph[f, c])
        img = np.einsum("yfc,fx->yxc", rows * (amp * np.cos(ph))[None], s_fx)
        img += np.einsum("yfc,fx->yxc", rows * (amp * np.sin(ph))[None], c_fx)
        img += offset
        img += 0.02 * np.random.default_rng([seed, h, w, c, i]).standard_normal((h, w, c))
        out[j] = img
    return out


def fingerprint(x: np.ndarray) -> list[float]:
    x64 = x.astype(np.float64)
    return [float(x64[0].sum()), float(x64.sum()), float(x64[-1].sum())]


def fingerprints_match(a: list[float], b: list[float], rtol: float = 1e-6) -> bool:
    return all(abs(p - q) <= rtol * max(1.0, abs(p), abs(q)) for p, q in zip(a, b))


def preset_shape(preset: str) -> tuple[int, int, int]:
    return PRESET_SHAPES[preset]


def n_views(width: int, step: int) -> int:
    return -(-width // step)


def rss_now_gb() -> float:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1e6  # kB -> GB
    except OSError:
        pass
    return float("nan")


def maxrss_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # kB on Linux


# --------------------------------------------------------------------------
# worker: sfanav thesis-5.2 training in a fresh process (time + peak memory)
# --------------------------------------------------------------------------


def new_network(sfanav, preset: str, precision: str):
    """The preset's network; ``precision`` "preset" keeps the preset file's setting."""
    if precision == "preset":
        return sfanav.Network.from_preset(preset)
    return sfanav.Network.from_preset(preset, precision=precision)


def worker_train(args: argparse.Namespace) -> dict:
    import sfanav  # noqa: PLC0415

    rss_start = rss_now_gb()
    h, w, c = preset_shape(args.preset)
    images = make_images(0, args.n, h, w, c, args.seed)
    rss_data = rss_now_gb()
    net = new_network(sfanav, args.preset, args.precision)
    gc.collect()
    t0 = time.perf_counter()
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    net.fit(images, sfanav.Rotation(step=args.step, window=1.0), fast=True,
            cache=False if args.no_cache else "auto", cache_limit=args.cache_limit,
            batch_size=args.batch_size, progress=False)
    t_fit = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    peak = maxrss_gb()
    if args._model:
        net.save(args._model)
    return {
        "preset": args.preset,
        "n": args.n,
        "threads": sfanav.get_num_threads(),
        "precision": net.config_.get("mixed_precision"),
        "t_fit": t_fit,
        # process CPU seconds of the fit: steadier than wall time on a shared machine
        "cpu_fit": (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime),
        "cache_plan": [list(p) for p in getattr(net, "cache_plan_", [])],
        "rss_start_gb": rss_start,
        "rss_after_data_gb": rss_data,
        "images_gb": images.nbytes / 1e9,
        "peak_rss_gb": peak,
        "fingerprint": fingerprint(images[: min(len(images), 64)]),
        "delta": [float(v) for v in net.delta_values_],
        "describe": net.describe(),
    }


# --------------------------------------------------------------------------
# worker: MDP 3.6 hinet (runs in the MDP venv, NumPy 1.23)
# --------------------------------------------------------------------------


def build_mdp_flow(mdp, geometry: list[dict], rank_deficit_method: str):
    """The sfanav network as an MDP 3.6 hinet flow.

    Per layer: ``Rectangular2dSwitchboard`` over the layer's input map (x = columns,
    y = rows, in_channel_dim = channels: MDP indexes input channel (x, y) as
    ``y * width + x`` times in_channel_dim, i.e. the row-major (H, W, C)
    flattening of an image or of a layer's output map; each field is gathered
    row by row, x inside, channel innermost, the same order as sfanav's RF
    gather), then a ``CloneLayer`` (one shared node, trained on every field's own
    time series) of ``FlowNode(SFANode(output_dim=k) -> QuadraticExpansionNode ->
    SFANode(output_dim=out))``. The CloneLayer's output is the fields' outputs
    in switchboard order (y outer, x inner), i.e. the next map row-major. The top
    layer's field covers the whole map (one node).
    """
    nodes = []
    for g in geometry:
        in_w, in_h, in_c = g["input"]
        sb = mdp.hinet.Rectangular2dSwitchboard(
            in_channels_xy=(in_w, in_h),
            field_channels_xy=tuple(g["rf"]),
            field_spacing_xy=tuple(g["stride"]),
            in_channel_dim=in_c,
            ignore_cover=True,  # sfanav's grid also drops columns/rows that no field covers
        )
        assert tuple(sb.out_channels_xy) == tuple(g["grid"]), (sb.out_channels_xy, g["grid"])
        assert sb.out_channel_dim == g["in_dim"]
        inner = mdp.Flow([
            mdp.nodes.SFANode(input_dim=g["in_dim"], output_dim=g["reduce_to"],
                              rank_deficit_method=rank_deficit_method),
            mdp.nodes.QuadraticExpansionNode(),
            mdp.nodes.SFANode(output_dim=g["n_out"], rank_deficit_method=rank_deficit_method),
        ])
        nodes.append(sb)
        nodes.append(mdp.hinet.CloneLayer(mdp.hinet.FlowNode(inner), n_nodes=sb.output_channels))
    return mdp.Flow(nodes)


def worker_mdp(args: argparse.Namespace) -> dict:
    import mdp  # noqa: PLC0415  (only in the MDP venv)

    geometry = json.loads(Path(args._geom).read_text())
    h, w, c = preset_shape(args.preset)
    images = make_images(0, args.n, h, w, c, args.seed)
    fp = fingerprint(images)
    k_views = n_views(w, args.step)
    dtype = np.dtype(args.mdp_dtype)
    # All views of all images form one training sequence (image after image, view k =
    # the image rolled left by k*step columns), flattened row-major (H, W, C).
    # --mdp-chunk > 0 splits it into chunks of that many images (less memory; MDP's
    # SFANode then loses the derivative pairs across chunk boundaries).
    per = args.mdp_chunk if args.mdp_chunk > 0 else args.n
    chunks = []
    for s in range(0, args.n, per):
        block = np.empty(((min(args.n, s + per) - s) * k_views, h * w * c), dtype=dtype)
        r = 0
        for i in range(s, min(args.n, s + per)):
            for k in range(k_views):
                block[r] = np.roll(images[i], -k * args.step, axis=1).reshape(-1)
                r += 1
        chunks.append(block)
    del images

    progress_path = Path(args._out + ".progress")
    state: dict = {
        "mdp_version": mdp.__version__,
        "numpy_version": np.__version__,
        "blas": blas_info(),
        "fingerprint": fp,
        "n": args.n,
        "n_views": k_views,
        "samples": args.n * k_views,
        "chunks": len(chunks),
        "dtype": str(dtype),
        "attempts": [],
    }

    class TimedFlow(mdp.Flow):
        """mdp.Flow that records how long each node's training (all phases) takes."""

        def _train_node(self, data_iterable, nodenr):
            t0 = time.perf_counter()
            super()._train_node(data_iterable, nodenr)
            att = state["attempts"][-1]
            att["node_times"].append([nodenr, type(self.flow[nodenr]).__name__, time.perf_counter() - t0])
            progress_path.write_text(json.dumps(state))

    methods = ["none", "auto"] if args.mdp_rank_deficit == "retry" else [args.mdp_rank_deficit]
    flow = None
    for method in methods:
        flow = TimedFlow(build_mdp_flow(mdp, geometry, method).flow)
        att = {"rank_deficit_method": method, "node_times": [], "wall_start": time.time()}
        state["attempts"].append(att)
        progress_path.write_text(json.dumps(state))
        t0 = time.perf_counter()
        try:
            flow.train([chunks] * len(flow))
        except Exception as e:  # noqa: BLE001  (MDP raises FlowExceptionCR around NodeException)
            att["t"] = time.perf_counter() - t0
            lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
            where = [ln for ln in lines if ln.startswith("! Exception in node")]
            what = [ln for ln in lines if ln.split(":")[0].rsplit(".", 1)[-1].endswith(("Exception", "Error"))]
            att["error"] = " ".join(where[:1] + what[-1:]) or type(e).__name__
            att["error_full"] = str(e)[-3000:]
            flow = None
            continue
        att["t"] = time.perf_counter() - t0
        break
    state["ok"] = flow is not None
    if flow is not None:
        top = flow[-1].node._flow[-1]  # CloneLayer -> FlowNode -> last SFANode
        state["t_train"] = state["attempts"][-1]["t"]
        state["delta"] = [float(v) for v in top.d]
        state["tlen_top"] = int(top.tlen)
    progress_path.write_text(json.dumps(state))
    return state


# --------------------------------------------------------------------------
# subprocess plumbing
# --------------------------------------------------------------------------


def run_worker(kind: str, python: str, args: argparse.Namespace, extra: list[str], env: dict,
               timeout: float | None = None) -> tuple[dict | None, str | None]:
    """Runs this file as a worker; returns (result, error). On a timeout or a crash
    the last progress record of the worker (if any) is returned with the error."""
    with tempfile.TemporaryDirectory(prefix="sfanav-bench-net-") as tmp:
        out = Path(tmp) / "result.json"
        cmd = [python, os.path.abspath(__file__), "--_worker", kind, "--_out", str(out),
               "--seed", str(args.seed), "--step", str(args.step), *extra]
        if kind == "train":
            cmd += ["--precision", args.precision, "--cache-limit", repr(args.cache_limit)] + (["--no-cache"] if args.no_cache else [])
        err = None
        try:
            proc = subprocess.run(cmd, env=env, timeout=timeout)
            if proc.returncode != 0 or not out.exists():
                err = f"{kind} worker failed (exit {proc.returncode})"
        except subprocess.TimeoutExpired:
            err = f"timeout after {timeout:.0f} s"  # subprocess.run killed the worker
            Path(tmp, "killed_at").write_text(repr(time.time()))
        if err is None:
            return json.loads(out.read_text()), None
        prog = Path(str(out) + ".progress")
        partial = json.loads(prog.read_text()) if prog.exists() else None
        killed = Path(tmp, "killed_at")
        if partial is not None and killed.exists():
            partial["killed_at"] = float(killed.read_text())
        return partial, err


# --------------------------------------------------------------------------
# main
# --------------------------------------------------------------------------


def time_fit(sfanav, preset: str, images: np.ndarray, args: argparse.Namespace, fast: bool,
             repeats: int) -> tuple[float, list[float], object]:
    times, net = [], None
    for _ in range(repeats):
        net = new_network(sfanav, preset, args.precision)
        gc.collect()
        t0 = time.perf_counter()
        net.fit(images, sfanav.Rotation(step=args.step, window=1.0), fast=fast, cache=False if args.no_cache else "auto", cache_limit=args.cache_limit,
                batch_size=args.batch_size, progress=False)
        times.append(time.perf_counter() - t0)
    return min(times), times, net


def main_bench(args: argparse.Namespace) -> int:
    import sfanav  # noqa: PLC0415

    res: dict = {
        "config": {
            "seed": args.seed, "step": args.step, "n51": args.n51, "n52": args.n52,
            "subset": args.subset, "subset_preset": args.subset_preset, "batch_size": args.batch_size,
            "repeats": args.repeats, "quick": args.quick, "mdp_timeout": args.mdp_timeout,
            "mdp_dtype": args.mdp_dtype, "mdp_chunk": args.mdp_chunk, "precision": args.precision,
            "cache": not args.no_cache,
            "python": sys.version.split()[0], "machine": platform.machine(), "cpu_count": os.cpu_count(),
            "sfanav_version": sfanav.__version__, "sfanav_threads": sfanav.get_num_threads(),
            "numpy_version": np.__version__,
            "env": {k: os.environ.get(k) for k in OPENBLAS_OVERRIDES},
        },
        "targets": {
            "train_minutes_at_5900_max": TARGET_TRAIN_MIN, "mdp_ratio_min": TARGET_MDP_RATIO,
            "peak_gb_at_5900_max": TARGET_PEAK_GB, "latency_ms_max": TARGET_LATENCY_MS,
        },
    }
    step = args.step
    print(f"sfanav network benchmark: thesis-5.1 x {args.n51}, thesis-5.2 x {args.n52}, subset "
          f"{args.subset_preset} x {args.subset}, step {step}, seed {args.seed}"
          f"{' (--quick)' if args.quick else ''}", flush=True)
    print(f"sfanav {sfanav.__version__}, {sfanav.get_num_threads()} threads, {os.cpu_count()} cores "
          f"(build with `maturin develop --release` before timing)", flush=True)
    load = os.getloadavg()[0]
    res["config"]["loadavg_1min_start"] = load
    if load > 0.5:
        print(f"warning: 1-min load average is {load:.2f} before the run: other processes are busy; "
              f"on {os.cpu_count()} cores multithreaded BLAS/rayon timings can be off by large factors",
              flush=True)

    # ---- 1a: thesis-5.1 training ------------------------------------------
    if args.n51 > 0:
        h, w, c = preset_shape("thesis-5.1")
        imgs = make_images(0, args.n51, h, w, c, args.seed)
        t51, times51, _ = time_fit(sfanav, "thesis-5.1", imgs, args, True, args.repeats)
        res["train_51"] = {"n": args.n51, "t": t51, "times": times51, "ms_per_image": 1e3 * t51 / args.n51,
                           "views": n_views(w, step)}
        print(f"[5.1] fit {args.n51} images ({n_views(w, step)} views each): {t51:.2f} s, "
              f"{1e3 * t51 / args.n51:.1f} ms/image", flush=True)
        del imgs
        gc.collect()

    # ---- 1b + 4: thesis-5.2 training in a fresh process (time, peak RSS) ----
    tmpdir = tempfile.TemporaryDirectory(prefix="sfanav-bench-net-")
    model_path = os.path.join(tmpdir.name, "thesis-5.2.sfanav")
    if args.n52 > 0:
        print(f"[5.2] fit {args.n52} images in a fresh subprocess (time, peak RSS) ...", flush=True)
        r52, err = run_worker("train", sys.executable, args,
                              ["--preset", "thesis-5.2", "--n", str(args.n52), "--batch-size", str(args.batch_size),
                               "--_model", model_path], dict(os.environ))
        if err is not None:
            print(f"[5.2] failed: {err}", flush=True)
            res["train_52_error"] = err
        else:
            n = r52["n"]
            per_img_gb = r52["images_gb"] / n
            working = r52["peak_rss_gb"] - r52["rss_after_data_gb"]
            r52["ms_per_image"] = 1e3 * r52["t_fit"] / n
            r52["extrapolated_minutes_at_5900"] = r52["t_fit"] / n * TARGET_IMAGES / 60.0
            r52["training_working_set_gb"] = working
            res["train_52"] = r52
            plan = ", ".join(f"layer {l} {'cached' if keep else 'streamed'} ({b / 1e9:.2f} GB)"
                             for l, keep, b in r52.get("cache_plan", []))
            print(f"[5.2] field cache plan (cache=\"auto\", limit {args.cache_limit / 1e9:.2f} GB): {plan}; "
                  f"fit CPU time {1e3 * r52['cpu_fit'] / n:.1f} ms/image", flush=True)
            print(f"[5.2] fit {n} images: {r52['t_fit']:.2f} s, {r52['ms_per_image']:.1f} ms/image "
                  f"({r52['threads']} threads, {'mixed' if r52['precision'] else 'double'} precision, "
                  f"cache {'off' if args.no_cache else 'on'}); peak RSS {r52['peak_rss_gb']:.2f} GB "
                  f"(images {r52['images_gb']:.2f} GB float32, training working set {working:.2f} GB)", flush=True)
            # The working set grows with N (the field cache keeps every image's field of the
            # layer below): a second fresh process with fewer images gives the slope.
            ws_slope = None  # without a second point the memory is not extrapolated
            # (below ~256 images the allocator's noise swamps the slope: no default second point)
            n_small = args.mem_small if args.mem_small is not None else (n // 8 if n >= 256 else 0)
            if 0 < n_small < n:
                rs, err_s = run_worker("train", sys.executable, args,
                                       ["--preset", "thesis-5.2", "--n", str(n_small),
                                        "--batch-size", str(args.batch_size)], dict(os.environ))
                if err_s is None:
                    ws_small = rs["peak_rss_gb"] - rs["rss_after_data_gb"]
                    ws_slope = max(0.0, (working - ws_small) / (n - n_small))
                    r52["mem_small"] = {"n": n_small, "training_working_set_gb": ws_small,
                                        "peak_rss_gb": rs["peak_rss_gb"], "t_fit": rs["t_fit"]}
                    t_slope = (r52["t_fit"] - rs["t_fit"]) / (n - n_small)
                    r52["extrapolated_minutes_at_5900_two_point"] = (
                        r52["t_fit"] + t_slope * (TARGET_IMAGES - n)) / 60.0
                    print(f"[5.2] fit {n_small} images (second point): working set {ws_small:.2f} GB -> "
                          f"{1e6 * ws_slope:.0f} KB per image; time {rs['t_fit']:.1f} s -> two-point extrapolation "
                          f"{r52['extrapolated_minutes_at_5900_two_point']:.1f} min at {TARGET_IMAGES}", flush=True)
            r52["working_set_gb_per_image"] = ws_slope
            plan = r52.get("cache_plan") or []
            if plan and not args.no_cache:
                # cache="auto": the cached fields are the part of the working set that grows with N,
                # up to the budget per layer; the rest (node statistics, batches) does not. At 5900
                # images, keep the layers whose fields still fit the budget (as Network.fit decides).
                cached_now = sum(b for _, keep, b in plan if keep) / 1e9
                fixed = max(0.0, working - cached_now)
                cached_5900 = sum(b / n * TARGET_IMAGES for _, _, b in plan
                                  if b / n * TARGET_IMAGES <= args.cache_limit) / 1e9
                base = r52["rss_after_data_gb"] - r52["images_gb"] + fixed + cached_5900
                r52["extrapolated_peak_gb_at_5900_f32"] = base + per_img_gb * TARGET_IMAGES
                r52["extrapolated_peak_gb_at_5900_u8"] = base + per_img_gb / 4 * TARGET_IMAGES
                r52["extrapolation"] = "cache plan"
                if ws_slope is None:
                    r52["working_set_gb_per_image"] = ws_slope = 0.0
            elif ws_slope is not None:
                # at 5900 images: same baseline, working set grown by the slope, images as float32 (or uint8)
                base = r52["peak_rss_gb"] - r52["images_gb"] + ws_slope * (TARGET_IMAGES - n)
                r52["extrapolated_peak_gb_at_5900_f32"] = base + per_img_gb * TARGET_IMAGES
                r52["extrapolated_peak_gb_at_5900_u8"] = base + per_img_gb / 4 * TARGET_IMAGES

    # ---- 2: fast vs naive on a subset --------------------------------------
    sp = args.subset_preset
    h, w, c = preset_shape(sp)
    sub = make_images(0, args.subset, h, w, c, args.seed)
    fp_sub = fingerprint(sub)
    t_fast, times_fast, net_fast = time_fit(sfanav, sp, sub, args, True, max(3, args.repeats))
    res["subset_fast"] = {"preset": sp, "n": args.subset, "t": t_fast, "times": times_fast,
                          "ms_per_image": 1e3 * t_fast / args.subset, "fingerprint": fp_sub,
                          "delta": [float(v) for v in net_fast.delta_values_]}
    print(f"[subset] {sp} x {args.subset} images, fast: {t_fast:.2f} s "
          f"({1e3 * t_fast / args.subset:.1f} ms/image, best of {len(times_fast)})", flush=True)
    if not args.no_naive:
        t_naive, _, net_naive = time_fit(sfanav, sp, sub, args, False, 1)
        d_f = np.asarray(net_fast.delta_values_)
        d_n = np.asarray(net_naive.delta_values_)
        res["subset_naive"] = {"t": t_naive, "ms_per_image": 1e3 * t_naive / args.subset,
                               "delta_max_reldiff_vs_fast": float(np.max(np.abs(d_f - d_n) / np.abs(d_n)))}
        res["naive_over_fast"] = t_naive / t_fast
        print(f"[subset] naive: {t_naive:.2f} s -> naive/fast {t_naive / t_fast:.1f}x "
              f"(top Delta max rel diff fast vs naive {res['subset_naive']['delta_max_reldiff_vs_fast']:.1e})",
              flush=True)
    net_geom = [dict(g) for g in net_fast._net.geometry()]
    for g in net_geom:
        for key in ("input", "rf", "stride", "grid"):
            g[key] = list(g[key])
    del sub
    gc.collect()

    # ---- 3: MDP 3.6 hinet on the same subset --------------------------------
    mdp_res = None
    if args.no_mdp:
        res["mdp_skipped"] = "--no-mdp"
        print("[mdp] skipped (--no-mdp)")
    else:
        py = ensure_mdp_venv(Path(args.mdp_venv).expanduser(), args.mdp_base_python)
        if py is None:
            res["mdp_skipped"] = "venv creation failed"
        else:
            geom_path = os.path.join(tmpdir.name, "geometry.json")
            Path(geom_path).write_text(json.dumps(net_geom))
            k_views = n_views(w, step)
            gb = args.subset * k_views * h * w * c * np.dtype(args.mdp_dtype).itemsize / 1e9
            print(f"[mdp] hinet Flow.train on {sp} x {args.subset} images x {k_views} views "
                  f"({gb:.2f} GB of views, {args.mdp_dtype}; timeout {args.mdp_timeout:.0f} s) ...", flush=True)
            mdp_res, err = run_worker(
                "mdp", str(py), args,
                ["--preset", sp, "--n", str(args.subset), "--_geom", geom_path, "--mdp-dtype", args.mdp_dtype,
                 "--mdp-chunk", str(args.mdp_chunk), "--mdp-rank-deficit", args.mdp_rank_deficit],
                dict(os.environ), timeout=args.mdp_timeout)
            if mdp_res is not None:
                res["mdp"] = mdp_res
                print(f"[mdp] mdp {mdp_res['mdp_version']}, numpy {mdp_res['numpy_version']}, "
                      f"BLAS: {blas_summary(mdp_res['blas'])}", flush=True)
                if not fingerprints_match(fp_sub, mdp_res["fingerprint"]):
                    print(f"warning: image fingerprint differs from the MDP worker: {fp_sub} vs {mdp_res['fingerprint']}")
                for att in mdp_res["attempts"]:
                    layers = [f"L{(nt[0] + 1) // 2}:{nt[2]:.1f}s" for nt in att["node_times"] if nt[1] == "CloneLayer"]
                    status = (f"failed after {att['t']:.1f} s: {att['error'][:300]}" if "error" in att
                              else (f"{att['t']:.1f} s" if "t" in att else "unfinished"))
                    print(f"[mdp] rank_deficit_method={att['rank_deficit_method']!r}: {status}; per layer "
                          f"{' '.join(layers) or '-'}", flush=True)
            if err is not None:
                res["mdp_error"] = err
                print(f"[mdp] {err}", flush=True)
                # lower bound: the time MDP spent in Flow.train (all attempts) before it was killed
                if err.startswith("timeout") and mdp_res is not None and mdp_res.get("attempts"):
                    spent = sum(a["t"] for a in mdp_res["attempts"][:-1] if "t" in a)
                    spent += mdp_res.get("killed_at", time.time()) - mdp_res["attempts"][-1]["wall_start"]
                    res["mdp_train_seconds_before_timeout"] = spent
                    res["mdp_over_fast_lower_bound"] = spent / t_fast
                    print(f"[mdp] {spent:.1f} s in Flow.train before the timeout -> MDP/sfanav-fast >= "
                          f"{spent / t_fast:.1f}x (raise --mdp-timeout or lower --subset for the full ratio)", flush=True)
            elif mdp_res is not None and mdp_res.get("ok"):
                res["mdp_over_fast"] = mdp_res["t_train"] / t_fast
                res["mdp_ms_per_image"] = 1e3 * mdp_res["t_train"] / args.subset
                d_m = np.sort(np.asarray(mdp_res["delta"])) * delta_mdp_to_sfanav_factor(mdp_res["tlen_top"])
                d_s = np.sort(np.asarray(res["subset_fast"]["delta"]))
                m_ = min(len(d_m), len(d_s))
                res["mdp_delta_max_reldiff"] = float(np.max(np.abs(d_s[:m_] - d_m[:m_]) / np.abs(d_m[:m_])))
                print(f"[mdp] Flow.train {mdp_res['t_train']:.1f} s ({res['mdp_ms_per_image']:.0f} ms/image) -> "
                      f"MDP/sfanav-fast {res['mdp_over_fast']:.1f}x; top-node Delta max rel diff "
                      f"{res['mdp_delta_max_reldiff']:.1e}", flush=True)
            elif mdp_res is not None:
                res["mdp_error"] = "every rank_deficit_method failed"

    # ---- 5: latency and throughput (thesis-5.2 network) ---------------------
    if args.n52 > 0 and os.path.exists(model_path):
        net = sfanav.load(model_path)
        h, w, c = preset_shape("thesis-5.2")
        imgs = make_images(10_000, 10_000 + max(args.batch, 8), h, w, c, args.seed)
        one = imgs[0]
        lat = {}
        try:
            sfanav.set_num_threads(1)
            for _ in range(5):
                net.transform(one)
            ts = []
            for _ in range(args.latency_calls):
                t0 = time.perf_counter()
                y = net.transform(one)
                ts.append(time.perf_counter() - t0)
            assert y.shape == (net.n_outputs_,)
            lat["single_median_ms"] = 1e3 * statistics.median(ts)
            lat["single_min_ms"] = 1e3 * min(ts)
            lat["calls"] = args.latency_calls
            t0 = time.perf_counter()
            net.transform(imgs[: args.batch])
            lat["batch_1thread_img_per_s"] = args.batch / (time.perf_counter() - t0)
        finally:
            sfanav.set_num_threads(0)
        threads = sfanav.get_num_threads()
        net.transform(imgs[:2])
        t0 = time.perf_counter()
        net.transform(imgs[: args.batch])
        lat["batch_img_per_s"] = args.batch / (time.perf_counter() - t0)
        lat["batch"] = args.batch
        lat["threads"] = threads
        t0 = time.perf_counter()
        yr = net.transform(imgs[:8], rotations=True)
        dt = time.perf_counter() - t0
        lat["rotations_img_per_s"] = 8 / dt
        lat["rotations_views"] = int(yr.shape[1])
        res["latency"] = lat
        print(f"[latency] 1 thread, one 600x60 image -> {net.n_outputs_}: median {lat['single_median_ms']:.2f} ms "
              f"over {args.latency_calls} calls; batch of {args.batch}: {lat['batch_1thread_img_per_s']:.0f} img/s "
              f"(1 thread), {lat['batch_img_per_s']:.0f} img/s ({threads} threads); all {yr.shape[1]} rotations: "
              f"{lat['rotations_img_per_s']:.1f} img/s", flush=True)
    tmpdir.cleanup()
    res["config"]["loadavg_1min_end"] = os.getloadavg()[0]

    # ---- summary ------------------------------------------------------------
    def status(val, target, higher_is_better=True):
        if val is None:
            return ""
        return "ok" if (val >= target if higher_is_better else val <= target) else "MISS"

    rows = []
    if "train_51" in res:
        r = res["train_51"]
        rows.append((f"thesis-5.1 fit, {r['n']} img x {r['views']} views", f"{r['t']:.1f} s", f"{r['ms_per_image']:.1f} ms/img", ""))
    if "train_52" in res:
        r = res["train_52"]
        rows.append((f"thesis-5.2 fit, {r['n']} img x {n_views(600, step)} views", f"{r['t_fit']:.1f} s",
                     f"{r['ms_per_image']:.1f} ms/img", ""))
        e = r["extrapolated_minutes_at_5900"]
        e2 = r.get("extrapolated_minutes_at_5900_two_point")
        rows.append((f"  -> {TARGET_IMAGES} images (t/N; target < {TARGET_TRAIN_MIN:g} min)", f"{e:.1f} min",
                     "" if e2 is None else f"2-point: {e2:.1f} min", status(e, TARGET_TRAIN_MIN, False)))
        slope = r["working_set_gb_per_image"]
        rows.append((f"peak RSS, 5.2 fit of {r['n']} img (fresh process)", f"{r['peak_rss_gb']:.2f} GB",
                     f"ws {r['training_working_set_gb']:.2f} GB"
                     + ("" if slope is None else " (cache plan)" if r.get("extrapolation") == "cache plan"
                        else f" +{1e6 * slope:.0f} KB/img"), ""))
        if slope is not None:
            p = r["extrapolated_peak_gb_at_5900_f32"]
            rows.append((f"  -> {TARGET_IMAGES} img float32 in RAM (target < {TARGET_PEAK_GB:g} GB)", f"{p:.2f} GB",
                         f"uint8: {r['extrapolated_peak_gb_at_5900_u8']:.2f} GB", status(p, TARGET_PEAK_GB, False)))
        else:
            rows.append((f"  -> {TARGET_IMAGES} img (needs n52 >= 256 or --mem-small)", "n/a", "", ""))
    sf = res["subset_fast"]
    rows.append((f"subset {sp} x {args.subset}: sfanav fast", f"{sf['t']:.2f} s", f"{sf['ms_per_image']:.0f} ms/img", ""))
    if "subset_naive" in res:
        rows.append(("  sfanav naive (roll + per-view net)", f"{res['subset_naive']['t']:.1f} s",
                     f"{res['subset_naive']['ms_per_image']:.0f} ms/img", ""))
        rows.append(("  RATIO naive / fast", f"{res['naive_over_fast']:.1f}x", "", ""))
    if "mdp_over_fast" in res:
        method = res["mdp"]["attempts"][-1]["rank_deficit_method"]
        rows.append((f"  MDP 3.6 hinet Flow.train (rank_deficit={method})", f"{res['mdp']['t_train']:.1f} s",
                     f"{res['mdp_ms_per_image']:.0f} ms/img", ""))
        rows.append((f"  RATIO MDP / sfanav fast (target >= {TARGET_MDP_RATIO:g})", f"{res['mdp_over_fast']:.1f}x", "",
                     status(res["mdp_over_fast"], TARGET_MDP_RATIO)))
        rows.append(("  top-node Delta max rel diff MDP vs sfanav", f"{res['mdp_delta_max_reldiff']:.1e}",
                     "(same network?)", ""))
    elif "mdp_over_fast_lower_bound" in res:
        rows.append((f"  RATIO MDP / sfanav fast (timeout; target >= {TARGET_MDP_RATIO:g})",
                     f">= {res['mdp_over_fast_lower_bound']:.1f}x", "",
                     status(res["mdp_over_fast_lower_bound"], TARGET_MDP_RATIO) or ""))
    elif "mdp_error" in res:
        rows.append(("  MDP", "failed", res["mdp_error"][:40], ""))
    if "latency" in res:
        lat = res["latency"]
        rows.append((f"latency 1 img 600x60 -> 8, 1 thread (target < {TARGET_LATENCY_MS:g} ms)",
                     f"{lat['single_median_ms']:.2f} ms", "median", status(lat["single_median_ms"], TARGET_LATENCY_MS, False)))
        rows.append((f"transform batch of {lat['batch']}, {lat['threads']} threads", f"{lat['batch_img_per_s']:.0f} img/s",
                     f"1 thr: {lat['batch_1thread_img_per_s']:.0f}", ""))
        rows.append((f"transform rotations=True ({lat['rotations_views']} views)", f"{lat['rotations_img_per_s']:.1f} img/s", "", ""))

    wn = max(len(r[0]) for r in rows)
    print()
    print(f"== sfanav network bench (step {step}, seed {args.seed}, precision {args.precision}, "
          f"cache {'off' if args.no_cache else 'on'}) ==")
    we = max(len(r[2]) for r in rows)
    for name, val, extra, st in rows:
        print(f"  {name:<{wn}}  {val:>10}  {extra:<{we}}  {st}")
    print(f"  (load average 1 min: {res['config']['loadavg_1min_start']:.2f} at start, "
          f"{res['config']['loadavg_1min_end']:.2f} at end)")
    if "mdp_skipped" in res:
        print(f"  MDP comparison skipped: {res['mdp_skipped']}")

    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2) + "\n")
        print(f"wrote {args.json}")
    if args.strict and any(r[3] == "MISS" for r in rows):
        return 1
    return 0


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=(
            "Benchmark sfanav's hierarchical network: training time of the thesis presets under simulated "
            "rotation (extrapolated to 5900 images of 600x60, target < 5 min), fast vs naive path, vs MDP 3.6 "
            "hinet (target >= 20x), peak memory (target < 4 GB at 5900 images) and single-image latency "
            "(target < 5 ms). Prints ratios measured in one run."
        ),
    )
    p.add_argument("--n51", type=int, default=None,
                   help=f"thesis-5.1 training images (default {DEFAULT_N51}; {QUICK_N51} with --quick; 0 = skip)")
    p.add_argument("--n52", type=int, default=None,
                   help=f"thesis-5.2 training images, fresh subprocess with peak RSS (default {DEFAULT_N52}; "
                        f"{QUICK_N52} with --quick; 0 = skip, also skips the latency part)")
    p.add_argument("--subset", type=int, default=None,
                   help=f"images for the naive and MDP comparisons (default {DEFAULT_SUBSET}; {QUICK_SUBSET} with --quick)")
    p.add_argument("--subset-preset", choices=sorted(PRESET_SHAPES), default=None,
                   help=f"preset for the naive and MDP comparisons (default {DEFAULT_SUBSET_PRESET}; "
                        f"{QUICK_SUBSET_PRESET} with --quick)")
    p.add_argument("--step", type=int, default=DEFAULT_STEP, help="rotation step in pixels (default: %(default)s)")
    p.add_argument("--batch-size", type=int, default=16, help="fit batch_size (default: %(default)s)")
    p.add_argument("--repeats", type=int, default=1,
                   help="timed repeats of the thesis-5.1 fit, best is reported; the subset fast fit uses max(3, this) "
                        "(default: %(default)s)")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help="seed of the synthetic panoramas (default: %(default)s)")
    p.add_argument("--quick", action="store_true",
                   help=f"smoke run (~1-2 min): thesis-5.1 x {QUICK_N51}, thesis-5.2 x {QUICK_N52}, "
                        f"subset {QUICK_SUBSET_PRESET} x {QUICK_SUBSET} (unless given explicitly)")
    p.add_argument("--latency-calls", type=int, default=DEFAULT_LATENCY_CALLS,
                   help="single-image transform calls for the median (default: %(default)s)")
    p.add_argument("--batch", type=int, default=DEFAULT_BATCH, help="images per transform call for throughput (default: %(default)s)")
    p.add_argument("--precision", choices=["preset", "double", "mixed"], default="preset",
                   help="network precision override; 'preset' keeps the preset file's setting (default: %(default)s)")
    p.add_argument("--no-cache", action="store_true", help="fit(cache=False): stream the images in every pass")
    p.add_argument("--cache-limit", type=float, default=1e9,
                   help="Network.fit cache_limit in bytes under cache=\"auto\" (default: %(default)g)")
    p.add_argument("--mem-small", type=int, default=None,
                   help="images of a second, smaller thesis-5.2 fit in a fresh process, for the per-image slope of "
                        "the training working set (default n52 // 8 if n52 >= 256, else none; 0 = skip; without it "
                        "the memory is not extrapolated to 5900 images)")
    p.add_argument("--no-naive", action="store_true", help="skip the naive path")
    p.add_argument("--no-mdp", action="store_true", help="skip the MDP comparison")
    p.add_argument("--mdp-timeout", type=float, default=DEFAULT_MDP_TIMEOUT,
                   help="seconds before the MDP worker is killed; the ratio is then a lower bound (default: %(default)s)")
    p.add_argument("--mdp-dtype", choices=["float64", "float32"], default="float64",
                   help="dtype of the views fed to MDP (MDP computes in its input dtype; default: %(default)s)")
    p.add_argument("--mdp-chunk", type=int, default=0,
                   help="images per chunk fed to MDP's Flow.train; 0 = all views of all images as one sequence "
                        "(default: %(default)s; >0 saves memory but drops the derivative pairs across chunks)")
    p.add_argument("--mdp-rank-deficit", choices=["retry", "none", "auto", "reg", "pca", "svd"], default="retry",
                   help="MDP SFANode rank_deficit_method; 'retry' = MDP's default 'none', and 'auto' only if that "
                        "fails (default: %(default)s)")
    p.add_argument("--mdp-venv", default=str(default_mdp_venv()),
                   help="venv holding MDP 3.6 + NumPy 1.23, created on first use (default: %(default)s)")
    p.add_argument("--mdp-base-python", default=sys.executable,
                   help="interpreter used to create the MDP venv; needs Python <= 3.11 (default: %(default)s)")
    p.add_argument("--json", metavar="OUT", help="write all measured numbers and ratios to this JSON file")
    p.add_argument("--strict", action="store_true", help="exit 1 if a target is missed")
    # worker options
    p.add_argument("--_worker", choices=["train", "mdp"], help=argparse.SUPPRESS)
    p.add_argument("--_out", help=argparse.SUPPRESS)
    p.add_argument("--_geom", help=argparse.SUPPRESS)
    p.add_argument("--_model", help=argparse.SUPPRESS)
    p.add_argument("--preset", default="thesis-5.2", help=argparse.SUPPRESS)
    p.add_argument("--n", type=int, default=0, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.n51 is None:
        args.n51 = QUICK_N51 if args.quick else DEFAULT_N51
    if args.n52 is None:
        args.n52 = QUICK_N52 if args.quick else DEFAULT_N52
    if args.subset is None:
        args.subset = QUICK_SUBSET if args.quick else DEFAULT_SUBSET
    if args.subset_preset is None:
        args.subset_preset = QUICK_SUBSET_PRESET if args.quick else DEFAULT_SUBSET_PRESET
    if args.step < 1 or args.subset < 1 or args.n51 < 0 or args.n52 < 0 or args.repeats < 1 or args.latency_calls < 1:
        p.error("need step >= 1, subset >= 1, n51/n52 >= 0, repeats >= 1, latency-calls >= 1")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    if args._worker:
        fn = worker_train if args._worker == "train" else worker_mdp
        out = fn(args)
        Path(args._out).write_text(json.dumps(out))
        return 0
    return main_bench(args)


if __name__ == "__main__":
    sys.exit(main())
