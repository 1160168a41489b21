"""The gardens suite: the sfanav default against the peers in clearly
different gardens (docs/gardens.md).

``gardens-suite``: every ``suite-*`` simulator preset (a garden each: objects
inside the area, the thesis-like control, dense trees close around, an open
lawn with few distant landmarks, strong ground texture, dusk and low-sun
light, a large and a small yard, ...) is simulated with its own seed; each
has two training runs (``train-grid``: serpentine lanes along x;
``train-cross``: the same with crossing lanes along y) and three test runs
(``test-grid``: points between and beyond the training lanes at random
headings, where a method must generalize instead of recall; ``test-walk``: a
random walk; ``test-walk jpeg-90``: the random walk as a ROS camera's
image_transport sends it, JPEG at quality 90). For every garden, training
run and test run it measures

* the **sfanav default** (:func:`sfanav.pipeline.train_localizer`, exactly
  as ``sfanav train`` without a preset),
* the **thesis configuration** (Table 5.1 network, all rows, quadratic
  regression of the 8 slowest outputs),
* the peers: **perfect memory** (rotational image difference) and the
  **Fourier signature**'s nearest neighbour, on the raw panoramas,
* the default's two parts on the default's own network: **slow features
  only** (the GP readout of the pooled slow features, the default before
  it read the signature) and **signature only** (the signature's GP),

as MAE per axis (% of the test run's range), MED and the 95th percentile of
the error (m), with the bytes each stores per training place and its query
time; then the ratio default / best peer per metric (best peer: the better of
the two on that metric), and the suite's worst case and median of each ratio.
A plot shows the per-garden ratios.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import sim
from .._threads import one_blas_thread
from ..data.corruptions import corrupt
from ..data.preprocessing import Preprocessing
from ..data.sources import load_run
from ..localization import baselines
from ..localization.error_metrics import localization_metrics
from ..localization.evaluation import coordinate_range
from ..localization.localizer import Localizer
from ..localization.signature_readout import SignatureGPReadout
from ..sfa.network import Network, Rotation
from . import ExperimentResult, register
from .localization import progress_log, simulated, tiny_config

TRAIN_RUNS = ("train-grid", "train-cross")
CORRUPTED_TESTS = {"test-walk jpeg-90": ("test-walk", "jpeg-90")}
"""Test runs as a robot's camera sends them: the test walk JPEG-compressed at quality 90 (the models trained on
the lossless run; the corruption suite, docs/robustness.md, measures the rest)."""
TEST_RUNS = ("test-grid", "test-walk", *CORRUPTED_TESTS)
METHODS = ("sfanav default", "thesis config", "perfect memory", "Fourier signature")
ABLATIONS = ("slow features only", "signature only")
"""The default's two parts on its own network: the slow features' GP readout (the default before the
signature), and the signature's GP alone."""
PEERS = ("perfect memory", "Fourier signature")
RATIO_METRICS = ("MAE x (%)", "MAE y (%)", "MED (m)", "p95 (m)")
TARGET_WORST, TARGET_MEDIAN = 0.9, 0.7  # ratio default / best peer: worst case and median
THESIS_SPEC = {"kind": "quadratic", "n_outputs": 8, "ridge": 0.0}


def gardens() -> list[str]:
    """The suite's garden names (the ``suite-<name>`` presets)."""
    return list(sim.presets.SUITE_GARDENS)


FAR = 0.35  # m: test points farther than this from every training position must be generalized to


def _metrics(pred: np.ndarray, xy: np.ndarray, crange: np.ndarray, far: np.ndarray) -> dict[str, float]:
    m = localization_metrics(pred, xy, coordinate_range=crange, percentiles=(50, 95))
    err = np.hypot(*(pred - xy).T)
    return {"MAE x (%)": m["mae_x_pct"], "MAE y (%)": m["mae_y_pct"], "MED (m)": m["med"], "p95 (m)": m["p95"],
            "MED far from training (m)": float(err[far].mean()) if far.any() else float("nan"),
            "MED near training (m)": float(err[~far].mean()) if (~far).any() else float("nan")}


