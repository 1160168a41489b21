"""The corruption suite: localization from the images a robot actually sends
(JPEG, sensor noise, blur, exposure, gamma, vignetting, white balance, dead
pixels; :data:`sfanav.data.corruptions.CORRUPTIONS`), the sfanav default
beside the thesis's configuration and the peers (docs/robustness.md).

``corruptions``: in each garden (the ``demo`` garden, 600x60 panoramas
resized to the network's 350x40 as a robot's camera images are, and two of
the gardens suite's, 350x40), every corruption is applied

* **(a) to the test run only**: every model trained once on the clean
  exploration run (a robot that recorded its exploration losslessly and
  localizes from its compressed live stream), and
* **(b) to both runs**: every model trained again on the corrupted
  exploration run (a robot that records what it sends),

at the images' own resolution, before anything else (the seed fixes each
image's draw). Rows per garden, mode and corruption: the MED (m) of

* the **sfanav default** (robustness ``"standard"``: photometric
  normalisation, readout fitted on corrupted copies as well, network
  trained to ignore the corruptions at weight 0.25) fitted to ground truth,
  and **without ground truth** (positions learned from the run's odometry;
  its estimates moved into the world frame by the rigid transform fitted on
  the training run, for evaluation only), and that model's estimates
  **fused with the test run's odometry** (the product path: the EKF noise
  chosen on the training run, as ``sfanav localize --odometry``; where the
  test run has odometry), and the supervised default again
  **without the camera's gamma** taken out (``sfanav localize
  --no-camera-gamma``; test only: what the tracker does);
* the sfanav network with robustness ``"light"`` (no invariance training),
  ``"full"`` (invariance at weight 1) and ``"none"`` (the default before
  this study);
* the **thesis configuration** (Table 5.1 network, all rows, quadratic
  regression of 8 outputs);
* **perfect memory** (rotational image difference) and the **Fourier
  signature** (nearest neighbour), on the same images;

every sfanav model localizing a test run as ``sfanav localize`` does: the
camera's gamma estimated over the run so far and taken out of the camera's
pixels where the model holds the training run's reference
(:class:`sfanav.data.camera_gamma.CameraGamma`; the robustness ``"none"``
and thesis models have none). The ground-truth-free default and its fused
track are in both modes.

Summary rows give each sfanav row's worst ratio to its own clean MED and to
the best peer's MED on the same images, and the cost on clean images against
robustness ``"none"``; the targets (docs/robustness.md) are the default's: at most
1.2x its clean MED and 0.9x the best peer's on every corruption, at most
5 % cost on clean images. Mode (b) runs in the first garden only (every
model trained again per corruption), to keep the whole run near two hours.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from .. import sim
from ..data.camera_gamma import CameraGamma, predict_corrected
from ..data.corruptions import CORRUPTIONS, corrupt
from ..data.preprocessing import Preprocessing, Preprocessor
from ..data.sources import load_run
from ..localization import baselines
from ..localization.error_metrics import align, localization_metrics
from ..localization.localizer import Localizer
from ..localization.recipe import default_network, recipe_for
from ..odometry.fusion import fuse_images
from ..pipeline import train_localizer
from ..sfa.network import Network
from . import ExperimentResult, register
from .localization import progress_log, simulated, tiny_config

GARDENS = (("demo", "train", "test"), ("suite-inner", "train-grid", "test-walk"),
           ("suite-control", "train-grid", "test-walk"))
"""(preset, training run, test run) of the gardens measured."""
METHODS = ("sfanav default", "sfanav default, no ground truth", "sfanav robustness light", "sfanav robustness full",
           "sfanav robustness none", "thesis configuration", "perfect memory", "Fourier signature")
FUSED = "sfanav default, no ground truth, fused"
"""The product path: the ground-truth-free default's estimates of the test run fused with its odometry (EKF, the noise
chosen on the training run, as ``sfanav localize --odometry``), in both modes of a garden whose test run has odometry.
Not a model of its own: the same network and readout as the row before it."""
NO_GAMMA = "sfanav default, no camera gamma"
"""The supervised default localizing the test run without the camera's gamma taken out (``sfanav localize
--no-camera-gamma``), in the test-only mode: the same model as the default's row, the images as they are."""
ROWS = (METHODS[0], NO_GAMMA, *METHODS[1:2], FUSED, *METHODS[2:])
"""The rows of a garden's table, in order: the trained METHODS, the row without the camera's gamma and the fused track."""
SFANAV = ROWS[:7]
PEERS = ("perfect memory", "Fourier signature")
BOTH_RUNS_METHODS = ("sfanav default", "sfanav default, no ground truth", "sfanav robustness light",
                     "sfanav robustness full", "sfanav robustness none", "thesis configuration", "perfect memory",
                     "Fourier signature")
