"""Evaluation of a :class:`~sfanav.landmarks.model.LandmarkLocalizer` on a
test run: the stacked readout's error, each marker's detection rate and its
own error where it was seen, the classic peers on panoramas of the same
frames, plots (marker visibility, Fig. 5.26 / 5.29; each marker's firing maps
and estimates, Fig. 5.27 / 5.30; the stacked estimates, Fig. 5.28 / 5.31)
and a Markdown report. :func:`landmark_rows` turns it into experiment rows."""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import as_matrix, check_same_length
from .._plotting import figure, save_figure
from .._progress import Log, quiet_log
from .._sampling import evenly_spaced
from ..localization import baselines
from ..localization.error_metrics import localization_metrics
from ..localization.evaluation import Evaluation, coordinate_range, write_evaluation_report
from ..localization.plots import plot_firing_maps, plot_trajectory
from ..localization.protocols import TEST_RUN
from .model import LandmarkLocalizer
from .views import MarkerViews

Region = tuple[tuple[float | None, float | None], tuple[float | None, float | None]]


@dataclass
class LandmarkEvaluation(Evaluation):
    """What :func:`evaluate_landmarks` measured: the fields of
    :class:`sfanav.localization.Evaluation` for the stacked readout
    (``metrics``, ``predictions``, ``baselines``, ``plots``, ``report``,
    ``model_bytes``) and, per marker:

    Attributes
    ----------
    markers : dict int -> dict
        ``"detection rate"`` (fraction of the test images it was found in),
        ``"n"`` (those images), ``"metrics"`` (its own readout's
        :func:`sfanav.localization.localization_metrics` on them; None when
        it was never found), ``"train detection rate"`` (None without the
        training views).
    """

    markers: dict[int, dict[str, Any]] = field(default_factory=dict)


def _model_bytes(loc: LandmarkLocalizer) -> int | None:
    import tempfile

    try:
        with tempfile.TemporaryDirectory(prefix="sfanav-") as tmp:
            path = Path(tmp) / "m.sfa"
            loc.save(path)
            return path.stat().st_size
    except (OSError, ValueError):  # pragma: no cover - size is informative only
        return None


