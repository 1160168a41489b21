"""The long-term experiments of thesis 6.2.2 with a map that grows online.

* ``6.2.2-online``: the ten recordings of ``thesis-6.2.2-conditions`` (one
  279-frame loop in ten different lights) fed one at a time to an
  updatable sfanav default: trained on the first recording
  (:func:`sfanav.pipeline.train_localizer` with ``readout_memory``), then
  updated with each further recording
  (:class:`sfanav.localization.updates.LocalizerUpdater`, ground-truth
  positions as 6.2.2 has them). After every update the MED on the next
  unseen recording (and on the permutation's last recording) beside the
  batch place-major training on the same recordings (6.2.2's own run,
  :func:`sfanav.experiments.robustness.run_622`, same permutations) and
  perfect memory fitted on them; the update's time beside the retrain's.
* ``6.2.2-seasons-online``: the same on ``thesis-6.2.2-seasons`` (ten
  recordings over a year), season by season: one order, spring to winter,
  each model tested on the next season's recording.

Both run each update twice: the top stage re-solved (``[updated]``, the
default policy) and every layer trained again on the remembered images
(``[updated, every layer]``, ``UpdatePolicy(resolve="all")`` with a readout
memory that keeps the images).

Rows: ``MED (m) after k recordings [updated]`` / ``[updated, every layer]`` /
``[batch place-major]`` / ``[perfect memory]`` (mean over permutations), the same on the held-out
last recording, and ``update time / retrain time after k recordings``.
docs/updates-measured.md describes the protocol and quotes the results.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from ..data.sources import load_run
from ..localization.error_metrics import localization_metrics
from ..localization.updates import MAX_VIEWS, LocalizerUpdater, remember
from ..sfa.updates import UpdatePolicy
from . import ExperimentResult, register
from .flags import area_diagonal, flag_row
from .localization import progress_log
from .robustness import long_term_configuration, run_622, train_long_term

CONFIG = "sfanav default"
"""The configuration made updatable (6.2.2's name for it)."""
PRESETS = {"6.2.2-online": "thesis-6.2.2-conditions", "6.2.2-seasons-online": "thesis-6.2.2-seasons"}
N_RECORDINGS = 10
"""Recordings in either scene."""
#: full mode: permutations of the ten recordings (6.2.2 runs 10; each permutation retrains 9 times)
FULL_PERMUTATIONS = 3
RESOLVES = ("top", "all")
"""The update policies measured (:class:`sfanav.sfa.updates.UpdatePolicy` ``resolve``)."""
LABEL_ALL = "updated, every layer"
"""The rows' name for ``resolve="all"``."""


def _med(loc: Any, X: np.ndarray, xy: np.ndarray) -> tuple[float, int]:
    """(MED in metres, estimates the readout extrapolated) of ``loc`` on one recording."""
    reg = getattr(loc, "regression_", None)
    before = int(getattr(reg, "n_extrapolated_", 0) or 0)
    med = float(localization_metrics(loc.predict(X), xy)["med"])
    return med, int(getattr(reg, "n_extrapolated_", 0) or 0) - before


def run_online(out: Path, *, quick: bool, seed: int, progress: bool, preset: str = "thesis-6.2.2-conditions",
               permutations: int | None = None, max_sets: int | None = None,
               readout_memory: int = MAX_VIEWS, chronological: bool = False) -> ExperimentResult:
    """The recordings of ``preset`` fed one at a time to an updatable sfanav
    default beside 6.2.2's batch place-major training and perfect memory
    on the same recordings (same permutations, same test recordings).

    ``permutations`` (default 1 quick, :data:`FULL_PERMUTATIONS` full) and
    ``max_sets`` (default 3 quick, 9 full): as :func:`run_622`.
    ``readout_memory``: views the localizer keeps for its readout (the
    default holds all ten 279-frame recordings). ``chronological``: one
    order, the recordings as their conditions are numbered (the seasons
    scene: spring to winter), instead of random permutations. ValueError
    for an unknown preset."""
    name = {v: k for k, v in PRESETS.items()}.get(preset)
    if name is None:
        raise ValueError(f"preset must be one of {sorted(PRESETS.values())}, got {preset!r}")
    log = progress_log(progress)
    permutations = permutations if permutations is not None else (1 if quick else FULL_PERMUTATIONS)
    max_sets = max_sets if max_sets is not None else (3 if quick else 9)
    batch = run_622(out, quick=quick, seed=seed, progress=progress, permutations=permutations, configs=(CONFIG,),
                    max_sets=max_sets, preset=preset, orders=[list(range(N_RECORDINGS))] if chronological else None)
    d = batch.details
    ds, conds, perms = d["dataset"], d["conditions"], d["permutations"][CONFIG]
    med_batch = np.asarray(d["curves"][CONFIG], dtype=np.float64)
    held_batch = np.asarray(d["curves"][CONFIG + ", last recording held out"], dtype=np.float64)
    pm = np.asarray(d["curves"]["perfect memory"], dtype=np.float64)
    t_batch = np.asarray(d["seconds"][CONFIG], dtype=np.float64)
    n_sets = med_batch.shape[1]

    make_net, prep, recipe = long_term_configuration(CONFIG, quick)
    sets = [load_run(ds.select(condition=c), prep, log=log) for c in conds]
    elev = tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))
    shape = (len(perms), n_sets)
    # per policy: the top stage re-solved (the default), every layer trained again on the remembered images
    med = {r: np.full(shape, np.nan) for r in RESOLVES}
    held = {r: np.full(shape, np.nan) for r in RESOLVES}
    secs = {r: np.full(shape, np.nan) for r in RESOLVES}  # k = 1: the first training; k > 1: the update with k
    ext = {r: np.zeros(shape, dtype=np.int64) for r in RESOLVES}
    for p, perm in enumerate(perms):
        first, t_first = train_long_term(make_net, *sets[perm[0]], recipe, elev, readout_memory=readout_memory)
        remember(first, *sets[perm[0]], max_views=readout_memory, keep_images=True)  # for resolve="all"
        for r in RESOLVES:
            up, loc = LocalizerUpdater(first, UpdatePolicy(resolve=r)), first
            secs[r][p, 0] = t_first
            for k in range(1, n_sets + 1):
                if k > 1:
                    t0 = time.perf_counter()
                    up.partial_fit(*sets[perm[k - 1]])
                    secs[r][p, k - 1] = time.perf_counter() - t0
                    loc = up.localizer_
                med[r][p, k - 1], ext[r][p, k - 1] = _med(loc, *sets[perm[k]])
                held[r][p, k - 1] = _med(loc, *sets[perm[-1]])[0]
                log(f"{name} permutation {p}, {k} recordings, resolve {r}: updated MED {med[r][p, k - 1]:.3f} m "
                    f"(batch {med_batch[p, k - 1]:.3f} m, perfect memory {pm[p, k - 1]:.3f} m); "
                    f"{'update' if k > 1 else 'first training'} {secs[r][p, k - 1]:.1f} s, "
                    f"retrain {t_batch[p, k - 1]:.1f} s")
    diagonal = area_diagonal(sets[0][1])
    rows: list[dict[str, Any]] = []
    for k in range(1, n_sets + 1):
        rec = f"{k} recording{'s' if k > 1 else ''}"
        for label, curve, n_ext in (("updated", med["top"], int(ext["top"][:, k - 1].sum())),
                                    (LABEL_ALL, med["all"], int(ext["all"][:, k - 1].sum())),
                                    ("batch place-major", med_batch, 0), ("perfect memory", pm, 0)):
            rows.append(flag_row({"metric": f"MED (m) after {rec} [{label}]", "thesis": None,
                                  "sfanav": float(np.nanmean(curve[:, k - 1])), "configuration": label},
                                 extrapolated=n_ext, diagonal=diagonal))
        for label, curve in (("updated", held["top"]), (LABEL_ALL, held["all"]), ("batch place-major", held_batch)):
            rows.append(flag_row({"metric": f"MED (m) after {rec}, last recording held out [{label}]",
                                  "thesis": None, "sfanav": float(np.nanmean(curve[:, k - 1])),
                                  "configuration": label}, diagonal=diagonal))
        if k > 1:
            rows.append({"metric": f"update time / retrain time after {rec}", "thesis": None,
                         "sfanav": float(np.nanmean(secs["top"][:, k - 1] / t_batch[:, k - 1]))})
            rows.append({"metric": f"update time / retrain time after {rec} [{LABEL_ALL}]", "thesis": None,
                         "sfanav": float(np.nanmean(secs["all"][:, k - 1] / t_batch[:, k - 1]))})
    rows.append({"metric": f"updated / batch MED after {n_sets} recordings", "thesis": None,
                 "sfanav": float(np.nanmean(med["top"][:, -1]) / np.nanmean(med_batch[:, -1]))})
    rows.append({"metric": f"updated / batch MED after {n_sets} recordings [{LABEL_ALL}]", "thesis": None,
                 "sfanav": float(np.nanmean(med["all"][:, -1]) / np.nanmean(med_batch[:, -1]))})
    rows.append({"metric": "total update time / total retrain time", "thesis": None,
                 "sfanav": float(np.nansum(secs["top"][:, 1:]) / np.nansum(t_batch[:, 1:]))})
    rows.append({"metric": f"total update time / total retrain time [{LABEL_ALL}]", "thesis": None,
                 "sfanav": float(np.nansum(secs["all"][:, 1:]) / np.nansum(t_batch[:, 1:]))})
    path = _plot(out / f"{name}-error-vs-recordings.png", name,
                 {"updated": med["top"], LABEL_ALL: med["all"], "batch place-major": med_batch, "perfect memory": pm})
    notes = (f"Scene: sim preset {preset} (seed {seed}), {len(conds)} recordings of one {len(sets[0][1])}-frame "
             f"loop. {len(perms)} permutation(s) of the recordings, the same as the batch run's. Updated: the "
             f"sfanav default ({'tiny network, 60x8' if quick else '350x40'}, 6.2.2's training: no simulated "
             f"rotation) trained on the permutation's first recording with a readout memory of {readout_memory} "
             "views, then updated (network top stage re-solved, readout refitted) with each further recording as its "
             f"own run at its ground-truth positions. '{LABEL_ALL}': the same updates with UpdatePolicy(resolve='all'): "
             "every layer trained again on the remembered images of every recording so far, each view paired with "
             "the nearest view of an earlier recording. Batch place-major: 6.2.2's training on the same k recordings, "
             "retrained from scratch each time. Test: the next unseen recording of the permutation (and the "
             "permutation's last recording). Times: update of the localizer with one recording against the batch "
             "retrain on all k recordings, same process.")
    return ExperimentResult(name, rows, [str(path)] + list(batch.plots), notes,
                            details={"curves": {"updated": med["top"].tolist(), LABEL_ALL: med["all"].tolist(),
                                                "updated, last recording held out": held["top"].tolist(),
                                                "batch place-major": med_batch.tolist(), "perfect memory": pm.tolist()},
                                     "seconds": {"updated": secs["top"].tolist(), LABEL_ALL: secs["all"].tolist(),
                                                 "batch place-major": t_batch.tolist()},
                                     "batch": batch})


