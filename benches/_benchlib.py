"""Helpers shared by the benchmark scripts: the MDP 3.6 reference venv, BLAS
reporting and the MDP -> sfanav Delta normalisation. Standard library only
at import time (the MDP workers import it under NumPy 1.23)."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

MDP_REQUIREMENTS = ["numpy==1.23.5", "mdp==3.6", "scipy==1.11.4", "threadpoolctl"]
OPENBLAS_OVERRIDES = ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE")


def default_mdp_venv() -> Path:
    cache = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(cache) / "sfanav-bench" / "mdp-venv"


def blas_info() -> list[dict]:
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return [{"error": "threadpoolctl not installed"}]
    keep = ("user_api", "internal_api", "version", "architecture", "num_threads", "threading_layer", "filepath")
    return [{k: info.get(k) for k in keep} for info in threadpool_info()]


def blas_summary(info: list[dict]) -> str:
    parts = []
    for i in info:
        if i.get("user_api") == "blas" or "error" in i:
            if "error" in i:
                parts.append(i["error"])
            else:
                parts.append(
                    f"{i.get('internal_api')} {i.get('version')} {i.get('architecture')} "
                    f"x{i.get('num_threads')} threads"
                )
    return "; ".join(dict.fromkeys(parts)) or "no BLAS found"


def ensure_mdp_venv(venv: Path, base_python: str) -> Path | None:
    """Create (once) a venv with MDP 3.6 + NumPy 1.23; return its python or None."""
    py = venv / "bin" / "python"
    stamp = venv / ".sfanav-bench-ok"
    wanted = " ".join(MDP_REQUIREMENTS)
    if py.exists() and stamp.exists() and stamp.read_text().strip() == wanted:
        return py
    venv.parent.mkdir(parents=True, exist_ok=True)
    log = venv.parent / (venv.name + "-install.log")
    print(f"[mdp] creating venv {venv} with {wanted} (one-off; log: {log}) ...", flush=True)
    with open(log, "w") as fh:
        steps = []
        if not py.exists():
            steps.append([base_python, "-m", "venv", str(venv)])
        steps.append([str(py), "-m", "pip", "install", *MDP_REQUIREMENTS])
        steps.append([str(py), "-c", "import mdp, numpy; print('mdp', mdp.__version__, 'numpy', numpy.__version__)"])
        for cmd in steps:
            fh.write("$ " + " ".join(cmd) + "\n")
            fh.flush()
            try:
                r = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT)
            except OSError as e:
                fh.write(f"{e}\n")
                r = None
            if r is None or r.returncode != 0:
                print(f"[mdp] venv setup failed at: {' '.join(cmd)} (see {log})", flush=True)
                return None
    stamp.write_text(wanted + "\n")
    return py


def delta_mdp_to_sfanav_factor(t: int) -> float:
    """Factor f with Delta_sfanav = f * Delta_mdp, for one sequence of t samples.

    sfanav: covariance B_s = C / T (population; C = centered scatter matrix),
            derivative covariance A_s = S_dd / P (mean squared derivative,
            uncentered), P = T - 1 derivative pairs.
    MDP 3.6 (SFANode with include_last_sample=True, CovarianceMatrix(bias=False)):
      mdp/utils/covariance.py, CovarianceMatrix.fix: line 119 ``cov_mtx /= tlen - 1``
            and line 126 ``avg_mtx /= tlen*(tlen - 1)`` (subtracted when center=True),
            i.e. B_m = C / (T - 1);
      mdp/nodes/sfa_nodes.py, SFANode._stop_training, lines 270-271: the derivative
            matrix is fixed with ``center=False``, so the same line 119 gives
            A_m = S_dd / (P - 1) with tlen = P = T - 1 (time_derivative, line 213:
            ``x[1:, :]-x[:-1, :]``, no 1/dt).
    Generalized eigenvalues scale as A/B:
      Delta_m = Delta_s * (P / (P - 1)) * ((T - 1) / T)
      => Delta_s = Delta_m * (P - 1) * T / (P * (T - 1)) = Delta_m * T (T - 2) / (T - 1)^2.
    """
    p = t - 1
    return (p - 1) * t / (p * (t - 1))


def rendered_garden(root: Path, small: bool, seed: int, max_frames: int | None, tag: object):
    """The ``thesis-6.2.1-static`` garden rendered at 60x8 (``small``) or
    350x40 under ``root`` (cached: reused when present; ``tag`` names the
    folder beside the size and seed) and the preprocessing of the sfanav
    default's long-term recipe: ``(dataset, prep)``."""
    from sfanav import Dataset, sim
    from sfanav.experiments.robustness import long_term_configuration

    camera = sim.PanoramicCamera(60, 8) if small else sim.PanoramicCamera(350, 40)
    path = Path(root) / f"garden-{camera.width}x{camera.height}-seed{seed}-{tag}"
    if (path / "metadata.json").exists():
        ds = Dataset(path)
    else:
        ds = sim.simulate("thesis-6.2.1-static", path, seed, max_frames=max_frames, camera=camera, overwrite=True,
                          progress=False)
    _, prep, _ = long_term_configuration("sfanav default", small)
    return ds, prep


def best(f, repeats: int):
    """(result of the last call, fastest seconds) of ``repeats`` calls of f."""
    ts, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = f()
        ts.append(time.perf_counter() - t)
    return out, min(ts)