TARGET_CLEAN_RATIO, TARGET_PEER_RATIO, TARGET_CLEAN_COST = 1.2, 0.9, 1.05
QUICK_CORRUPTIONS = ("jpeg-90", "exposure-0.6")


def _med(pred: np.ndarray, xy: np.ndarray) -> float:
    return float(localization_metrics(pred, xy, coordinate_range=np.ones(2))["med"])


def _localize(model: Any, X: np.ndarray, native: np.ndarray, conform: Any) -> np.ndarray:
    """A model's estimates of a test run's images X in their order (``conform`` of the camera's images ``native``):
    an sfanav model as ``sfanav localize`` runs it (the camera's gamma taken out of the camera's pixels where the
    model holds the reference), an aligned one in the world frame, a peer plainly."""
    if isinstance(model, _Aligned):
        return model.frame.apply(_localize(model.loc, X, native, conform))
    if isinstance(model, Localizer):
        return predict_corrected(model, CameraGamma.for_localizer(model), X, source=native, conform=conform)
    return model.predict(X)


class _Aligned:
    """A localizer trained without ground truth, its estimates moved into the
    world frame by the rigid transform fitted on its training run
    (evaluation only)."""

    def __init__(self, loc: Localizer, X_tr: np.ndarray, xy_tr: np.ndarray) -> None:
        self.loc, self.frame = loc, align(loc.predict(X_tr), xy_tr)

    def fused(self, X: np.ndarray, native: np.ndarray, conform: Any,
              odometry: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The estimates (N, 2) of images X (``conform`` of the camera's ``native``) and their fused track's
        positions (N, 2) with the odometry (N, 3), both in the world frame: the product path."""
        est, fused = fuse_images(self.loc, X, odometry, source=native, conform=conform)
        return self.frame.apply(est), self.frame.apply(fused[:, :2])


def _train(methods: tuple[str, ...], X: np.ndarray, xy: np.ndarray, odometry: np.ndarray | None,
           elev: tuple[float, float], *, quick: bool, seed: int) -> tuple[dict[str, Any], dict[str, float]]:
    """The models of ``methods`` trained on one run (images as the network
    takes them, uint8) and their training times (s)."""
    h, w, c = X.shape[1:]

    def net(out: int = 12) -> Network:
        return Network(tiny_config(w, h, c, out=out)) if quick else default_network()

    models: dict[str, Any] = {}
    times: dict[str, float] = {}
    for m in methods:
        t0 = time.perf_counter()
        if m in SFANAV:
            robustness = {"sfanav robustness light": "light", "sfanav robustness full": "full",
                          "sfanav robustness none": "none"}.get(m)  # None: the default's
            recipe = recipe_for(robustness=robustness, rows="all" if quick else None)  # quick: 8-row images
            if m == "sfanav default, no ground truth":
                if odometry is None:
                    continue
                loc = train_localizer(X, odometry=odometry, supervision="odometry", network=net(), recipe=recipe,
                                      camera_elevation=elev, seed=seed)
                models[m] = _Aligned(loc, X, xy)
            else:
                models[m] = train_localizer(X, xy=xy, network=net(), recipe=recipe, camera_elevation=elev, seed=seed)
        elif m == "thesis configuration":
            tnet = Network(tiny_config(w, h, c, out=8)) if quick else Network.from_preset("thesis-5.1",
                                                                                          precision="mixed")
            models[m] = train_localizer(X, xy=xy, network=tnet, recipe=recipe_for("thesis-5.1"))
        elif m == "perfect memory":
            models[m] = baselines.PerfectMemory().fit(X, xy)
        else:
            k = baselines.FourierSignature().n_coefficients
            models[m] = baselines.FourierSignature(min(k, w // 2 + 1)).fit(X, xy)
        times[m] = time.perf_counter() - t0
    return models, times


def run_garden(out: Path, preset: str, train_run: str, test_run: str, *, quick: bool, seed: int, progress: bool,
               both_runs: bool, corruptions: tuple[str, ...]) -> dict[str, Any]:
    """One garden: ``{"test only": {corruption: {method: MED}}, "both runs":
    {...}, "training (s)": {...}}``."""
    log = progress_log(progress)
    if quick:
        ds = simulated(out, preset, seed, quick=True, camera=sim.PanoramicCamera(60, 8), max_frames=60,
                       progress=progress)
    else:
        ds = simulated(out, preset, seed, quick=False, progress=progress)
    cam = ds.metadata["camera"]
    elev = tuple(cam.get("elevation_deg", (-30.0, 20.0)))
    native = Preprocessing(int(cam["width"]), int(cam["height"]), False)
    train, test = ds.select(run=train_run), ds.select(run=test_run)
    X0_tr, xy_tr = load_run(train, native)
    X0_te, xy_te = load_run(test, native)
    odometry = train.odometry if train.has_odometry else None
    odometry_test = test.odometry if test.has_odometry else None
    prep = Preprocessing(X0_tr.shape[2], X0_tr.shape[1], False) if quick else Preprocessing.for_network(
        default_network())
    conform = Preprocessor(prep, log=lambda *a, **k: None)

    def camera(X0: np.ndarray, name: str, draw: int) -> np.ndarray:
        return X0 if name == "clean" else corrupt(X0, name, seed=seed + draw)

    def images(X0: np.ndarray, name: str, draw: int) -> np.ndarray:
        return conform(camera(X0, name, draw))

    def localized(models: dict[str, Any], name: str) -> tuple[dict[str, float], np.ndarray]:
        """Every model's MED on the test run under corruption ``name`` (the ground-truth-free model's estimates and,
        where the test run has odometry, its fused track from one localization), and the test images."""
        N_te = camera(X0_te, name, 1)
        X_te = conform(N_te)
        r = {}
        for m, model in models.items():
            if isinstance(model, _Aligned) and odometry_test is not None:  # the product path
                est, fused = model.fused(X_te, N_te, conform, odometry_test)
                r[m], r[FUSED] = _med(est, xy_te), _med(fused, xy_te)
            else:
                r[m] = _med(_localize(model, X_te, N_te, conform), xy_te)
        return r, X_te

    res: dict[str, Any] = {"test only": {}, "both runs": {}, "training (s)": {}}
    X_tr = images(X0_tr, "clean", 0)
    models, times = _train(METHODS, X_tr, xy_tr, odometry, elev, quick=quick, seed=seed)
    res["training (s)"] = times
    for name in ("clean",) + corruptions:
        r, X_te = localized(models, name)
        if CameraGamma.for_localizer(models["sfanav default"]) is not None:  # what the tracker does
            r[NO_GAMMA] = _med(models["sfanav default"].predict(X_te), xy_te)
        res["test only"][name] = r = {m: r[m] for m in ROWS if m in r}
        log(f"{preset} test only {name}: " + ", ".join(f"{m} {v:.3f}" for m, v in r.items()))
    if both_runs:
        for name in ("clean",) + corruptions:
            if name == "clean":
                res["both runs"][name] = {m: v for m, v in res["test only"]["clean"].items()
                                          if m in BOTH_RUNS_METHODS or m == FUSED}
                continue
            ms, _ = _train(BOTH_RUNS_METHODS, images(X0_tr, name, 2), xy_tr, odometry, elev, quick=quick, seed=seed)
            r, _ = localized(ms, name)
            res["both runs"][name] = r = {m: r[m] for m in ROWS if m in r}
            log(f"{preset} both runs {name}: " + ", ".join(f"{m} {v:.3f}" for m, v in r.items()))
    return res


def summarize(table: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    """Per sfanav row of one garden and mode ({corruption: {method: MED}}):
    the worst ratio to its own clean MED, the worst ratio to the best peer
    on the same images, and its clean MED over robustness ``"none"``'s."""
    clean = table["clean"]
    out: dict[str, dict[str, float]] = {}
    for m in SFANAV:
        if m not in clean:
            continue
        vs_clean = [r[m] / clean[m] for n, r in table.items() if n != "clean" and m in r]
        vs_peer = [r[m] / min(r[p] for p in PEERS) for r in table.values() if m in r]
        out[m] = {"worst / clean": max(vs_clean, default=float("nan")),
                  "worst / best peer": max(vs_peer, default=float("nan"))}
        if "sfanav robustness none" in clean:
            out[m]["clean / robustness none"] = clean[m] / clean["sfanav robustness none"]
    return out


def plot_corruptions(results: dict[str, Any], path: Path) -> Path:
    """One panel per garden and mode: the MED of every row per corruption (log scale)."""
    from .._plotting import figure, save_figure

    panels = [(g, mode) for g, r in results.items() for mode in ("test only", "both runs") if r[mode]]
    fig = figure(11, 3.0 * len(panels))
    styles = {"sfanav default": ("C0", "o", 2.2), "sfanav default, no ground truth": ("C0", "s", 1.2),
              FUSED: ("C0", "*", 1.8), NO_GAMMA: ("C0", "d", 1.0),
              "sfanav robustness light": ("C9", "<", 1.0),
              "sfanav robustness full": ("C2", "^", 1.2), "sfanav robustness none": ("C7", "v", 1.0),
              "thesis configuration": ("C3", "x", 1.0), "perfect memory": ("C1", "D", 1.0),
              "Fourier signature": ("C4", "P", 1.0)}
    for k, (g, mode) in enumerate(panels):
        ax = fig.add_subplot(len(panels), 1, k + 1)
        table = results[g][mode]
        names = list(table)
        for m, (col, mk, lw) in styles.items():
            ys = [table[n].get(m, np.nan) for n in names]
            if np.all(np.isnan(ys)):
                continue
            ax.plot(range(len(names)), np.clip(ys, 1e-3, 1e3), color=col, marker=mk, lw=lw, ms=4, label=m)
        ax.set_yscale("log")
        ax.set_ylabel("MED (m)")
        ax.set_title(f"{g}: corruption applied to {'the test run only' if mode == 'test only' else 'both runs'}",
                     fontsize=9)
        ax.set_xticks(range(len(names)))
        ax.set_xticklabels(names, rotation=40, ha="right", fontsize=7)
        ax.grid(True, which="both", alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7, ncol=4)
    return save_figure(fig, path, 110)


def _cell(v: float | None) -> str:
    """A MED cell: 3 decimals; the thesis's quadratic regression, extrapolating far off its training
    features, reaches kilometres and more: shown as '> 1 km' rather than as a figure."""
    if v is None:
        return "-"
    return f"{v:.3f}" if v < 1000 else "> 1 km"


def markdown(results: dict[str, Any]) -> str:
    """The results as Markdown tables (one per garden and mode: MED per
    corruption and row, and the summary ratios), for docs/robustness.md."""
    parts = []
    for g, r in results.items():
        for mode in ("test only", "both runs"):
            table = r[mode]
            if not table:
                continue
            methods = [m for m in ROWS if m in table["clean"]]
            parts.append(f"**{g}, corruption applied to {'the test run only' if mode == 'test only' else 'both runs'}**"
                         " (MED, m)\n")
            parts.append("| corruption | " + " | ".join(methods) + " |")
            parts.append("|---" * (len(methods) + 1) + "|")
            for n, row in table.items():
                parts.append(f"| {n} | " + " | ".join(_cell(row.get(m)) for m in methods) + " |")
            s = summarize(table)
            parts.append("")
            parts.append("| | " + " | ".join(s) + " |")
            parts.append("|---" * (len(s) + 1) + "|")
            for key in ("worst / clean", "worst / best peer", "clean / robustness none"):
                parts.append(f"| {key} | " + " | ".join(f"{v.get(key, float('nan')):.2f}" for v in s.values()) + " |")
            parts.append("")
    return "\n".join(parts)


def results_from_rows(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The per-garden tables ``{garden: {mode: {corruption: {method: MED}}}}``
    back from the experiment's JSON rows (``corruptions.json``), e.g. to redo
    the Markdown tables of a finished run: ``markdown(results_from_rows(json.load(f)["rows"]))``."""
    out: dict[str, Any] = {}
    for r in rows:
        if r["metric"].startswith("MED (m) [") and "corruption" in r:
            g = out.setdefault(r["garden"], {"test only": {}, "both runs": {}})
            g[r["mode"]].setdefault(r["corruption"], {})[r["method"]] = r["sfanav"]
    return out


@register("corruptions", "Corruption suite: JPEG, noise, blur, exposure, ... in the test run and in both runs")
def exp_corruptions(out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    t_start = time.perf_counter()
    corruptions = QUICK_CORRUPTIONS if quick else tuple(CORRUPTIONS)
    gardens = GARDENS[:1] if quick else GARDENS
    results: dict[str, Any] = {}
    for k, (preset, tr, te) in enumerate(gardens):
        results[preset] = run_garden(out, preset, tr, te, quick=quick, seed=seed, progress=progress,
                                     both_runs=k == 0, corruptions=corruptions)
    rows: list[dict[str, Any]] = []
    targets: dict[str, bool] = {}
    for g, r in results.items():
        for mode in ("test only", "both runs"):
            for n, row in r[mode].items():
                for m, v in row.items():
                    rows.append({"metric": f"MED (m) [{g}, {mode}, {n}, {m}]", "thesis": None, "sfanav": v,
                                 "garden": g, "mode": mode, "corruption": n, "method": m})
            if not r[mode]:
                continue
            for m, s in summarize(r[mode]).items():
                for key, v in s.items():
                    rows.append({"metric": f"{key} [{g}, {mode}, {m}]", "thesis": None, "sfanav": v,
                                 "garden": g, "mode": mode, "method": m})
            s = summarize(r[mode]).get("sfanav default", {})
            if s:
                targets[f"{g}, {mode}: default <= {TARGET_CLEAN_RATIO}x its clean MED on every corruption"] = (
                    s["worst / clean"] <= TARGET_CLEAN_RATIO)
                targets[f"{g}, {mode}: default <= {TARGET_PEER_RATIO}x the best peer on every corruption"] = (
                    s["worst / best peer"] <= TARGET_PEER_RATIO)
        s = summarize(r["test only"]).get("sfanav default", {})
        if "clean / robustness none" in s:
            targets[f"{g}: default's clean MED <= {TARGET_CLEAN_COST}x robustness none's"] = (
                s["clean / robustness none"] <= TARGET_CLEAN_COST)
        for m, v in r["training (s)"].items():
            rows.append({"metric": f"training (s) [{g}, {m}]", "thesis": None, "sfanav": v, "garden": g,
                         "method": m})
    plot = plot_corruptions(results, out / "corruptions.png")
    (out / "corruptions.md").write_text(markdown(results) + "\n")
    wall = time.perf_counter() - t_start
    notes = (f"Gardens {', '.join(g for g, _, _ in gardens)} (seed {seed}); corruptions applied at the images' own "
             f"resolution before resizing, to the test run only and (first garden) to both runs. MED in metres. "
             f"Wall time {wall:.0f} s. Tables: {out / 'corruptions.md'}.")
    return ExperimentResult("corruptions", rows, [str(plot)], notes, targets=targets,
                            figures={"MED per corruption": plot}, details={"results": results})
