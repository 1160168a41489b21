#!/usr/bin/env python3
"""sfanav core benchmark: ratios measured in one run.

1. Accumulation throughput: ``sfanav.Statistics(D).update(X)`` (mean, covariance
   and derivative covariance in one streaming pass) against NumPy's ``X.T @ X``
   "roofline".  Reference time = 2 x time(X.T @ X) (covariance and derivative
   covariance: two products); the full NumPy path (sum, X.T @ X,
   dX = X[1:] - X[:-1], dX.T @ dX) is reported as a second reference.  The NumPy
   reference runs in a subprocess with OPENBLAS_CORETYPE and OPENBLAS_L2_SIZE
   unset (only there), and reports the BLAS kernel and threads it used.
   Target: reference / sfanav >= 0.8.

2. Full linear SFA fit: ``sfanav.SFA(n_components=K).fit(X)`` against MDP 3.6's
   ``SFANode(output_dim=K)``.  MDP 3.6 does not import under NumPy 2, so it runs
   in its own venv (created once, cached).  Targets: MDP / sfanav time >= 3 and
   max relative difference of the Delta values <= 1e-6 after converting MDP's
   normalisation to sfanav's.

Every process generates the same data from the seed (nothing large is shipped
between processes); a fingerprint of the data is compared across processes.
Quote the printed ratios, not the seconds: the machines are shared and noisy.

This file is also the worker script: the subprocesses run it with the hidden
``--_worker {numpy,mdp}`` option (the MDP venv runs it under NumPy 1.23, so it
must stay importable there and must not import sfanav at module level).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
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

DEFAULT_N = 10**6
DEFAULT_D = 300
QUICK_N = 200_000
QUICK_D = 100
DEFAULT_K = 20
DEFAULT_SEED = 20261123
DEFAULT_REPEATS = 3

TARGET_ACCUM_RATIO = 0.8  # (2 x numpy X.T@X time) / sfanav Statistics.update time
TARGET_FIT_RATIO = 3.0  # MDP SFANode fit time / sfanav SFA fit time
TARGET_DELTA_RELDIFF = 1e-6  # max |Delta_sfanav - Delta_mdp| / |Delta_mdp|

# Pinned so the venv is reproducible: numpy 1.23.5 is the last NumPy that MDP 3.6
# imports under (no np.typeDict/np.longfloat removals yet) and has cp311 wheels;
# scipy 1.11.4 is the newest SciPy that supports NumPy 1.23 on Python 3.11.

# Environment variables that slow a current OpenBLAS down on some machines (see
# docs/benchmarks.md): unset together, only in the NumPy-reference subprocess.

CHUNK = 1 << 16  # rows per generation chunk; fixed, so the RNG stream is fixed


# --------------------------------------------------------------------------
# data (identical in every process for a given seed, n, d)
# --------------------------------------------------------------------------


def make_data(n: int, d: int, seed: int) -> np.ndarray:
    """Seeded, correlated (n, d) float64 data with slow components.

    Sources: the first d//2 columns are sinusoids with periods log-spaced from
    1000 down to 20 samples (random phases, tiny white noise), the rest white
    Gaussian noise; they are mixed by a well-conditioned random matrix
    (I + 0.3 G / sqrt(d), condition number < ~4) and offset by a modest mean.
    The slowest Delta is ~4e-5 against ~2 for noise, so the generalized
    eigenproblem is well conditioned enough for a 1e-6 comparison.

    Uses only default_rng(seed).uniform/standard_normal (same stream in
    NumPy 1.23 and 2.x), np.sin and one matmul per chunk, so processes with
    different NumPy versions agree up to rounding.
    """
    rng = np.random.default_rng(seed)
    n_smooth = max(1, d // 2)
    omega = 2.0 * np.pi / np.geomspace(1000.0, 20.0, n_smooth)
    phase = rng.uniform(0.0, 2.0 * np.pi, n_smooth)
    mix = np.eye(d) + 0.3 * rng.standard_normal((d, d)) / np.sqrt(d)
    offset = rng.uniform(-1.0, 1.0, d)
    noise = 1e-3

    x = np.empty((n, d), dtype=np.float64)
    src = np.empty((min(CHUNK, n), d), dtype=np.float64)
    for start in range(0, n, CHUNK):
        stop = min(n, start + CHUNK)
        m = stop - start
        s = src[:m]
        t = np.arange(start, stop, dtype=np.float64)
        np.sin(np.multiply.outer(t, omega) + phase, out=s[:, :n_smooth])
        s[:, :n_smooth] += noise * rng.standard_normal((m, n_smooth))
        s[:, n_smooth:] = rng.standard_normal((m, d - n_smooth))
        np.matmul(s, mix, out=x[start:stop])
        x[start:stop] += offset
    return x


def fingerprint(x: np.ndarray) -> list[float]:
    return [float(x[: min(len(x), 4096)].sum()), float(x.sum()), float(x[-1].sum())]


def fingerprints_match(a: list[float], b: list[float], rtol: float = 1e-9) -> bool:
    return all(abs(p - q) <= rtol * max(1.0, abs(p), abs(q)) for p, q in zip(a, b))


def best_of(fn, repeats: int) -> tuple[float, list[float], object]:
    """Best wall time (perf_counter) over `repeats` calls; returns the last result."""
    times = []
    result = None
    for _ in range(repeats):
        result = None
        gc.collect()
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return min(times), times, result


# --------------------------------------------------------------------------
# workers (run in subprocesses)
# --------------------------------------------------------------------------


def worker_numpy(args: argparse.Namespace) -> dict:
    x = make_data(args.n, args.d, args.seed)
    fp = fingerprint(x)

    def xtx():
        return x.T @ x  # NumPy detects A.T @ A and calls SYRK

    def full():
        s = x.sum(axis=0)
        c = x.T @ x
        dx = x[1:] - x[:-1]
        cd = dx.T @ dx
        del dx
        return s, c, cd

    t_xtx, times_xtx, _ = best_of(xtx, args.repeats)
    t_full, times_full, _ = best_of(full, args.repeats)
    return {
        "numpy_version": np.__version__,
        "blas": blas_info(),
        "env": {k: os.environ.get(k) for k in OPENBLAS_OVERRIDES},
        "fingerprint": fp,
        "t_xtx": t_xtx,
        "times_xtx": times_xtx,
        "t_full": t_full,
        "times_full": times_full,
    }


def worker_mdp(args: argparse.Namespace) -> dict:
    import mdp  # noqa: PLC0415  (only in the MDP venv)

    x = make_data(args.n, args.d, args.seed)
    fp = fingerprint(x)

    def fit():
        node = mdp.nodes.SFANode(output_dim=args.k)
        node.train(x)
        node.stop_training()
        return node

    t_fit, times_fit, node = best_of(fit, args.repeats)
    return {
        "mdp_version": mdp.__version__,
        "numpy_version": np.__version__,
        "blas": blas_info(),
        "env": {k: os.environ.get(k) for k in OPENBLAS_OVERRIDES},
        "fingerprint": fp,
        "t_fit": t_fit,
        "times_fit": times_fit,
        "delta": [float(v) for v in node.d],
        "tlen": int(node.tlen),
        "dtlen": int(node.dtlen),
    }


def run_worker(kind: str, python: str, args: argparse.Namespace, env: dict) -> dict:
    with tempfile.TemporaryDirectory(prefix="sfanav-bench-") as tmp:
        out = Path(tmp) / "result.json"
        cmd = [
            python,
            os.path.abspath(__file__),
            "--_worker", kind,
            "--_out", str(out),
            "--n", str(args.n),
            "--d", str(args.d),
            "--k", str(args.k),
            "--seed", str(args.seed),
            "--repeats", str(args.repeats),
        ]
        proc = subprocess.run(cmd, env=env)
        if proc.returncode != 0 or not out.exists():
            raise RuntimeError(f"{kind} worker failed (exit {proc.returncode}): {' '.join(cmd)}")
        return json.loads(out.read_text())


# --------------------------------------------------------------------------
# MDP venv
# --------------------------------------------------------------------------


# --------------------------------------------------------------------------
# main
# --------------------------------------------------------------------------


def fmt_t(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.3f} s"


def fmt_r(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.2f}x"


def main_bench(args: argparse.Namespace) -> int:
    res: dict = {
        "config": {
            "n": args.n,
            "d": args.d,
            "k": args.k,
            "seed": args.seed,
            "repeats": args.repeats,
            "python": sys.version.split()[0],
            "machine": platform.machine(),
            "cpu_count": os.cpu_count(),
            "env": {k: os.environ.get(k) for k in OPENBLAS_OVERRIDES},
        },
        "targets": {
            "accum_ratio_min": TARGET_ACCUM_RATIO,
            "fit_ratio_min": TARGET_FIT_RATIO,
            "delta_reldiff_max": TARGET_DELTA_RELDIFF,
        },
    }
    sfanav = None
    if not args.no_sfanav:
        try:
            import sfanav  # noqa: PLC0415
        except ImportError as e:
            print(f"error: cannot import sfanav ({e}); build it first (maturin develop) "
                  "or pass --no-sfanav to run the references only", file=sys.stderr)
            return 2
        res["config"]["sfanav_version"] = getattr(sfanav, "__version__", None)
        get_threads = getattr(sfanav, "get_num_threads", None)
        res["config"]["sfanav_threads"] = get_threads() if get_threads else None
    n, d, k = args.n, args.d, args.k
    gb = n * d * 8 / 1e9
    print(f"sfanav benchmark: N={n} D={d} K={k} seed={args.seed} repeats={args.repeats} "
          f"(X is {gb:.2f} GB float64; each process holds <= ~2 copies)", flush=True)
    load = os.getloadavg()[0]
    res["config"]["loadavg_1min_start"] = load
    if load > 0.5:
        print(f"warning: 1-min load average is {load:.2f} before the run: other processes are busy; "
              f"on {os.cpu_count()} cores multithreaded BLAS/rayon timings can be off by large factors",
              flush=True)
    if sfanav is not None:
        print(f"sfanav {res['config']['sfanav_version']}, {res['config']['sfanav_threads']} threads "
              f"(build with `maturin develop --release` before timing)", flush=True)

    # ---- phase 1: accumulation vs NumPy -----------------------------------
    ref = None
    if not args.no_numpy:
        env = {k_: v for k_, v in os.environ.items() if k_ not in OPENBLAS_OVERRIDES}
        print("[numpy] reference subprocess (OPENBLAS_CORETYPE/OPENBLAS_L2_SIZE unset) ...", flush=True)
        ref = run_worker("numpy", sys.executable, args, env)
        print(f"[numpy] numpy {ref['numpy_version']}, BLAS: {blas_summary(ref['blas'])}", flush=True)
        res["numpy"] = ref

    x = None
    fp_main = None
    if sfanav is not None:
        print("[sfanav] generating data ...", flush=True)
        x = make_data(n, d, args.seed)
        fp_main = fingerprint(x)
        res["fingerprint"] = fp_main
        time.sleep(0.5)  # let idle OpenBLAS threads from the generation matmul stop spinning

        def accumulate():
            st = sfanav.Statistics(d)
            st.update(x)
            return st

        t_acc, times_acc, _ = best_of(accumulate, args.repeats)
        res["sfanav_statistics"] = {"t": t_acc, "times": times_acc}
        print(f"[sfanav] Statistics.update best {t_acc:.3f} s", flush=True)
        if ref is not None:
            if not fingerprints_match(fp_main, ref["fingerprint"]):
                print(f"warning: data fingerprint differs from numpy worker: {fp_main} vs {ref['fingerprint']}")
            res["accum_ratio"] = 2.0 * ref["t_xtx"] / t_acc
            res["accum_ratio_full"] = ref["t_full"] / t_acc

    # ---- phase 2: full linear SFA fit vs MDP -------------------------------
    delta_s = None
    if sfanav is not None:

        def fit():
            return sfanav.SFA(n_components=k).fit(x)

        t_fit, times_fit, model = best_of(fit, args.repeats)
        delta_s = np.sort(np.asarray(model.delta_values_, dtype=np.float64))
        del model
        res["sfanav_fit"] = {"t": t_fit, "times": times_fit, "delta": delta_s.tolist()}
        print(f"[sfanav] SFA.fit best {t_fit:.3f} s", flush=True)
    del x
    gc.collect()

    mdp_res = None
    if args.no_mdp:
        print("[mdp] skipped (--no-mdp)")
        res["mdp_skipped"] = "--no-mdp"
    else:
        py = ensure_mdp_venv(Path(args.mdp_venv).expanduser(), args.mdp_base_python)
        if py is None:
            print("[mdp] skipped: the MDP venv could not be created")
            res["mdp_skipped"] = "venv creation failed"
        else:
            # The MDP process keeps the caller's environment: its old OpenBLAS (0.3.20)
            # is what the OPENBLAS_* overrides exist for.
            print(f"[mdp] SFANode subprocess ({py}) ...", flush=True)
            try:
                mdp_res = run_worker("mdp", str(py), args, dict(os.environ))
            except RuntimeError as e:
                print(f"[mdp] skipped: {e}")
                res["mdp_skipped"] = str(e)
            if mdp_res is not None:
                print(f"[mdp] mdp {mdp_res['mdp_version']}, numpy {mdp_res['numpy_version']}, "
                      f"BLAS: {blas_summary(mdp_res['blas'])}; fit best {mdp_res['t_fit']:.3f} s", flush=True)
                res["mdp"] = mdp_res
                if fp_main is not None and not fingerprints_match(fp_main, mdp_res["fingerprint"]):
                    print(f"warning: data fingerprint differs from MDP worker: "
                          f"{fp_main} vs {mdp_res['fingerprint']}")
                factor = delta_mdp_to_sfanav_factor(mdp_res["tlen"])
                assert mdp_res["dtlen"] == mdp_res["tlen"] - 1
                res["delta_factor_mdp_to_sfanav"] = factor
                if delta_s is not None:
                    delta_m = np.sort(np.asarray(mdp_res["delta"])) * factor
                    if delta_m.shape != delta_s.shape:
                        print(f"warning: Delta shapes differ: mdp {delta_m.shape} vs sfanav {delta_s.shape}")
                        m_ = min(len(delta_m), len(delta_s))
                        delta_m, delta_s = delta_m[:m_], delta_s[:m_]
                    rel = np.abs(delta_s - delta_m) / np.abs(delta_m)
                    res["delta_max_reldiff"] = float(rel.max())
                    res["fit_ratio"] = mdp_res["t_fit"] / res["sfanav_fit"]["t"]

    res["config"]["loadavg_1min_end"] = os.getloadavg()[0]

    # ---- summary ------------------------------------------------------------
    def status(val, target, higher_is_better=True):
        if val is None:
            return ""
        ok = val >= target if higher_is_better else val <= target
        return "ok" if ok else "MISS"

    rows = []
    if ref is not None:
        rows.append(("numpy X.T@X (best)", fmt_t(ref["t_xtx"]), ""))
        rows.append(("numpy reference = 2 x X.T@X", fmt_t(2 * ref["t_xtx"]), ""))
        rows.append(("numpy full path (sum, XtX, diff, dXtdX)", fmt_t(ref["t_full"]), ""))
    if "sfanav_statistics" in res:
        rows.append(("sfanav Statistics.update", fmt_t(res["sfanav_statistics"]["t"]), ""))
    if "accum_ratio" in res:
        a = res["accum_ratio"]
        rows.append((f"RATIO 2xXtX / sfanav (target >= {TARGET_ACCUM_RATIO})", fmt_r(a), status(a, TARGET_ACCUM_RATIO)))
        rows.append(("ratio numpy full path / sfanav", fmt_r(res["accum_ratio_full"]), ""))
    if mdp_res is not None:
        rows.append((f"MDP 3.6 SFANode train+stop (K={k})", fmt_t(mdp_res["t_fit"]), ""))
    if "sfanav_fit" in res:
        rows.append((f"sfanav SFA.fit (K={k})", fmt_t(res["sfanav_fit"]["t"]), ""))
    if "fit_ratio" in res:
        f_ = res["fit_ratio"]
        rows.append((f"RATIO MDP / sfanav fit (target >= {TARGET_FIT_RATIO:g})", fmt_r(f_), status(f_, TARGET_FIT_RATIO)))
        dr = res["delta_max_reldiff"]
        rows.append((f"max rel diff Delta (target <= {TARGET_DELTA_RELDIFF:g})", f"{dr:.2e}",
                     status(dr, TARGET_DELTA_RELDIFF, higher_is_better=False)))
    if ref is not None and mdp_res is not None:
        rows.append(("(info) MDP fit / (2 x numpy X.T@X)", fmt_r(mdp_res["t_fit"] / (2 * ref["t_xtx"])), ""))

    w = max(len(r[0]) for r in rows) if rows else 10
    print()
    print(f"== sfanav bench: N={n} D={d} K={k}, best of {args.repeats} ==")
    for name, val, st in rows:
        print(f"  {name:<{w}}  {val:>10}  {st}")
    print(f"  (load average 1 min: {res['config']['loadavg_1min_start']:.2f} at start, "
          f"{res['config']['loadavg_1min_end']:.2f} at end)")
    if "mdp_skipped" in res:
        print(f"  MDP comparison skipped: {res['mdp_skipped']}")
    if sfanav is None:
        print("  sfanav not run (--no-sfanav)")

    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2) + "\n")
        print(f"wrote {args.json}")

    if args.strict:
        misses = [r for r in rows if r[2] == "MISS"]
        if misses:
            return 1
    return 0


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=(
            "Benchmark sfanav's Rust core: accumulation throughput vs NumPy's X.T@X "
            "(target ratio >= 0.8) and full linear SFA fit vs MDP 3.6's SFANode "
            "(target >= 3x, Delta agreement <= 1e-6). Prints ratios measured in one run."
        ),
    )
    p.add_argument("--n", type=int, default=None, help=f"number of samples T (default {DEFAULT_N}; {QUICK_N} with --quick)")
    p.add_argument("--d", type=int, default=None, help=f"input dimension D (default {DEFAULT_D}; {QUICK_D} with --quick)")
    p.add_argument("--k", type=int, default=DEFAULT_K, help="number of slow features K for the fit comparison (default: %(default)s)")
    p.add_argument("--repeats", type=int, default=DEFAULT_REPEATS, help="timed repeats per measurement, best is reported (default: %(default)s)")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help="seed for the generated data (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help=f"small problem: N={QUICK_N}, D={QUICK_D} (unless --n/--d given)")
    p.add_argument("--no-mdp", action="store_true", help="skip the MDP comparison")
    p.add_argument("--no-numpy", action="store_true", help="skip the NumPy X.T@X reference")
    p.add_argument("--no-sfanav", action="store_true", help="run the references only (sfanav not imported)")
    p.add_argument("--mdp-venv", default=str(default_mdp_venv()),
                   help="venv holding MDP 3.6 + NumPy 1.23, created on first use (default: %(default)s)")
    p.add_argument("--mdp-base-python", default=sys.executable,
                   help="interpreter used to create the MDP venv; needs Python <= 3.11 for NumPy 1.23 wheels (default: %(default)s)")
    p.add_argument("--json", metavar="OUT", help="write all measured numbers and ratios to this JSON file")
    p.add_argument("--strict", action="store_true", help="exit 1 if a target is missed")
    p.add_argument("--_worker", choices=["numpy", "mdp"], help=argparse.SUPPRESS)
    p.add_argument("--_out", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.n is None:
        args.n = QUICK_N if args.quick else DEFAULT_N
    if args.d is None:
        args.d = QUICK_D if args.quick else DEFAULT_D
    if args.n < 3 or args.d < 2 or not (1 <= args.k <= args.d) or args.repeats < 1:
        p.error("need n >= 3, d >= 2, 1 <= k <= d, repeats >= 1")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    if args._worker:
        fn = worker_numpy if args._worker == "numpy" else worker_mdp
        out = fn(args)
        Path(args._out).write_text(json.dumps(out))
        return 0
    return main_bench(args)


if __name__ == "__main__":
    sys.exit(main())
