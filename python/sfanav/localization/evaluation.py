"""Evaluation of a trained localizer on a test run, beside the classic
baselines: :func:`evaluate` returns an :class:`Evaluation` (errors, timings,
model and memory sizes, baselines); :func:`evaluation_rows` and
:func:`metrics_json` turn it into experiment rows and JSON;
:func:`write_evaluation_report` writes it as Markdown."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._progress import Log, quiet_log
from .._sampling import evenly_spaced
from ..sfa.diagnostics import eta_values, orientation_angles, plot_eta
from . import baselines
from .error_metrics import align, localization_metrics
from .localizer import Localizer
from .plots import plot_firing_maps, plot_trajectory
from .protocols import (
    RANDOM_SPLITS,
    TEST_RUN,
    RegressionResult,
    error_vs_n,
    evaluate_random_splits,
)
from .report import write_report
from .signature_readout import SignatureGPReadout
from .trajectory_metrics import trajectory_errors


@dataclass
class Evaluation:
    """What :func:`evaluate` measured.

    Attributes
    ----------
    metrics : dict
        Test-run metrics of the SFA localizer
        (:func:`sfanav.localization.localization_metrics`, metres and %), plus
        ``query_ms`` per image and evo's trajectory errors ``ape_rmse`` (m,
        after a rigid alignment on the run) and ``rpe_rmse`` (m per frame;
        :func:`sfanav.localization.trajectory_metrics.trajectory_errors`).
    splits : RegressionResult or None
        The thesis 5.1.1 protocol on the test run's features: random 50/50
        splits, 100 repeats (optimistic on a continuous walk).
    eta_p, eta_phi : ndarray or None
        Per output (the first ``n_eta``), on the training views under all
        simulated rotations (thesis 3.5) if a training run was given, else on
        the test run normalised by each output's variance.
    curve, curve_splits : ErrorCurve or None
        Error against the number of outputs: training run -> test run, and
        random splits of the test run.
    baselines : dict
        ``"perfect memory"`` and ``"Fourier signature"`` ->
        :func:`sfanav.localization.benchmark` results (metrics, ``query_ms``,
        ``bytes_per_place``).
    predictions : ndarray (N, 2)
        Test-run estimates, metres (in the world frame).
    plots : list of (caption, path)
    report : Path or None
    frame_alignment : Alignment or None
        For a localizer trained without ground truth: the rigid transform
        (fitted on the training run, for evaluation only) that moved its
        estimates from its odometry frame into the world frame.
    """

    metrics: dict[str, Any]
    splits: Any = None
    eta_p: np.ndarray | None = None
    eta_phi: np.ndarray | None = None
    eta_source: str = ""
    curve: Any = None
    curve_splits: Any = None
    baselines: dict[str, dict[str, Any]] = field(default_factory=dict)
    predictions: np.ndarray | None = None
    plots: list[tuple[str, Path]] = field(default_factory=list)
    report: Path | None = None
    model_bytes: int | None = None
    baseline_queries: int = 0
    frame_alignment: Any = None


def coordinate_range(xy: np.ndarray) -> np.ndarray:
    """Range per axis (m) for MAE %: max - min, or, along an axis without
    extent (a straight run), the other axis's range (1 m if both are 0)."""
    rng = np.ptp(np.asarray(xy, dtype=float), axis=0)
    return np.where(rng > 0, rng, max(float(rng.max()), 1.0))


def _model_bytes(loc: Localizer) -> int | None:
    import tempfile

    try:
        with tempfile.TemporaryDirectory(prefix="sfanav-") as tmp:
            path = Path(tmp) / "m.sfa"
            loc.save(path)
            return path.stat().st_size
    except Exception:  # pragma: no cover - size is informative only
        return None