def evaluate_landmarks(
    loc: LandmarkLocalizer,
    test_views: MarkerViews,
    test_xy: Any,
    *,
    train_views: MarkerViews | None = None,
    train_xy: Any = None,
    panoramas: tuple[np.ndarray, np.ndarray] | None = None,
    out: str | os.PathLike | None = None,
    prefix: str = "",
    title: str = "sfanav landmark localization report",
    regions: Mapping[int, Region] | None = None,
    marker_positions: Mapping[int, Sequence[float]] | None = None,
    text: Sequence[str] = (),
    log: Log = quiet_log,
    report: bool = True,
    baseline_queries: int | None = 1000,
) -> LandmarkEvaluation:
    """Evaluates a fitted landmark localizer on the views of a test run.

    Parameters
    ----------
    loc : LandmarkLocalizer
    test_views : MarkerViews
        ``loc.extractor.transform(test_images)``.
    test_xy : array (N, 2)
        True positions, metres.
    train_views, train_xy : optional
        The training run's views and positions: training detection rates,
        firing maps over the training positions (else the test run's), and
        the peers' memory (with ``panoramas``).
    panoramas : (train, test) arrays (N, H, W[, C]), optional
        Panoramas of the same frames for the peers (perfect memory, Fourier
        signature; needs ``train_xy``), answering at most
        ``baseline_queries`` test images evenly spaced over the run.
    out : path, optional
        Directory for the PNG plots (names start with ``prefix``) and, if
        ``report``, ``<prefix>report.md``.
    regions : dict marker id -> ((x_lo, x_hi), (y_lo, y_hi)), optional
        Occluded regions to draw on the visibility plot (None: unbounded).
    marker_positions : dict marker id -> (x, y), optional
        Where the markers stand, for the plots.

    Returns
    -------
    LandmarkEvaluation

    Raises
    ------
    ValueError
        For positions whose number does not match the views.

    Examples
    --------
    >>> V_tr, V_te = loc.extractor.transform(train_images), loc.extractor.transform(test_images)  # doctest: +SKIP
    >>> ev = evaluate_landmarks(loc, V_te, test_xy, train_views=V_tr, train_xy=train_xy,
    ...                         out="report")                                                     # doctest: +SKIP
    >>> ev.metrics["med"], ev.markers[136]["detection rate"]                                      # doctest: +SKIP
    (0.17, 0.99)
    """
    Y = as_matrix(test_xy, "test_xy", n_cols=2)
    check_same_length(test_views.found, Y, "test_views", "test_xy")
    if train_views is not None:
        if train_xy is None:
            raise ValueError("train_views need train_xy (the training positions)")
        Ytr = as_matrix(train_xy, "train_xy", n_cols=2)
        check_same_length(train_views.found, Ytr, "train_views", "train_xy")
    crange = coordinate_range(Y)
    t0 = time.perf_counter()
    pred = loc.predict_views(test_views)
    ms = 1000.0 * (time.perf_counter() - t0) / len(Y)
    m = localization_metrics(pred, Y, coordinate_range=crange)
    m["query_ms"] = ms  # views to position; detection and extraction are not included
    ev = LandmarkEvaluation(metrics=m, predictions=pred)
    ev.model_bytes = _model_bytes(loc)
    log(f"stacked readout: MED {m['med']:.3f} m on {len(Y)} test images")
    tr_rates = train_views.detection_rate() if train_views is not None else None
    for j, mid in enumerate(loc.ids):
        p, idx = loc.predict_marker(test_views, mid)
        mm = localization_metrics(p, Y[idx], coordinate_range=crange) if len(idx) else None
        ev.markers[mid] = {"detection rate": float(test_views.detection_rate()[j]), "n": int(len(idx)),
                           "metrics": mm, "predictions": p, "index": idx,
                           "train detection rate": None if tr_rates is None else float(tr_rates[j])}
        log(f"marker {mid}: found in {100 * ev.markers[mid]['detection rate']:.1f} % of the test images"
            + (f", its own readout MED {mm['med']:.3f} m there" if mm else ""))
    if panoramas is not None and train_views is not None:
        P_tr, P_te = panoramas
        q = np.arange(len(P_te))
        if baseline_queries is not None and len(q) > baseline_queries:
            q = evenly_spaced(len(q), int(baseline_queries))
        ev.baseline_queries = len(q)
        for name, model in (("perfect memory", baselines.PerfectMemory()),
                            ("Fourier signature", baselines.FourierSignature(min(15, P_tr.shape[2] // 2 + 1)))):
            model.fit(P_tr, Ytr)
            ev.baselines[name] = baselines.benchmark(model, P_te[q], Y[q], coordinate_range=crange)
            log(f"{name}: MED {ev.baselines[name]['med']:.3f} m on {len(q)} queries")
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        runs = [("test", test_views, Y)] + ([("training", train_views, Ytr)] if train_views is not None else [])
        ev.plots.append(("marker visibility: crosses where a marker was not found"
                         + (", dotted: its occluded region" if regions else ""),
                         plot_visibility(runs, out / f"{prefix}visibility.png", regions=regions,
                                         marker_positions=marker_positions)))
        map_views, map_xy = (train_views, Ytr) if train_views is not None else (test_views, Y)
        for mid in loc.ids:
            F, idx = loc.marker_features(map_views, mid)
            if len(idx):
                ev.plots.append((f"marker {mid}: firing maps of its four slowest outputs",
                                 plot_firing_maps(F, map_xy[idx], out / f"{prefix}firing-{mid}.png",
                                                  which=tuple(range(min(4, F.shape[1]))),
                                                  title=f"marker {mid}")))
            e = ev.markers[mid]
            if e["n"]:
                ev.plots.append((f"marker {mid}: its own estimates where it was found",
                                 plot_trajectory(Y[e["index"]], e["predictions"], out / f"{prefix}trajectory-{mid}.png",
                                                 connect=False, error_lines=True,
                                                 title=f"marker {mid}: MED {e['metrics']['med']:.2f} m")))
        ev.plots.append(("stacked readout: ground truth and estimates",
                         plot_trajectory(Y, pred, out / f"{prefix}trajectory-stacked.png", connect=False,
                                         error_lines=True, title=f"stacked: MED {m['med']:.2f} m")))
        if report:
            paras = list(text) + [marker_sentence(ev)]
            ev.report = write_evaluation_report(ev, out / f"{prefix}report.md", title=title, text=paras)
    return ev


def marker_sentence(ev: LandmarkEvaluation) -> str:
    """The per-marker results in one paragraph."""
    parts = []
    for mid, e in ev.markers.items():
        s = f"marker {mid}: found in {100 * e['detection rate']:.1f} % of the test images"
        if e["train detection rate"] is not None:
            s += f" ({100 * e['train detection rate']:.1f} % of the training images)"
        if e["metrics"] is not None:
            s += f", its own readout MED {e['metrics']['med']:.3f} m there"
        parts.append(s)
    return "Markers: " + "; ".join(parts) + f". Stacked readout: MED {ev.metrics['med']:.3f} m on every test image."


def landmark_rows(ev: LandmarkEvaluation, *, suffix: str = "", thesis: Mapping[str, Any] | None = None,
                  baselines_rows: bool = True) -> list[dict[str, Any]]:
    """Experiment rows with stable names: ``detection rate train (%) <id>``,
    ``detection rate test (%) <id>``, ``MED (m) marker <id>`` (its own
    readout where it was found), ``MED (m) stacked``, ``MAE x (%) stacked``,
    ``MAE y (%) stacked``, ``stacked / best single marker``, ``query ms``,
    ``model bytes``, and per peer ``MED (m) <name>``, ``bytes per place
    <name>``, ``query ms <name>``. ``suffix`` is appended to every name,
    ``thesis`` maps names (without it) to the thesis's values.

    Examples
    --------
    >>> rows = landmark_rows(ev, suffix=" [occlusion]", thesis={"MED (m) stacked": 0.32})   # doctest: +SKIP
    >>> [r for r in rows if r["metric"] == "MED (m) stacked [occlusion]"][0]["thesis"]      # doctest: +SKIP
    0.32
    """
    th = dict(thesis or {})
    rows: list[dict[str, Any]] = []

    def add(name: str, value: Any, **extra: Any) -> None:
        if isinstance(value, (np.floating, np.integer)):
            value = value.item()
        rows.append({"metric": name + suffix, "thesis": th.get(name), "sfanav": value, **extra})

    tr = {"protocol": TEST_RUN}
    for mid, e in ev.markers.items():
        if e["train detection rate"] is not None:
            add(f"detection rate train (%) {mid}", 100 * e["train detection rate"])
        add(f"detection rate test (%) {mid}", 100 * e["detection rate"])
    singles = []
    for mid, e in ev.markers.items():
        if e["metrics"] is not None:
            add(f"MED (m) marker {mid}", e["metrics"]["med"], **tr)
            singles.append(e["metrics"]["med"])
    add("MED (m) stacked", ev.metrics["med"], **tr)
    add("MAE x (%) stacked", ev.metrics["mae_x_pct"], **tr)
    add("MAE y (%) stacked", ev.metrics["mae_y_pct"], **tr)
    if singles:
        add("stacked / best single marker", ev.metrics["med"] / min(singles))
    add("query ms", float(ev.metrics["query_ms"]))
    if ev.model_bytes is not None:
        add("model bytes", int(ev.model_bytes))
    if baselines_rows:
        for name, b in ev.baselines.items():
            extra = {"protocol": TEST_RUN, "baseline": name}
            add(f"MED (m) {name}", b["med"], **extra)
            add(f"bytes per place {name}", b["bytes_per_place"], **extra)
            add(f"query ms {name}", b["query_ms"], **extra)
    return rows


def plot_visibility(runs: Sequence[tuple[str, MarkerViews, np.ndarray]], path: Any, *,
                    regions: Mapping[int, Region] | None = None,
                    marker_positions: Mapping[int, Sequence[float]] | None = None, dpi: int = 110) -> Path:
    """Marker visibility (thesis Fig. 5.26, 5.29): one row per run
    ``(name, views, xy (N, 2) metres)``, one column per marker; the
    trajectory as a line, crosses where the marker was not found, the
    marker's occluded region dotted (``regions``: marker id -> ((x_lo,
    x_hi), (y_lo, y_hi)), None unbounded, drawn to the plot's edge) and the
    marker itself as a star (``marker_positions``). Returns the PNG path.

    Examples
    --------
    >>> plot_visibility([("test", V_te, test_xy)], "visibility.png",
    ...                 regions={136: ((None, 0.0), (None, 0.0))})                   # doctest: +SKIP
    """
    ids = list(runs[0][1].ids)
    fig = figure(3.6 * len(ids), 3.4 * len(runs))
    axes = np.atleast_2d(fig.subplots(len(runs), len(ids), squeeze=False))
    every = np.concatenate([np.asarray(xy, float) for _, _, xy in runs])
    lo, hi = every.min(axis=0) - 0.5, every.max(axis=0) + 0.5  # unbounded regions end here
    for r, (name, views, xy) in enumerate(runs):
        xy = np.asarray(xy, float)
        for j, mid in enumerate(ids):
            ax = axes[r, j]
            miss = ~views.found[:, j]
            ax.plot(xy[:, 0], xy[:, 1], "-", color="tab:blue", lw=0.6)
            ax.plot(xy[miss, 0], xy[miss, 1], "x", color="tab:red", ms=4)
            if regions and mid in regions:
                (x0, x1), (y0, y1) = regions[mid]
                x0, x1 = lo[0] if x0 is None else x0, hi[0] if x1 is None else x1
                y0, y1 = lo[1] if y0 is None else y0, hi[1] if y1 is None else y1
                ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], ":", color="k", lw=1.2)
            if marker_positions and mid in marker_positions:
                mx, my = marker_positions[mid]
                ax.plot([mx], [my], "*", color="k", ms=10)
            ax.set_aspect("equal")
            ax.set_title(f"{name}: marker {mid}, found {100 * views.found[:, j].mean():.0f} %", fontsize="small")
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
    return save_figure(fig, path, dpi)