def _plot(path: Path, name: str, curves: dict[str, np.ndarray]) -> Path:
    from .._plotting import figure, save_figure

    fig = figure(6, 4)
    ax = fig.add_subplot()
    for label, med in curves.items():
        k = np.arange(1, med.shape[1] + 1)
        ax.errorbar(k, np.nanmean(med, axis=0), yerr=np.nanstd(med, axis=0), marker="o", capsize=3, label=label)
    ax.set_xlabel("recordings (updated one at a time / batch)")
    ax.set_ylabel("MED on the next recording (m)")
    ax.set_yscale("log")
    ax.legend()
    ax.set_title(f"{name}: a map updated recording by recording")
    return save_figure(fig, path, 120)


@register("6.2.2-online", "6.2.2's ten recordings in different light fed one at a time to an updatable sfanav "
          "default, beside the batch place-major training and perfect memory")
def exp_622_online(out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    return run_online(out, quick=quick, seed=seed, progress=progress, preset="thesis-6.2.2-conditions")


@register("6.2.2-seasons-online", "6.2.2-seasons's recordings over a year fed season by season to an updatable "
          "sfanav default, beside the batch place-major training and perfect memory")
def exp_622_seasons_online(out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    return run_online(out, quick=quick, seed=seed, progress=progress, preset="thesis-6.2.2-seasons",
                      chronological=True)