def evaluate(
    loc: Localizer,
    test_images: np.ndarray,
    test_xy: np.ndarray,
    *,
    train_images: np.ndarray | None = None,
    train_xy: np.ndarray | None = None,
    out: str | os.PathLike | None = None,
    prefix: str = "",
    title: str = "sfanav localization report",
    run_baselines: bool = True,
    n_eta: int = 8,
    n_repeats: int = 100,
    seed: int = 0,
    text: Sequence[str] = (),
    log: Log = quiet_log,
    report: bool = True,
    baseline_queries: int | None = 1000,
) -> Evaluation:
    """Evaluates a fitted localizer on a test run (``test_images`` in the
    network's input format, ``test_xy`` (N, 2) metres).

    With the training run (``train_images``, ``train_xy``) it also computes
    eta on the training views, the train -> test error curve and the
    baselines (fitted on the training run). With ``out`` it writes PNG plots
    (firing maps, trajectory, error vs n, eta; names start with ``prefix``)
    and, if ``report``, ``<prefix>report.md``.

    The baselines answer at most ``baseline_queries`` test images, evenly
    spaced over the run (perfect memory compares every query with every
    stored view under every rotation: on 5900 stored 600x60 views a query
    takes seconds); ``Evaluation.baseline_queries`` records how many.
    """
    net = loc.trained_network()
    n_out = net.n_outputs_
    raw_test, raw_train = test_images, train_images  # the baselines see the panoramas as they are
    # the network sees the images as the localizer hands them on (photometric normalisation, rows)
    test_images = loc.network_input(test_images)
    train_images = None if train_images is None else loc.network_input(train_images)
    t0 = time.perf_counter()
    F_test = loc.transform_rows(test_images)  # rotation pooled if the localizer pools
    sfa_ms = 1000.0 * (time.perf_counter() - t0) / len(test_images)
    G_test = loc.signatures(raw_test) if loc.n_signature_ else None
    pred = loc.predict_features(F_test, signatures=G_test)
    frame = None
    if loc.info.get("supervision") == "odometry":
        # trained without ground truth: its frame is the training run's odometry; for evaluation only, move the
        # estimates into the world frame by the rigid transform fitted on the training run
        if train_images is None or train_xy is None:
            raise ValueError("this localizer was trained without ground truth (it reports in its training run's "
                             "odometry frame): evaluating it needs the training run with ground truth, to align "
                             "the frames")
        frame = align(loc.predict_features(loc.transform_rows(train_images), signatures=(
            loc.signatures(raw_train) if loc.n_signature_ else None)), np.asarray(train_xy, float))
        pred = frame.apply(pred)
        log(f"trained without ground truth: estimates moved into the world frame by the rigid transform fitted on "
            f"the training run (rms {frame.rmse:.3f} m; evaluation only)")
    crange = coordinate_range(test_xy)
    m = localization_metrics(pred, test_xy, coordinate_range=crange)
    m["query_ms"] = sfa_ms
    try:  # the trajectory errors as evo defines them (APE after a rigid alignment on this run, RPE per frame)
        te = trajectory_errors(pred, test_xy)
        m["ape_rmse"], m["rpe_rmse"] = te["ape_rmse"], te["rpe_rmse"]
    except ValueError:  # fewer than 2 frames, or every estimate at one point: no alignment
        pass
    ev = Evaluation(metrics=m, predictions=pred, frame_alignment=frame)
    ev.model_bytes = _model_bytes(loc)
    n_reg = loc.n_outputs_
    spec = loc.readout_spec_
    log(f"test run: MED {m['med']:.3f} m, MAE x {m['mae_x_pct']:.2f} %, y {m['mae_y_pct']:.2f} % "
        f"(readout {loc.describe_readout()})")
    if len(test_xy) >= 8:
        try:
            if spec["kind"] == "quadratic":
                ev.splits = evaluate_random_splits(F_test, test_xy, n_outputs=n_reg,
                                                              ridge=float(spec.get("ridge", 0.0)),
                                                              n_repeats=n_repeats, random_state=seed)
            else:
                ev.splits = random_splits_readout(spec, loc.readout_features(F_test, G_test), test_xy,
                                                  n_repeats=n_repeats, seed=seed)
        except ValueError as exc:  # too few samples for the expansion
            log(f"random splits skipped: {exc}")
    ns = range(2, n_out + 1)
    n_eta = min(n_eta, n_out)
    rot_angles = None
    R = None
    if train_images is not None and train_xy is not None:
        R = net.transform(train_images, rotations=True)
        ep, ef = eta_values(R[:, :, :n_eta])
        ev.eta_source = "training views under all simulated rotations (thesis 3.5)"
        F_train = loc.transform_rows(train_images)
        ev.curve = error_vs_n(F_train, train_xy, F_test, test_xy, ns=ns)
        map_xy = train_xy
    else:
        R = net.transform(test_images, rotations=True)
        ep, ef = eta_values(R[:, :, :n_eta], normalize=True)
        ev.eta_source = "test views under all simulated rotations, normalised by each output's variance"
        map_xy = test_xy
    ev.eta_p, ev.eta_phi = ep, ef
    step = net.step_
    period = net.period_ or test_images.shape[2]
    rot_angles = orientation_angles(R.shape[1], step=step, width=period) if step else None
    try:
        ev.curve_splits = error_vs_n(F_test, test_xy, ns=ns, n_repeats=n_repeats, random_state=seed)
    except ValueError as exc:
        log(f"random-split error curve skipped: {exc}")
    if run_baselines and train_images is not None and train_xy is not None:
        q = np.arange(len(test_images))
        if baseline_queries is not None and len(q) > baseline_queries:
            q = evenly_spaced(len(q), int(baseline_queries))
        ev.baseline_queries = len(q)
        Xq, Yq = raw_test[q], test_xy[q]
        for name, model in (("perfect memory", baselines.PerfectMemory()),
                            ("Fourier signature", baselines.FourierSignature())):
            k = getattr(model, "n_coefficients", None)
            if k is not None and k > raw_train.shape[2] // 2 + 1:
                model = baselines.FourierSignature(raw_train.shape[2] // 2 + 1)
            model.fit(raw_train, train_xy)
            ev.baselines[name] = baselines.benchmark(model, Xq, Yq, coordinate_range=crange)
            b = ev.baselines[name]
            log(f"{name}: MED {b['med']:.3f} m on {len(q)} queries, {b['query_ms']:.2f} ms per query, "
                f"{b['bytes_per_place']} bytes per place")
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        which = tuple(range(min(4, n_out)))
        ev.plots.append(("spatial firing maps of the slowest outputs at four relative orientations",
                         plot_firing_maps(R, map_xy, out / f"{prefix}firing_maps.png", which=which,
                                                   angles=rot_angles)))
        ev.plots.append(("test run: ground truth and estimates",
                         plot_trajectory(test_xy, pred, out / f"{prefix}trajectory.png", connect=False,
                                                  error_lines=True)))
        curve = ev.curve or ev.curve_splits
        if curve is not None:
            ev.plots.append((f"error vs number of outputs ({curve.protocol})", curve.plot(out / f"{prefix}error_vs_n.png")))
        ev.plots.append(("eta_p and eta_phi per output", plot_eta(ep, ef, out / f"{prefix}eta.png")))
        if report:
            ev.report = write_evaluation_report(ev, out / f"{prefix}report.md", title=title, text=text)
    return ev


def random_splits_readout(spec: dict[str, Any], features: np.ndarray, xy: np.ndarray, *, n_repeats: int = 100,
                          seed: int = 0) -> Any:
    """The thesis 5.1.1 protocol (random 50/50 splits of one run, mean over
    ``n_repeats``) with any readout ``spec`` (:func:`sfanav.localization.make_readout`;
    its hyperparameters as chosen on the training run; a Gaussian process
    learns its kernel on the first split and keeps it for the others). Returns a
    :class:`sfanav.localization.RegressionResult`; optimistic on a continuous walk."""
    from .readouts import make_readout

    F = np.asarray(features, float)
    Y = np.asarray(xy, float)
    crange = coordinate_range(Y)
    rng = np.random.default_rng(seed)
    ms, tms = [], []
    pred_sum = np.zeros_like(Y)
    count = np.zeros(len(Y))
    first = None
    for _ in range(n_repeats):
        perm = rng.permutation(len(F))
        tr, te = perm[: len(F) // 2], perm[len(F) // 2 :]
        r = make_readout(spec)
        if isinstance(r, SignatureGPReadout) and first is not None:
            r.fit(F[tr], Y[tr], hyperparameters_from=first)  # kernel learned once: 100 optimisations cost minutes
        else:
            r.fit(F[tr], Y[tr])
            first = r
        p = r.predict(F[te])
        ms.append(localization_metrics(p, Y[te], coordinate_range=crange))
        tms.append(localization_metrics(r.predict(F[tr]), Y[tr], coordinate_range=crange))
        pred_sum[te] += p
        count[te] += 1
    keys = [k for k in ms[0] if isinstance(ms[0][k], (int, float))]
    mean = {k: float(np.mean([d[k] for d in ms])) for k in keys}
    std = {k: float(np.std([d[k] for d in ms])) for k in keys}
    tmean = {k: float(np.mean([d[k] for d in tms])) for k in keys}
    with np.errstate(invalid="ignore", divide="ignore"):
        pred = pred_sum / count[:, None]
    from .readouts import describe_spec

    return RegressionResult(
        protocol=RANDOM_SPLITS,
        description=f"random 50/50 splits of one run with readout {describe_spec(spec)}, {n_repeats} repeats "
                    "(thesis 5.1.1 protocol; optimistic on a continuous walk)",
        n_outputs=int(spec.get("n_outputs", F.shape[1])), ridge=float(spec.get("ridge", 0.0)), metrics=mean,
        metrics_std=std, train_metrics=tmean, predictions=pred, n_repeats=n_repeats)


def _fmt_list(a: np.ndarray) -> str:
    return ", ".join(f"{v:.3f}" for v in a)


def write_evaluation_report(ev: Evaluation, path: Path, *, title: str, text: Sequence[str] = ()) -> Path:
    """A Markdown report of an :class:`Evaluation`: metrics table (SFA on the
    test run, random splits, baselines), eta values, error curve, plots."""
    rows: dict[str, Any] = {"sfanav (test run)": {"protocol": TEST_RUN, **ev.metrics,
                                                  "bytes_per_place": None}}
    if ev.splits is not None:
        rows["sfanav (random 50/50 splits of the test run)"] = ev.splits
    for name, b in ev.baselines.items():
        rows[f"{name} (test run)"] = {"protocol": TEST_RUN, **b}
    paras = list(text)
    if ev.eta_p is not None:
        paras.append(f"eta values on the {ev.eta_source}: eta_p = [{_fmt_list(ev.eta_p)}], "
                     f"eta_phi = [{_fmt_list(ev.eta_phi)}] (ideal: 1 and 0).")
    if ev.curve is not None:
        paras.append(f"Best number of outputs, training run -> test run: n = {ev.curve.best_n} "
                     f"(MED {ev.curve.test_error.min():.3f} m).")
    if ev.curve_splits is not None:
        paras.append(f"Best number of outputs, random splits of the test run: n = {ev.curve_splits.best_n}.")
    paras.append("Protocols: *test run* fits the regression on the training run and measures on the separate "
                 "test run (the honest figure); *random splits* fits and measures on halves of the test run "
                 "(thesis 5.1.1), optimistic on a continuous walk. Memory per place: the baselines store every "
                 f"training view; the SFA model has a fixed size ({ev.model_bytes} bytes) whatever the number "
                 "of places." + (f" The baselines answered {ev.baseline_queries} of the {ev.metrics['n']} test images "
                                  "(evenly spaced)." if ev.baselines and ev.baseline_queries < ev.metrics["n"] else ""))
    return write_report(
        path, title=title, metrics=rows,
        columns=["protocol", "med", "mae_x", "mae_y", "mae_x_pct", "mae_y_pct", "p90", "query_ms", "bytes_per_place"],
        figures=ev.plots, text=paras,
    )


def _row(metric: str, thesis: Any, value: Any, **extra: Any) -> dict[str, Any]:
    if isinstance(value, (np.floating, np.integer)):
        value = value.item()
    return {"metric": metric, "thesis": thesis, "sfanav": value, **extra}


def evaluation_rows(ev: Evaluation, *, suffix: str = "", thesis: dict[str, Any] | None = None,
                    baselines_rows: bool = True) -> list[dict[str, Any]]:
    """The experiment table's rows for one evaluation, with stable names:

    ``MAE x (%)``, ``MAE y (%)``, ``MAE x (m)``, ``MAE y (m)``, ``MED (m)``
    (test run), the same with `` (random splits)``, ``max eta_phi (outputs
    1-8)``, ``eta_phi s1``, ``eta_phi s8``, ``min eta_p (outputs 1-8)``,
    ``best n``, ``best n (random splits)``, ``query ms``, ``model bytes``,
    and per baseline ``MED (m) <name>``, ``MAE x (%) <name>``, ``MAE y (%)
    <name>``, ``bytes per place <name>``, ``query ms <name>``. ``suffix`` is
    appended to every name (e.g. `` indoor I``); ``thesis`` maps names
    (without the suffix) to the thesis's values."""
    th = thesis or {}
    rows: list[dict[str, Any]] = []

    def add(name: str, value: Any, **extra: Any) -> None:
        rows.append(_row(name + suffix, th.get(name), value, **extra))

    m = ev.metrics
    tr = {"protocol": TEST_RUN}
    add("MAE x (%)", m["mae_x_pct"], **tr)
    add("MAE y (%)", m["mae_y_pct"], **tr)
    add("MAE x (m)", m["mae_x"], **tr)
    add("MAE y (m)", m["mae_y"], **tr)
    add("MED (m)", m["med"], **tr)
    if ev.splits is not None:
        s = ev.splits.metrics
        rs = {"protocol": RANDOM_SPLITS}
        add("MAE x (%) (random splits)", s["mae_x_pct"], **rs)
        add("MAE y (%) (random splits)", s["mae_y_pct"], **rs)
        add("MED (m) (random splits)", s["med"], **rs)
    if ev.eta_phi is not None:
        k = len(ev.eta_phi)
        add(f"max eta_phi (outputs 1-{k})", float(ev.eta_phi.max()))
        add("eta_phi s1", float(ev.eta_phi[0]))
        add(f"eta_phi s{k}", float(ev.eta_phi[-1]))
        add(f"min eta_p (outputs 1-{k})", float(ev.eta_p.min()))
    if ev.curve is not None:
        add("best n", int(ev.curve.best_n), **tr)
    if ev.curve_splits is not None:
        add("best n (random splits)", int(ev.curve_splits.best_n), protocol=RANDOM_SPLITS)
    add("query ms", float(m["query_ms"]))
    if ev.model_bytes is not None:
        add("model bytes", int(ev.model_bytes))
    if baselines_rows:
        for name, b in ev.baselines.items():
            extra = {"protocol": TEST_RUN, "baseline": name}
            add(f"MED (m) {name}", b["med"], **extra)
            add(f"MAE x (%) {name}", b["mae_x_pct"], **extra)
            add(f"MAE y (%) {name}", b["mae_y_pct"], **extra)
            add(f"bytes per place {name}", b["bytes_per_place"], **extra)
            add(f"query ms {name}", b["query_ms"], **extra)
    return rows


def metrics_json(ev: Evaluation) -> dict[str, Any]:
    """The evaluation as a JSON-able dict."""

    def clean(d: dict[str, Any]) -> dict[str, Any]:
        return {k: (v.item() if isinstance(v, (np.floating, np.integer)) else v) for k, v in d.items()}

    out: dict[str, Any] = {"test_run": clean(ev.metrics)}
    if ev.frame_alignment is not None:
        out["frame_alignment"] = {"kind": "rigid, fitted on the training run (evaluation only)",
                                  "rotation": ev.frame_alignment.rotation.tolist(),
                                  "translation": ev.frame_alignment.translation.tolist(),
                                  "rms_m": float(ev.frame_alignment.rmse)}
    if ev.splits is not None:
        out["random_splits"] = clean(ev.splits.metrics)
    if ev.eta_p is not None:
        out["eta_p"] = ev.eta_p.tolist()
        out["eta_phi"] = ev.eta_phi.tolist()
        out["eta_source"] = ev.eta_source
    if ev.curve is not None:
        out["error_vs_n"] = {"ns": ev.curve.ns.tolist(), "train": ev.curve.train_error.tolist(),
                             "test": ev.curve.test_error.tolist(), "best_n": ev.curve.best_n}
    out["baselines"] = {k: clean(v) for k, v in ev.baselines.items()}
    out["baseline_queries"] = ev.baseline_queries
    out["plots"] = [str(p) for _, p in ev.plots]
    out["model_bytes"] = ev.model_bytes
    return json.loads(json.dumps(out, default=float))
