"""Thesis 5.4 on the built-in simulator: landmark-based SFA localization.

* ``5.4``: the 16x18 m garden with ArUco markers 136 and 144 (sim presets
  ``thesis-5.4-landmarks`` and ``thesis-5.4-occlusion``), 1000x1000
  omnidirectional images; one ``landmark-120`` network per marker on its
  120x120 views aligned by polar angle, each marker's own quadratic readout,
  and the quadratic readout of the stacked 8 slowest outputs of both with a
  "found" flag each. Beside it, on panoramas unwarped from the same frames:
  the whole-image model (the thesis configuration: Table 5.2 network, 600x60,
  5 px simulated rotation, quadratic readout; and the sfanav default) and the
  peers (perfect memory, Fourier signature). Then the occlusion variant:
  marker 136 covered where x < 0 and y < 0, marker 144 where x > 0 and y > 0.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from .. import sim
from ..landmarks.evaluation import evaluate_landmarks, landmark_rows
from ..landmarks.model import LandmarkLocalizer
from ..landmarks.views import MarkerViews, ViewExtractor
from ..localization.error_metrics import localization_metrics
from ..localization.evaluation import coordinate_range
from ..localization.plots import plot_trajectory
from ..localization.readouts import make_readout
from ..localization.recipe import recipe_for
from ..pipeline import train_localizer
from ..sfa.network import Network
from ..sim.presets import LANDMARK_MARKERS
from . import ExperimentResult, register
from .localization import progress_log, simulated, tiny_config
from .product_rows import ProductRun, product_rows, quick_subsample
from .product_rows import configuration as product_configuration

PRESET = "thesis-5.4-landmarks"
PRESET_OCCLUSION = "thesis-5.4-occlusion"
PANORAMA_ELEVATION = (-30.0, 20.0)
"""Elevation range (deg) of the panoramas unwarped for the whole-image models and the peers (the thesis's)."""

THESIS = {
    "detection rate train (%) 136": 97.0, "detection rate train (%) 144": 95.0,
    "detection rate test (%) 136": 99.0, "detection rate test (%) 144": 96.0,
    "MED (m) marker 136": 0.36, "MED (m) marker 144": 0.43, "MED (m) stacked": 0.21,
    "stacked / best single marker": 0.21 / 0.36, "MED (m) whole image [thesis configuration]": 0.23,
}
THESIS_OCCLUSION = {
    "detection rate train (%) 136": 77.0, "detection rate train (%) 144": 71.0,
    "detection rate test (%) 136": 73.0, "detection rate test (%) 144": 71.0,
    "MED (m) marker 136": 0.67, "MED (m) marker 144": 0.50, "MED (m) stacked": 0.32,
    "stacked / best single marker": 0.32 / 0.50,
}
QUICK_VIEW_NETWORK = {
    "input": {"width": 32, "height": 32, "channels": 3},
    "network": {"precision": "mixed"},
    "layers": [{"rf": [8, 8], "stride": [4, 4], "out": 8, "degree": 2}, {"rf": "full", "out": 12, "degree": 2}],
}
"""The views' network of the quick smoke run (32x32 views)."""
TARGET_STACKED = 0.21
TARGET_STACKED_OCCLUSION = 0.32


def _quick_world(occluded: bool) -> sim.World:
    occ = ({"marker_id": 136, "x_range": (None, 0.0), "y_range": (None, 0.0)},
           {"marker_id": 144, "x_range": (0.0, None), "y_range": (0.0, None)}) if occluded else ()
    return sim.World.generate(seed=3, area=(4.0, 4.0), n_objects=8, depth=4.0, margin=0.3, markers=LANDMARK_MARKERS,
                              marker_size=2.0, occlusions=occ)


def _quick_runs(occluded: bool) -> tuple[dict[str, Any], sim.OmniCamera, sim.World]:
    """A 4x4 m garden with 2 m boards close by, 320 px omni images, a few
    dozen frames: seconds."""
    world = _quick_world(occluded)
    cam = sim.OmniCamera(320, (-30.0, 25.0), mirror="equiangular")
    ren = sim.Renderer(world)
    runs = {"train": sim.trajectories.grid(world.area, spacing=1.2, step=0.5, margin=0.4),
            "test": sim.trajectories.random_walk(world.area, 20, 0.3, margin=0.4, rng=np.random.default_rng(1),
                                                 world=world)}
    out: dict[str, Any] = {"odometry": {}}
    for k, (name, tr) in enumerate(runs.items()):
        imgs = np.stack([ren.render(cam, pose) for pose in tr.poses])
        out[name] = (lambda a=imgs: [a], tr.poses[:, :2].copy())
        out["odometry"][name] = sim.simulate_odometry(tr.poses, rng=k)
    return out, cam, world


def _dataset_runs(out: Path, preset: str, seed: int, progress: bool) -> tuple[dict[str, Any], sim.OmniCamera, sim.World]:
    ds = simulated(out, preset, seed, quick=False, progress=progress)
    cam = sim.camera_from_dict(ds.metadata["camera"])
    world = sim.World.load(ds.root / "world.json")
    runs: dict[str, Any] = {"odometry": {}}
    for name in ("train", "test"):
        part = ds.select(run=name)
        runs[name] = (lambda p=part: p.images(batch_size=32), part.poses[:, :2].copy())
        runs["odometry"][name] = part.odometry
    return runs, cam, world


def read_frames(batches: Iterable[np.ndarray], extractor: ViewExtractor, camera: sim.OmniCamera,
                sizes: dict[str, tuple[int, int]], *, progress: bool = False) -> tuple[MarkerViews, dict[str, np.ndarray]]:
    """One pass over omnidirectional frames: their marker views and their
    panoramas unwarped with the camera's own mirror to each of ``sizes``
    (name -> (width, height)) over :data:`PANORAMA_ELEVATION`."""
    from .._progress import progress_bar

    parts, panos = [], {k: [] for k in sizes}
    bar = progress_bar(progress, None, "marker views and panoramas")
    for batch in batches:
        parts.append(extractor.transform(batch))
        for k, (w, h) in sizes.items():
            panos[k].append(np.stack([camera.unwarp(img, w, h, PANORAMA_ELEVATION) for img in batch]))
        if bar is not None:
            bar.update(len(batch))
    if bar is not None:
        bar.close()
    return MarkerViews.concatenate(parts), {k: np.concatenate(v) for k, v in panos.items()}


def _whole_image(kind: str, quick: bool, P_tr: np.ndarray, xy_tr: np.ndarray, P_te: np.ndarray, xy_te: np.ndarray,
                 progress: bool) -> tuple[Any, dict[str, Any], float]:
    t0 = time.perf_counter()
    if kind == "thesis configuration":
        net = Network(tiny_config(P_tr.shape[2], P_tr.shape[1], 3)) if quick else Network.from_preset("thesis-5.2")
        loc = train_localizer(P_tr, xy=xy_tr, network=net, recipe=recipe_for("thesis-5.2"), progress=progress)
    else:
        net = Network(tiny_config(P_tr.shape[2], P_tr.shape[1], 3)) if quick else None
        loc = train_localizer(P_tr, xy=xy_tr, camera_elevation=PANORAMA_ELEVATION, network=net,
                              progress=progress)
    fit_s = time.perf_counter() - t0
    pred = loc.predict(P_te)
    return loc, localization_metrics(pred, xy_te, coordinate_range=coordinate_range(xy_te)), fit_s


def _variant(out: Path, name: str, runs: dict[str, Any], cam: sim.OmniCamera, world: sim.World, *, quick: bool,
             sizes: dict[str, tuple[int, int]], suffix: str, thesis: dict[str, Any], peers: bool, progress: bool,
             log: Callable[[str], None]) -> tuple[Any, LandmarkLocalizer, list[dict[str, Any]], dict[str, Any]]:
    extractor = ViewExtractor(LANDMARK_MARKERS, size=32 if quick else 120, margin=10 if quick else 50)
    t0 = time.perf_counter()
    batches, xy_tr = runs["train"]
    V_tr, P_tr = read_frames(batches(), extractor, cam, sizes, progress=progress)
    batches, xy_te = runs["test"]
    V_te, P_te = read_frames(batches(), extractor, cam, sizes, progress=progress)
    read_s = time.perf_counter() - t0
    log(f"{name}: {len(V_tr)} training / {len(V_te)} test frames read in {read_s:.0f} s; markers found in "
        f"{np.round(100 * V_tr.detection_rate(), 1)} / {np.round(100 * V_te.detection_rate(), 1)} % of them")
    net = QUICK_VIEW_NETWORK if quick else "landmark-120"
    loc = LandmarkLocalizer(extractor, net).fit_views(V_tr, xy_tr, progress=progress)
    log(f"{name}: landmark networks trained in {loc.info['fit_seconds']:.0f} s")
    regions = {o.marker_id: (o.x_range, o.y_range) for o in world.occlusions} or None
    ev = evaluate_landmarks(loc, V_te, xy_te, train_views=V_tr, train_xy=xy_tr,
                            panoramas=(P_tr["thesis"], P_te["thesis"]) if peers else None, out=out,
                            prefix=f"5.4{suffix.replace(' ', '-').replace('[', '').replace(']', '')}-",
                            title=f"thesis 5.4 landmarks{suffix}", regions=regions,
                            marker_positions=world.markers, log=log,
                            text=[f"Scene: {name}, {len(V_tr)} training and {len(V_te)} test frames."])
    rows = landmark_rows(ev, suffix=suffix, thesis=thesis)
    # the same stack read by a GP (ARD kernel, marginal likelihood): the sfanav default's kind of readout
    V_te_stack = loc.stack(V_te)
    gp = make_readout({"kind": "gp", "n_outputs": V_te_stack.shape[1]}).fit(loc.stack(V_tr), xy_tr)
    gp_med = localization_metrics(gp.predict(V_te_stack), xy_te)["med"]
    log(f"{name}: stacked features read by a GP: MED {gp_med:.3f} m")
    rows.append({"metric": f"MED (m) stacked [GP readout]{suffix}", "thesis": None, "sfanav": gp_med,
                 "protocol": "test-run"})
    rows.append({"metric": f"training (s) landmark networks{suffix}", "thesis": None,
                 "sfanav": float(loc.info["fit_seconds"])})
    data = {"P_tr": P_tr, "P_te": P_te, "xy_tr": xy_tr, "xy_te": xy_te, "views": (V_tr, V_te)}
    return ev, loc, rows, data


def _row(rows: list[dict[str, Any]], metric: str) -> Any:
    return next(r["sfanav"] for r in rows if r["metric"] == metric)


@register("5.4", "landmarks: one SFA network per ArUco marker on its aligned views, stacked readout, occlusion "
                 "variant; whole-image model and peers beside")
def exp_5_4(out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    log = progress_log(progress)
    sizes = {"thesis": (60, 8), "default": (60, 8)} if quick else {"thesis": (600, 60), "default": (350, 40)}
    if quick:
        runs, cam, world = _quick_runs(False)
    else:
        runs, cam, world = _dataset_runs(out, PRESET, seed, progress)
    ev, loc, rows, data = _variant(out, PRESET, runs, cam, world, quick=quick, sizes=sizes, suffix="",
                                   thesis=THESIS, peers=True, progress=progress, log=log)
    stacked = ev.metrics["med"]
    singles = [e["metrics"]["med"] for e in ev.markers.values() if e["metrics"] is not None]
    whole: dict[str, float] = {}
    plots = [str(p) for _, p in ev.plots] + ([str(ev.report)] if ev.report else [])
    for kind, key in (("thesis configuration", "thesis"), ("sfanav default", "default")):
        wl, m, fit_s = _whole_image(kind, quick, data["P_tr"][key], data["xy_tr"], data["P_te"][key], data["xy_te"],
                                    progress)
        whole[kind] = m["med"]
        log(f"whole image [{kind}]: MED {m['med']:.3f} m (trained in {fit_s:.0f} s)")
        rows.append({"metric": f"MED (m) whole image [{kind}]", "thesis": THESIS.get(f"MED (m) whole image [{kind}]"),
                     "sfanav": m["med"], "protocol": "test-run", "configuration": kind})
        rows.append({"metric": f"training (s) whole image [{kind}]", "thesis": None, "sfanav": fit_s,
                     "configuration": kind})
        plots.append(str(plot_trajectory(data["xy_te"], wl.predict(data["P_te"][key]),
                                         out / f"5.4-whole-{key}-trajectory.png", connect=False, error_lines=True,
                                         title=f"whole image, {kind}: MED {m['med']:.2f} m")))
    # the product rows on the sfanav default's panoramas, beside the stacked landmark model (the thesis's method)
    make_net, recipe = product_configuration(quick)
    train = ProductRun(data["P_tr"]["default"], data["xy_tr"], runs["odometry"]["train"])
    product = product_rows(quick_subsample(train) if quick else train,
                           [ProductRun(data["P_te"]["default"], data["xy_te"], runs["odometry"]["test"])],
                           thesis=[ev.predictions], network=make_net, recipe=recipe,
                           camera_elevation=PANORAMA_ELEVATION, seed=seed, progress=progress, log=log)
    rows += product.rows
    # the occlusion variant
    if quick:
        runs_o, cam_o, world_o = _quick_runs(True)
    else:
        runs_o, cam_o, world_o = _dataset_runs(out, PRESET_OCCLUSION, seed, progress)
    ev_o, loc_o, rows_o, _ = _variant(out, PRESET_OCCLUSION, runs_o, cam_o, world_o, quick=quick, sizes={},
                                      suffix=" [occlusion]", thesis=THESIS_OCCLUSION, peers=False, progress=progress,
                                      log=log)
    rows += [dict(r, configuration="occlusion") for r in rows_o]
    plots += [str(p) for _, p in ev_o.plots] + ([str(ev_o.report)] if ev_o.report else [])
    stacked_o = ev_o.metrics["med"]
    singles_o = [e["metrics"]["med"] for e in ev_o.markers.values() if e["metrics"] is not None]
    targets = {
        f"stacked MED <= {TARGET_STACKED} m": stacked <= TARGET_STACKED,
        "stacked better than each single marker": bool(singles) and stacked < min(singles),
        "stacked better than the whole-image model [thesis configuration]": stacked < whole["thesis configuration"],
        "stacked better than the whole-image model [sfanav default]": stacked < whole["sfanav default"],
        "stacked [GP readout] better than the whole-image model [sfanav default]":
            _row(rows, "MED (m) stacked [GP readout]") < whole["sfanav default"],
        f"occlusion: stacked MED <= {TARGET_STACKED_OCCLUSION} m": stacked_o <= TARGET_STACKED_OCCLUSION,
        "occlusion: stacked better than each single marker": bool(singles_o) and stacked_o < min(singles_o),
    }
    notes = (
        ("QUICK smoke run: a 4x4 m garden with 2 m boards, 320 px omni images, 32x32 views, tiny networks; "
         "numbers not meaningful. " if quick else "")
        + f"Scenes: sim presets {PRESET} and {PRESET_OCCLUSION} (seed {seed}), "
        f"{len(data['xy_tr'])} training / {len(data['xy_te'])} test frames (thesis: 1773 / 1190). Views: "
        f"{loc.extractor.size}x{loc.extractor.size} RGB, bounding box + {loc.extractor.margin:g} px on every side, "
        "aligned by the marker's polar angle; one network per marker ("
        + ("tiny" if quick else "landmark-120") + ") trained on its views as one time series (no simulated "
        "rotation). 'MED (m) marker <id>': that marker's own quadratic readout of its 8 slowest outputs, on the "
        "test frames where it was found; 'MED (m) stacked': the quadratic readout of both markers' 8 slowest "
        "outputs (zeros where not found) and a found-flag each, on every test frame. Whole image: panoramas "
        f"unwarped from the same frames ({sizes['thesis'][0]}x{sizes['thesis'][1]} for the thesis configuration "
        f"and the peers, {sizes['default'][0]}x{sizes['default'][1]} for the sfanav default; elevation "
        f"{PANORAMA_ELEVATION[0]:g}..{PANORAMA_ELEVATION[1]:g} deg). Occlusion: the scene covers marker 136 where "
        "x <= 0 and y <= 0 and marker 144 where x >= 0 and y >= 0, in training and test (the thesis excluded the "
        "views from training; its test detection rates show the occlusion there too). Peers answer at most 1000 "
        "test frames, evenly spaced.\n" + product.note + " 'thesis configuration' rows: the stacked landmark "
        "model (the thesis's method in 5.4); the product rows read the sfanav default's panoramas unwarped from "
        "the same frames" + (" (quick: odometry simulated along the rendered poses)." if quick else "."))
    details = {"landmarks": loc, "landmarks_occlusion": loc_o, "evaluation": ev, "evaluation_occlusion": ev_o,
               "whole_image": whole}
    return ExperimentResult("5.4", rows, plots=plots, notes=notes, targets=targets, details=details)
