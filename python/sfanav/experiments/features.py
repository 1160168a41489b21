"""Local visual features over the seasons (thesis 6.1) on the simulator.

* ``6.1.1``: a fixed camera records 101 panoramas over a year
  (preset ``thesis-6.1-seasons``, run ``year``); up to 1000 features of the
  first frame are the reference, each later frame's up to 1000 features are
  matched to them with the mutual consistency check, and a match is true if
  the two keypoints lie within 10 px (same pose). True matches against the
  days since the reference, per detector.
* ``6.1.2``: the preset's 160-frame loop driven in every season (run
  ``route``). Stable / unstable features from the first half of the loop in
  spring, summer and autumn train the robustness predictor; on the second
  half, spring is the reference and summer, autumn and the held-out winter
  are matched to it for memory sizes 5..2000, keeping the m reference
  features of largest detector response, or m of the 1.5 m strongest chosen
  by predicted robustness (:func:`~sfanav.features.select_ranked`: the
  library default ``rank-sum``, rank by response plus rank by robustness,
  and the thesis's rule ``robust``, the m most robust). F1 (precision: true
  among mutual matches; recall: true matches per reference feature kept)
  and its mean relative gain over the response selection.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .. import sim
from ..features import (
    DETECTORS,
    METHODS,
    RobustnessPredictor,
    balanced,
    descriptor_distances,
    detect,
    match,
    match_distances,
    robustness_vectors,
    select_ranked,
    stability_labels,
    true_match,
)
from . import ExperimentResult, register
from .localization import progress_log, simulated

PRESET = "thesis-6.1-seasons"
#: thesis 6.1.1 (FAST + BRIEF): true matches in the first and the last frame
THESIS_611 = {"first": 580, "last": 50}
#: thesis 6.1.2: mean F1 gain (%) of robustness selection over detector response, per reference/query pair
THESIS_612 = {("fast-brief", "summer"): 4.74, ("fast-brief", "autumn"): 8.88,
              ("sift", "summer"): 7.72, ("sift", "autumn"): 11.79}
MEMORY = (5, 10, 20, 50, 100, 150, 200, 300, 500, 750, 1000, 1500, 2000)
THRESHOLD = 10.0
#: the SVM grid of the full run (gamma in standardised units; scikit-learn's "scale" is about 1/77)
GRID = {"C": [1.0, 10.0, 100.0], "gamma": [0.003, 0.01, 0.03]}
#: most balanced training samples per detector in the full run
MAX_SAMPLES = 4000
#: candidate pool of the robustness selection, in multiples of the memory size
CANDIDATES = 1.5
QUICK_CAMERA = (300, 40)


def _data(out: Path, seed: int, quick: bool, progress: bool) -> Any:
    if quick:
        return simulated(out, PRESET, seed, quick=True, camera=sim.PanoramicCamera(*QUICK_CAMERA),
                         max_frames=8, progress=progress)
    return simulated(out, PRESET, seed, quick=False, progress=progress)


@register("6.1.1", "feature matching over a year (thesis 6.1.1): FAST+BRIEF best, true matches fall from ~580 to ~50")
def exp_611(out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    log = progress_log(progress)
    ds = _data(out, seed, quick, progress).select(run="year")
    days = (ds.timestamps - ds.timestamps[0]) / 86400.0
    dets = ("fast-brief", "sift") if quick else DETECTORS
    n = 200 if quick else 1000
    curves: dict[str, np.ndarray] = {}
    rows: list[dict[str, Any]] = []
    for det in dets:
        log(f"6.1.1: {det}")
        ref = detect(ds.image(0), det, n)
        tp, prec = [], []
        for i in range(1, len(ds)):
            q = detect(ds.image(i), det, n)
            pairs = match(ref, q, cross_check=True)
            ok = true_match(ref, q, pairs, THRESHOLD)
            tp.append(int(ok.sum()))
            prec.append(float(ok.mean()) if len(ok) else 0.0)
        curves[det] = np.array(tp)
        thesis_fb = det == "fast-brief"
        rows += [
            {"metric": f"{det}: reference features", "thesis": 1000 if thesis_fb else None, "sfanav": len(ref)},
            {"metric": f"{det}: true matches, first frame", "thesis": THESIS_611["first"] if thesis_fb else None,
             "sfanav": tp[0]},
            {"metric": f"{det}: true matches, last frame", "thesis": THESIS_611["last"] if thesis_fb else None,
             "sfanav": tp[-1]},
            {"metric": f"{det}: fewest true matches", "thesis": 10 if thesis_fb else None, "sfanav": int(min(tp))},
            {"metric": f"{det}: mean precision", "thesis": None, "sfanav": float(np.mean(prec))},
            {"metric": f"{det}: mean recall", "thesis": None, "sfanav": float(np.mean(tp) / max(len(ref), 1))},
        ]
    best = max(curves, key=lambda d: curves[d].mean())
    rows.append({"metric": "best detector (most true matches over the year)", "thesis": "fast-brief", "sfanav": best})
    out.mkdir(parents=True, exist_ok=True)
    path = out / "6.1.1-true-matches.png"
    _plot_611(path, days[1:], curves)
    notes = (f"preset {PRESET}, run 'year' ({len(ds)} frames, fixed camera, seasons blend over a year from the start "
             f"of spring, a random day's light per frame); up to {n} features per frame, mutual consistency check, "
             f"true if within {THRESHOLD:g} px. SURF stands in as SIFT, upright SURF as upright SIFT, BRIEF as ORB's "
             "rBRIEF at orientation 0 on FAST corners.")
    return ExperimentResult("6.1.1", rows, [str(path)], notes, figures={"true matches over a year": path},
                            details={"days": days[1:].tolist(), "true_matches": {k: v.tolist() for k, v in curves.items()}})


def _plot_611(path: Path, days: np.ndarray, curves: dict[str, np.ndarray]) -> None:
    from .._plotting import figure, save_figure

    fig = figure(8, 4)
    ax = fig.add_subplot()
    for det, c in curves.items():
        ax.plot(days, c, label=det)
    ax.set_xlabel("days since the reference frame")
    ax.set_ylabel("true matches")
    ax.set_title("feature matches over a year (mutual check, 10 px)")
    ax.legend()
    save_figure(fig, path, 110)


def _f1(tp: int, fp: int, n_ref: int) -> float:
    p = tp / (tp + fp) if tp + fp else 0.0
    r = tp / n_ref if n_ref else 0.0
    return 2 * p * r / (p + r) if p + r else 0.0


@register("6.1.2", "robustness prediction (thesis 6.1.2): F1 gain over detector response +4.74..+11.79 %")
def exp_612(out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    return run_612(out, quick=quick, seed=seed, progress=progress)


def run_612(out: Path, *, quick: bool, seed: int, progress: bool,
            match_threshold: float = THRESHOLD) -> ExperimentResult:
    """Experiment 6.1.2; ``match_threshold``: the largest image distance
    (px) of a true test match (the labels of the training features keep
    ``THRESHOLD``)."""
    log = progress_log(progress)
    ds = _data(out, seed, quick, progress).select(run="route")
    by_season = {c: np.flatnonzero(ds.conditions == c)[np.argsort(ds.frames[ds.conditions == c], kind="stable")]
                 for c in np.unique(ds.conditions)}
    frames = np.arange(min(len(v) for v in by_season.values()))  # k: the k-th pose of the loop
    half = len(frames) // 2
    train_f, test_f = frames[:half], frames[half:]
    seasons = ("spring", "summer", "autumn")
    queries = ("summer", "autumn", "winter")
    memory = (5, 10, 20, 50) if quick else MEMORY
    dets = ("fast-brief",) if quick else DETECTORS
    n_detect = int(np.ceil(CANDIDATES * max(memory)))
    default = METHODS[0]  # RobustnessPredictor.select's default; the thesis's rule is "robust"
    grid = {"C": [1.0], "gamma": [0.01]} if quick else GRID
    cv = 2 if quick else 5
    rng = np.random.default_rng(seed)

    def image(frame: int, season: str) -> np.ndarray:
        return ds.image(int(by_season[season][frame]))

    rows: list[dict[str, Any]] = []
    curves: dict[str, Any] = {}
    for det in dets:
        log(f"6.1.2: {det}: training data")
        X, y = [], []
        for f in train_f:
            imgs = [image(f, s) for s in seasons]
            feats = [detect(im, det, 1000) for im in imgs]
            labs = stability_labels(feats, threshold=THRESHOLD)
            for im, ft, lab in zip(imgs, feats, labs):
                keep = lab >= 0
                X.append(robustness_vectors(im, ft.xy[keep]))
                y.append(lab[keep])
        Xa, ya = np.vstack(X), np.concatenate(y)
        sel = balanced(ya, rng)
        if not quick and len(sel) > MAX_SAMPLES:
            sel = np.sort(rng.choice(sel, MAX_SAMPLES, replace=False))
        log(f"6.1.2: {det}: {len(sel)} balanced samples of {len(ya)} labelled, grid search")
        pred = RobustnessPredictor.fit(Xa[sel], ya[sel], detector=det, grid=grid, cv=cv, seed=seed)
        log(f"6.1.2: {det}: C {pred.info['C']:g}, gamma {pred.gamma:g}, CV accuracy {pred.info['cv_accuracy']:.3f}")
        hows = ("response",) + METHODS
        counts = {(q, how): np.zeros((len(memory), 3), int) for q in queries for how in hows}
        for f in test_f:
            ref_img = image(f, "spring")
            ref_all = detect(ref_img, det, n_detect)
            scores = pred.score_keypoints(ref_img, ref_all)
            qs = {q: detect(image(f, q), det, max(memory)) for q in queries}
            # one distance matrix per query, sliced for every memory size (features come sorted by response)
            dist = {q: descriptor_distances(ref_all, qf) for q, qf in qs.items()}
            for mi, m in enumerate(memory):
                kept_by = {"response": np.arange(min(len(ref_all), m)),
                           **{how: select_ranked(scores, m, candidates=CANDIDATES, method=how) for how in METHODS}}
                for q, qf in qs.items():
                    cols = np.arange(min(len(qf), m))
                    qm = qf.subset(cols)
                    for how, kept in kept_by.items():
                        pairs = match_distances(dist[q][np.ix_(kept, cols)], cross_check=True)
                        ok = true_match(ref_all.subset(kept), qm, pairs, match_threshold)
                        counts[(q, how)][mi] += (int(ok.sum()), int((~ok).sum()), len(kept))
        for q in queries:
            f1s = {how: np.array([_f1(*c) for c in counts[(q, how)]]) for how in hows}
            f_conv = f1s["response"]
            valid = f_conv > 0
            gain = {how: float(np.mean((f1s[how][valid] - f_conv[valid]) / f_conv[valid]) * 100) if valid.any()
                    else float("nan") for how in METHODS}
            thesis = THESIS_612.get((det, q))
            held = " (held-out season)" if q == "winter" else ""
            rows.append({"metric": f"{det}: F1 gain % {q} to spring{held}", "thesis": thesis, "sfanav": gain[default]})
            for how in METHODS[1:]:
                rows.append({"metric": f"{det}: F1 gain % {q} to spring, selection '{how}'", "thesis": thesis,
                             "sfanav": gain[how]})
            rows.append({"metric": f"{det}: mean F1 {q} to spring, {' / '.join(hows)}", "thesis": None,
                         "sfanav": " / ".join(f"{f1s[how].mean():.3f}" for how in hows)})
            curves[f"{det}/{q}"] = {how: f.tolist() for how, f in f1s.items()}
        rows.append({"metric": f"{det}: predictor CV accuracy", "thesis": None, "sfanav": pred.info["cv_accuracy"]})
        rows.append({"metric": f"{det}: balanced training samples", "thesis": 10000 if det == "fast-brief" else None,
                     "sfanav": int(len(sel))})
        if not quick:
            out.mkdir(parents=True, exist_ok=True)
            pred.save(out / f"6.1.2-predictor-{det}.json")
    out.mkdir(parents=True, exist_ok=True)
    path = out / "6.1.2-f1.png"
    _plot_612(path, memory, curves)
    targets = {f"{det}: gain >= thesis {q} to spring": bool(next(r["sfanav"] for r in rows
                                                                 if r["metric"].startswith(f"{det}: F1 gain % {q}"))
                                                            >= THESIS_612[(det, q)])
               for det, q in THESIS_612 if det in dets}
    notes = (f"preset {PRESET}, run 'route': training on loop poses {int(train_f[0])}..{int(train_f[-1])} in "
             f"{', '.join(seasons)} (stable: matched in all, ratio 0.75, {THRESHOLD:g} px; unstable: in none; "
             f"balanced), test on poses {int(test_f[0])}..{int(test_f[-1])}; reference spring, memory sizes "
             f"{', '.join(map(str, memory))}; gain = mean over memory sizes of the relative F1 change of the "
             f"selection '{default}' (rank by response + rank by robustness among the {CANDIDATES:g} m strongest; "
             "rows 'robust': the m most robust of them, the thesis's rule) over the m strongest. "
             "Thesis SURF rows are compared with SIFT (the stand-in).")
    return ExperimentResult("6.1.2", rows, [str(path)], notes, targets=targets, figures={"F1 against memory": path},
                            details={"memory": list(memory), "f1": curves})


def _plot_612(path: Path, memory: Any, curves: dict[str, Any]) -> None:
    from .._plotting import figure, save_figure

    keys = sorted(curves)
    fig = figure(3.2 * len(keys), 3.2)
    axes = fig.subplots(1, len(keys), squeeze=False)
    for ax, k in zip(axes[0], keys):
        ax.semilogx(memory, curves[k]["response"], "o-", ms=3, label="detector response")
        ax.semilogx(memory, curves[k]["rank-sum"], "o-", ms=3, label="response + robustness ranks (default)")
        ax.semilogx(memory, curves[k]["robust"], "o--", ms=3, label="predicted robustness (thesis)")
        ax.set_title(k.replace("/", ", ") + " to spring", fontsize=8)
        ax.set_xlabel("memory (features)")
    axes[0][0].set_ylabel("F1")
    axes[0][0].legend(fontsize=7)
    save_figure(fig, path, 100)