def _bytes_per_place(loc: Localizer, n_train: int) -> float:
    """Bytes of the readout's arrays that grow with the training run, per
    training place (0 for a parametric readout). A readout fitted with
    augmented copies (robustness ``"standard"``) stores each place twice, and
    both count."""
    n_fit = n_train + getattr(loc, "n_augmented_", 0)
    state = loc.regression_.get_state()
    total = sum(v.nbytes for v in state.values() if isinstance(v, np.ndarray) and v.ndim >= 1 and len(v) == n_fit)
    return total / n_train


class _SignatureOnly:
    """The signature's GP readout as a localizer of images."""

    def __init__(self, readout: SignatureGPReadout, loc: Localizer) -> None:
        self.readout, self.loc = readout, loc
        self.bytes_per_place_ = float(readout.G_[0].nbytes + readout.dual_[0].nbytes)

    def predict(self, images: np.ndarray) -> np.ndarray:
        return self.readout.predict(self.loc.signatures(images))


def _timed_predict(model: Any, X: np.ndarray) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    pred = model.predict(X)
    return pred, 1000.0 * (time.perf_counter() - t0) / len(X)


def run_garden(out: Path, name: str, seed: int, *, quick: bool, progress: bool,
               points: dict[str, np.ndarray] | None = None) -> dict[str, Any]:
    """One garden: {train run: {method: {test run: metrics + bytes/place, query ms}}}
    plus the training times. ``points`` (if given) receives per test point
    the error of every method and the point's distances to the training
    run and to the area's border, keyed ``garden|train|test|what``."""
    from scipy.spatial import cKDTree

    from ..localization.recipe import default_network
    from ..pipeline import train_localizer

    log = progress_log(progress)
    preset = f"suite-{name}"
    if quick:
        ds = simulated(out, preset, seed, quick=True, camera=sim.PanoramicCamera(60, 8), max_frames=50,
                       progress=progress)
    else:
        ds = simulated(out, preset, seed, quick=False, progress=progress)
    cam = ds.metadata["camera"]
    elev = tuple(cam.get("elevation_deg", (-30.0, 20.0)))
    prep = Preprocessing(int(cam["width"]), int(cam["height"]), False, False)
    tests = {t: load_run(ds.select(run=t), prep) for t in TEST_RUNS if t not in CORRUPTED_TESTS}
    for t, (base, corruption) in CORRUPTED_TESTS.items():
        X_te, xy_te = tests[base]
        tests[t] = (corrupt(X_te, corruption, seed=seed), xy_te)
    res: dict[str, Any] = {}
    for tr in TRAIN_RUNS:
        X_tr, xy_tr = load_run(ds.select(run=tr), prep)
        per: dict[str, dict[str, Any]] = {m: {} for m in METHODS + ABLATIONS}
        models: dict[str, Any] = {}
        t0 = time.perf_counter()
        shape = X_tr.shape[1:]
        net = Network(tiny_config(shape[1], shape[0], shape[2], out=12)) if quick else default_network()
        loc = models["sfanav default"] = train_localizer(X_tr, xy=xy_tr, camera_elevation=elev, network=net)
        t_default = time.perf_counter() - t0
        F_tr, G_tr = loc.features(X_tr), loc.signatures(X_tr)
        slow = loc.sibling(readout={"kind": "gp", "n_outputs": min(12, F_tr.shape[1])}, n_outputs=None,
                           rotation_pooling="auto", signature=None).fit_features(F_tr, xy_tr)  # the previous default's readout (its CV chose the GP)
        sig = SignatureGPReadout(0, G_tr.shape[1]).fit(G_tr, xy_tr)
        models["slow features only"] = slow
        models["signature only"] = _SignatureOnly(sig, loc)
        t0 = time.perf_counter()
        tnet = (Network(tiny_config(shape[1], shape[0], shape[2], out=8)) if quick
                else Network.from_preset("thesis-5.1", precision="mixed"))
        tnet.fit(X_tr, Rotation(step=5, window=1.0), progress=False)
        models["thesis config"] = Localizer(tnet, n_outputs=8, readout=dict(THESIS_SPEC),
                                            rotation_pooling=None).fit(X_tr, xy_tr)
        t_thesis = time.perf_counter() - t0
        models["perfect memory"] = baselines.PerfectMemory().fit(X_tr, xy_tr)
        k = baselines.FourierSignature().n_coefficients
        models["Fourier signature"] = baselines.FourierSignature(min(k, X_tr.shape[2] // 2 + 1)).fit(X_tr, xy_tr)
        tree = cKDTree(xy_tr)
        half = np.asarray(sim.presets.get(preset).world["area"], float) / 2
        dists = {t: tree.query(xy_te)[0] for t, (_, xy_te) in tests.items()}
        for t, (_, xy_te) in tests.items():
            dist = dists[t]
            if points is not None:
                points[f"{name}|{tr}|{t}|distance to training (m)"] = dist
                points[f"{name}|{tr}|{t}|distance to border (m)"] = np.min(half - np.abs(xy_te), axis=1)
        for method, model in models.items():
            bpp = (_bytes_per_place(model, len(X_tr)) if isinstance(model, Localizer)
                   else float(getattr(model, "bytes_per_place_", 0) or 0))
            for t, (X_te, xy_te) in tests.items():
                pred, ms = _timed_predict(model, X_te)
                far = dists[t] > FAR
                per[method][t] = {**_metrics(pred, xy_te, coordinate_range(xy_te), far), "bytes per place": bpp,
                                  "query ms": ms, "share far from training": float(far.mean())}
                if points is not None:
                    points[f"{name}|{tr}|{t}|{method} error (m)"] = np.hypot(*(pred - xy_te).T)
        res[tr] = {"methods": per, "training (s)": {"sfanav default": t_default, "thesis config": t_thesis},
                   "n_train": len(X_tr), "n_test": {t: len(v[1]) for t, v in tests.items()}}
        d, pm, fs = (per[m]["test-walk"]["MED (m)"] for m in ("sfanav default", "perfect memory", "Fourier signature"))
        log(f"{name} seed {seed} {tr} ({len(X_tr)} images): test-walk MED default {d:.3f}, perfect memory {pm:.3f}, "
            f"Fourier {fs:.3f} m; training default {t_default:.0f} s, thesis {t_thesis:.0f} s")
    return res


def ratios(res: dict[str, Any]) -> dict[str, dict[str, float]]:
    """{"<train run> / <test run>": {metric: default / best peer}} of one garden."""
    out: dict[str, dict[str, float]] = {}
    for tr, r in res.items():
        per = r["methods"]
        for te in TEST_RUNS:
            out[f"{tr} / {te}"] = {m: per["sfanav default"][te][m] / min(per[p][te][m] for p in PEERS)
                                   for m in RATIO_METRICS}
    return out


def plot_ratios(table: dict[str, dict[str, dict[str, float]]], path: Path) -> Path:
    """One group of bars per garden: the ratio default / best peer of each
    metric, worst over the training and test runs; lines at 1 and the
    targets."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(table)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(names) + 2), 4.0))
    width = 0.8 / len(RATIO_METRICS)
    for j, m in enumerate(RATIO_METRICS):
        vals = [max(c[m] for c in table[g].values()) for g in names]
        ax.bar(np.arange(len(names)) + (j - (len(RATIO_METRICS) - 1) / 2) * width, vals, width, label=m)
    for y, style, label in ((1.0, "-", "peer's level"), (TARGET_WORST, "--", "target, worst case"),
                            (TARGET_MEDIAN, ":", "target, median")):
        ax.axhline(y, color="k", linestyle=style, linewidth=0.8, label=label)
    ax.set_xticks(np.arange(len(names)), names, rotation=35, ha="right")
    ax.set_ylabel("sfanav default / best peer (worst run)")
    ax.set_title("gardens suite: ratio to the best peer per garden (lower is better)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _markdown(results: dict[str, dict[str, Any]], table: dict[str, dict[str, dict[str, float]]]) -> str:
    lines = [("| garden | training / test | sfanav default MAE x / y %, MED, p95 | thesis config | perfect memory | "
              "Fourier signature | slow features only | signature only | ratio default / best peer (MAE x, MAE y, MED, p95) |"),
             "|---|---|---|---|---|---|---|---|---|"]
    for g, res in results.items():
        for tr, r in res.items():
            for te in TEST_RUNS:
                cells = []
                for meth in METHODS + ABLATIONS:
                    v = r["methods"][meth][te]
                    cells.append(f"{v['MAE x (%)']:.2f} / {v['MAE y (%)']:.2f}, {v['MED (m)']:.3f}, {v['p95 (m)']:.2f}")
                rt = table[g][f"{tr} / {te}"]
                lines.append(f"| {g} | {tr} / {te} | " + " | ".join(cells) + " | "
                             + ", ".join(f"{rt[m]:.2f}" for m in RATIO_METRICS) + " |")
    lines += ["", "| garden | training | bytes per place: " + " / ".join(METHODS) + " | query ms per image (test walk): "
              + " / ".join(METHODS) + " | training s: sfanav default / thesis config |", "|---|---|---|---|---|"]
    for g, res in results.items():
        for tr, r in res.items():
            walk = {m: r["methods"][m]["test-walk"] for m in METHODS}
            t = r["training (s)"]
            lines.append(f"| {g} | {tr} | " + " / ".join(f"{walk[m]['bytes per place']:.0f}" for m in METHODS) + " | "
                         + " / ".join(f"{walk[m]['query ms']:.1f}" for m in METHODS)
                         + f" | {t['sfanav default']:.1f} / {t['thesis config']:.1f} |")
    return "\n".join(lines)


@register("gardens-suite", "sfanav default vs. peers in 12 different gardens (grid and crossing runs, test grid "
                           "and walk)")
def exp_gardens_suite(out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    with one_blas_thread():  # the readouts' many small solves thrash with more threads
        return _exp_suite(out, quick=quick, seed=seed, progress=progress)


def _exp_suite(out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    t_all = time.perf_counter()
    names = gardens()[:2] if quick else gardens()
    points: dict[str, np.ndarray] = {}
    results = {g: run_garden(out, g, seed + i, quick=quick, progress=progress, points=points)
               for i, g in enumerate(names)}
    np.savez_compressed(out / "gardens-suite-points.npz", **points)
    table = {g: ratios(r) for g, r in results.items()}
    rows: list[dict[str, Any]] = []
    for g, res in results.items():
        for tr, r in res.items():
            for meth in METHODS + ABLATIONS:
                for te in TEST_RUNS:
                    for k, v in r["methods"][meth][te].items():
                        rows.append({"metric": f"{k} [{g}: {tr} / {te}: {meth}]", "thesis": None, "sfanav": v,
                                     "garden": g, "train": tr, "test": te, "method": meth})
            for meth, s in r["training (s)"].items():
                rows.append({"metric": f"training (s) [{g}: {tr}: {meth}]", "thesis": None, "sfanav": s, "garden": g})
        for case, rt in table[g].items():
            for m, v in rt.items():
                rows.append({"metric": f"ratio default / best peer, {m} [{g}: {case}]", "thesis": None, "sfanav": v,
                             "garden": g})
    summary = []
    for m in RATIO_METRICS:
        allv = [v[m] for g in table for v in table[g].values()]
        worst, med = float(max(allv)), float(np.median(allv))
        rows.append({"metric": f"worst ratio default / best peer, {m}", "thesis": None, "sfanav": worst,
                     "target": TARGET_WORST})
        rows.append({"metric": f"median ratio default / best peer, {m}", "thesis": None, "sfanav": med,
                     "target": TARGET_MEDIAN})
        summary.append(f"{m}: worst {worst:.2f}, median {med:.2f}")
    t_ratio = [r["training (s)"]["sfanav default"] / r["training (s)"]["thesis config"]
               for res in results.values() for r in res.values()]
    rows.append({"metric": "training time ratio default / thesis config (worst)", "thesis": None,
                 "sfanav": float(max(t_ratio)), "target": 2.0})
    plots = [str(plot_ratios(table, out / "gardens-suite-ratios.png"))]
    md = _markdown(results, table)
    (out / "gardens-suite.md").write_text(md + "\n")
    notes = (f"Gardens: {', '.join(f'suite-{g} (seed {seed + i})' for i, g in enumerate(names))}"
             + (" (quick: 60x8 panoramas, 50 frames per run, tiny networks; numbers not meaningful)" if quick else
                "; 350x40 RGB panoramas")
             + ". Ratios are default / best peer per metric (best peer: the better of perfect memory and the Fourier "
             f"signature on that metric); targets: worst <= {TARGET_WORST}, median <= {TARGET_MEDIAN}. "
             + "; ".join(summary) + f". Training time default / thesis config, worst: {max(t_ratio):.2f} (target 2). "
             f"Wall time {time.perf_counter() - t_all:.0f} s.\n\n" + md)
    return ExperimentResult("gardens-suite", rows, plots, notes)
