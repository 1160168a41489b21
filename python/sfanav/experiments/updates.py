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

``6.2.1-changes-online``: a garden whose objects change between runs (sim
preset ``garden-changes``): the sfanav default trained on run A (the stale
model), updated with run B, a second exploration after objects were moved,
removed and added (both policies), beside a retrain on A + B and perfect
memory of A and of A + B; all tested on a walk in the changed garden
(:func:`run_changes`). Its online peer: the stale model's top stage
replaced by IncSFA learning from A's and then B's top-stage sequence, the
readout refitted (``IncSFA top stage``, :mod:`sfanav.experiments.incsfa_peer`).

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

from .. import sim
from ..data.sources import load_run
from ..localization import baselines
from ..localization.error_metrics import localization_metrics
from ..localization.updates import MAX_VIEWS, LocalizerUpdater, remember
from ..pipeline import train_localizer
from ..sfa.network import Rotation
from ..sfa.updates import UpdatePolicy
from . import ExperimentResult, register
from .flags import area_diagonal, flag_row
from .incsfa_peer import INCSFA_MCA_RATES, INCSFA_WHITENED, IncSFATopStage, incsfa_update, memory_views
from .localization import progress_log, simulated
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
LABEL_INCSFA = "IncSFA top stage"
"""The rows' name for the online peer (:mod:`sfanav.experiments.incsfa_peer`): the top stage replaced by IncSFA."""


def _med(loc: Any, X: np.ndarray, xy: np.ndarray) -> tuple[float, int]:
    """(MED in metres, estimates the readout extrapolated) of ``loc`` on one recording."""
    reg = getattr(loc, "regression_", None)
    before = int(getattr(reg, "n_extrapolated_", 0) or 0)
    med = float(localization_metrics(loc.predict(X), xy)["med"])
    return med, int(getattr(reg, "n_extrapolated_", 0) or 0) - before


def run_online(out: Path, *, quick: bool, seed: int, progress: bool, preset: str = "thesis-6.2.2-conditions",
               permutations: int | None = None, max_sets: int | None = None,
               readout_memory: int = MAX_VIEWS, chronological: bool = False, readout: str = "auto") -> ExperimentResult:
    """The recordings of ``preset`` fed one at a time to an updatable sfanav
    default beside 6.2.2's batch place-major training and perfect memory
    on the same recordings (same permutations, same test recordings).

    ``permutations`` (default 1 quick, :data:`FULL_PERMUTATIONS` full) and
    ``max_sets`` (default 3 quick, 9 full): as :func:`run_622`.
    ``readout_memory``: views the localizer keeps for its readout (the
    default holds all ten 279-frame recordings). ``chronological``: one
    order, the recordings as their conditions are numbered (the seasons
    scene: spring to winter), instead of random permutations. ``readout``:
    ``"auto"`` (the default's behaviour) the updates choose the readout
    again over the recordings and the batch trainings are told the
    recordings (both then choose as ``sfanav train --recordings``);
    ``"keep"`` every model keeps the readout kind its first recording
    chose (the slow features' own join, compared on equal readouts). ValueError
    for an unknown preset."""
    if readout not in ("auto", "keep"):
        raise ValueError(f'readout must be "auto" or "keep", got {readout!r}')
    name = {v: k for k, v in PRESETS.items()}.get(preset)
    if name is None:
        raise ValueError(f"preset must be one of {sorted(PRESETS.values())}, got {preset!r}")
    log = progress_log(progress)
    permutations = permutations if permutations is not None else (1 if quick else FULL_PERMUTATIONS)
    max_sets = max_sets if max_sets is not None else (3 if quick else 9)
    batch = run_622(out, quick=quick, seed=seed, progress=progress, permutations=permutations, configs=(CONFIG,),
                    max_sets=max_sets, preset=preset, orders=[list(range(N_RECORDINGS))] if chronological else None,
                    by_recordings=readout == "auto")
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
    med_inc, held_inc, secs_inc = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
    for p, perm in enumerate(perms):
        first, t_first = train_long_term(make_net, *sets[perm[0]], recipe, elev, readout_memory=readout_memory)
        remember(first, *sets[perm[0]], max_views=readout_memory, keep_images=True)  # for resolve="all"
        exact: list[Any] = []  # the top-stage update's localizer after each count, whose readout the peer copies
        for r in RESOLVES:
            up, loc = LocalizerUpdater(first, UpdatePolicy(resolve=r), readout=readout), first
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
                if r == "top":
                    exact.append(loc)
        # the online peer: IncSFA as the top stage on the first model's frozen lower layers, fed one recording at a
        # time (its passes over the first recording stand for the first training and are not timed as an update),
        # its readout of the kind the exact top-stage update has at the same count
        inc = IncSFATopStage(first, seed=seed).partial_fit(sets[perm[0]][0])
        for k in range(1, n_sets + 1):
            t0 = time.perf_counter()
            if k > 1:
                inc.partial_fit(sets[perm[k - 1]][0])
            # the exact update's views: the same frozen lower layers give the same stage inputs
            views = memory_views(exact[k - 1].readout_memory_)
            inc.fit_readout(views.inputs, views.positions, views.signatures, like=exact[k - 1])
            secs_inc[p, k - 1] = time.perf_counter() - t0 if k > 1 else t_first
            med_inc[p, k - 1] = _med(inc, *sets[perm[k]])[0]
            held_inc[p, k - 1] = _med(inc, *sets[perm[-1]])[0]
            log(f"{name} permutation {p}, {k} recordings, IncSFA top stage: MED {med_inc[p, k - 1]:.3f} m "
                f"(readout {inc.readout_.describe_readout()})")
    diagonal = area_diagonal(sets[0][1])
    rows: list[dict[str, Any]] = []
    for k in range(1, n_sets + 1):
        rec = f"{k} recording{'s' if k > 1 else ''}"
        for label, curve, n_ext in (("updated", med["top"], int(ext["top"][:, k - 1].sum())),
                                    (LABEL_ALL, med["all"], int(ext["all"][:, k - 1].sum())),
                                    (LABEL_INCSFA, med_inc, 0),
                                    ("batch place-major", med_batch, 0), ("perfect memory", pm, 0)):
            rows.append(flag_row({"metric": f"MED (m) after {rec} [{label}]", "thesis": None,
                                  "sfanav": float(np.nanmean(curve[:, k - 1])), "configuration": label},
                                 extrapolated=n_ext, diagonal=diagonal))
        for label, curve in (("updated", held["top"]), (LABEL_ALL, held["all"]), (LABEL_INCSFA, held_inc),
                             ("batch place-major", held_batch)):
            rows.append(flag_row({"metric": f"MED (m) after {rec}, last recording held out [{label}]",
                                  "thesis": None, "sfanav": float(np.nanmean(curve[:, k - 1])),
                                  "configuration": label}, diagonal=diagonal))
        if k > 1:
            rows.append({"metric": f"update time / retrain time after {rec}", "thesis": None,
                         "sfanav": float(np.nanmean(secs["top"][:, k - 1] / t_batch[:, k - 1]))})
            rows.append({"metric": f"update time / retrain time after {rec} [{LABEL_ALL}]", "thesis": None,
                         "sfanav": float(np.nanmean(secs["all"][:, k - 1] / t_batch[:, k - 1]))})
            rows.append({"metric": f"update time / retrain time after {rec} [{LABEL_INCSFA}]", "thesis": None,
                         "sfanav": float(np.nanmean(secs_inc[:, k - 1] / t_batch[:, k - 1]))})
    rows.append({"metric": f"updated / batch MED after {n_sets} recordings", "thesis": None,
                 "sfanav": float(np.nanmean(med["top"][:, -1]) / np.nanmean(med_batch[:, -1]))})
    rows.append({"metric": f"updated / batch MED after {n_sets} recordings [{LABEL_ALL}]", "thesis": None,
                 "sfanav": float(np.nanmean(med["all"][:, -1]) / np.nanmean(med_batch[:, -1]))})
    rows.append({"metric": f"updated / batch MED after {n_sets} recordings [{LABEL_INCSFA}]", "thesis": None,
                 "sfanav": float(np.nanmean(med_inc[:, -1]) / np.nanmean(med_batch[:, -1]))})
    rows.append({"metric": "total update time / total retrain time", "thesis": None,
                 "sfanav": float(np.nansum(secs["top"][:, 1:]) / np.nansum(t_batch[:, 1:]))})
    rows.append({"metric": f"total update time / total retrain time [{LABEL_ALL}]", "thesis": None,
                 "sfanav": float(np.nansum(secs["all"][:, 1:]) / np.nansum(t_batch[:, 1:]))})
    rows.append({"metric": f"total update time / total retrain time [{LABEL_INCSFA}]", "thesis": None,
                 "sfanav": float(np.nansum(secs_inc[:, 1:]) / np.nansum(t_batch[:, 1:]))})
    path = _plot(out / f"{name}-error-vs-recordings.png", name,
                 {"updated": med["top"], LABEL_ALL: med["all"], LABEL_INCSFA: med_inc, "batch place-major": med_batch,
                  "perfect memory": pm})
    again = readout == "auto"
    notes = (f"Scene: sim preset {preset} (seed {seed}), {len(conds)} recordings of one {len(sets[0][1])}-frame "
             f"loop. {len(perms)} permutation(s) of the recordings, the same as the batch run's. Updated: the "
             f"sfanav default ({'tiny network, 60x8' if quick else '350x40'}, 6.2.2's training: no simulated "
             f"rotation) trained on the permutation's first recording with a readout memory of {readout_memory} "
             "views, then updated (network top stage re-solved, readout refitted) with each further recording as its "
             "own run at its ground-truth positions, "
             + ("its readout chosen again over the runs whenever the kernel is learned again "
                "(LocalizerUpdater(readout='auto'), the default). " if again else
                "its readout's kind kept as the first recording chose it (LocalizerUpdater(readout='keep')). ")
             + f"'{LABEL_ALL}': the same updates with UpdatePolicy(resolve='all'): every layer trained again on the "
             "remembered images of every recording so far, each view paired with the nearest view of an earlier "
             f"recording. '{LABEL_INCSFA}': the online peer, IncSFA ({len(INCSFA_MCA_RATES)} passes per recording, "
             f"{INCSFA_WHITENED} whitened directions) as the top stage on the first model's frozen lower layers, fed "
             "one recording at a time, the readout refitted on its features of every view so far, of the kind the "
             "exact top-stage update has at the same count (the two differ only in the top stage). Batch place-major: 6.2.2's training on the same k recordings, "
             "retrained from scratch each time"
             + (", told which recording each image comes from (its readout chosen by recordings, as sfanav train "
                "--recordings chooses it)" if again else ", not told the recordings")
             + ". Test: the next unseen recording of the permutation (and the permutation's last recording). Times: "
             "update of the localizer with one recording against the batch retrain on all k recordings, same process.")
    return ExperimentResult(name, rows, [str(path)] + list(batch.plots), notes,
                            details={"curves": {"updated": med["top"].tolist(), LABEL_ALL: med["all"].tolist(),
                                                LABEL_INCSFA: med_inc.tolist(),
                                                "updated, last recording held out": held["top"].tolist(),
                                                "batch place-major": med_batch.tolist(), "perfect memory": pm.tolist()},
                                     "seconds": {"updated": secs["top"].tolist(), LABEL_ALL: secs["all"].tolist(),
                                                 LABEL_INCSFA: secs_inc.tolist(),
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


# ----------------------------------------------------------------------------------- 6.2.1-changes-online
CHANGES_PRESET = "garden-changes"
"""The scene of ``6.2.1-changes-online``: runs A, B (after the garden changed) and a test walk after B."""
CHANGES_QUICK_FRAMES = 600
"""Quick mode: the first frames of every run (most of A's and B's lanes), of which every
:data:`CHANGES_QUICK_STEP`-th is used."""
CHANGES_QUICK_STEP = 4
CHANGES_LABELS = ("stale", "updated", LABEL_ALL, LABEL_INCSFA, "retrained", "perfect memory A",
                  "perfect memory A + B")
"""The models of ``6.2.1-changes-online``, as the rows name them."""


def _fit_changes(make_net: Any, X: np.ndarray, xy: np.ndarray, recipe: Any, elev: tuple[float, float],
                 memory: int | None = None) -> tuple[Any, float]:
    """6.2.1's training of a configuration on images X (N, H, W[, C]) at
    positions xy (N, 2) m: simulated rotation (5 px, whole panorama), the
    recipe's pooling. ``memory``: keep that many views, with their images,
    for updates of either policy. Returns (localizer, seconds)."""
    t0 = time.perf_counter()
    loc = train_localizer(X, xy=xy, network=make_net(), recipe=recipe, camera_elevation=elev, rotation=Rotation(5, 1.0),
                          readout_memory=memory, readout_memory_images=memory is not None)
    return loc, time.perf_counter() - t0


def run_changes(out: Path, *, quick: bool, seed: int, progress: bool,
                readout_memory: int = MAX_VIEWS) -> ExperimentResult:
    """A garden whose objects change between runs (``garden-changes``):
    the sfanav default trained on run A (``stale``), updated with run B
    after the change by the top-stage policy (``updated``) and by
    ``UpdatePolicy(resolve="all")`` (``updated, every layer``), retrained
    from scratch on A + B (``retrained``), the online peer (``IncSFA top
    stage``: the stale model's top stage replaced by IncSFA learning from
    A's and then B's top-stage sequence, the readout refitted,
    :func:`sfanav.experiments.incsfa_peer.incsfa_update`), and perfect
    memory of A and of A + B; MED (m) of each on the test walk in the
    changed garden, the updates' time against the retrain's.
    ``readout_memory``: views the stale model keeps (the default holds all
    of A and B). Quick: the tiny network on 60x8 panoramas, every
    :data:`CHANGES_QUICK_STEP`-th of the first :data:`CHANGES_QUICK_FRAMES`
    frames of every run."""
    name = "6.2.1-changes-online"
    log = progress_log(progress)
    if quick:
        ds = simulated(out, CHANGES_PRESET, seed, quick=True, camera=sim.PanoramicCamera(60, 8),
                       max_frames=CHANGES_QUICK_FRAMES, progress=progress)
    else:
        ds = simulated(out, CHANGES_PRESET, seed, quick=False, progress=progress)
    make_net, prep, recipe = long_term_configuration(CONFIG, quick)
    run_a, run_b, test = (load_run(ds.select(run=r), prep, log=log) for r in ("A", "B", "test"))
    if quick:
        run_a, run_b, test = ((X[::CHANGES_QUICK_STEP], xy[::CHANGES_QUICK_STEP]) for X, xy in (run_a, run_b, test))
    both = (np.concatenate([run_a[0], run_b[0]]), np.concatenate([run_a[1], run_b[1]]))
    elev = tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))
    models: dict[str, Any] = {}
    med: dict[str, float] = {}
    ext: dict[str, int] = {}
    secs: dict[str, float] = {}
    models["stale"], secs["stale"] = _fit_changes(make_net, *run_a, recipe, elev, memory=readout_memory)
    log(f"{name}: stale model trained on A ({len(run_a[1])} frames) in {secs['stale']:.1f} s")
    for resolve, label in zip(RESOLVES, ("updated", LABEL_ALL)):
        t0 = time.perf_counter()
        models[label] = LocalizerUpdater(models["stale"], UpdatePolicy(resolve=resolve)).partial_fit(*run_b).localizer_
        secs[label] = time.perf_counter() - t0
        log(f"{name}: updated with B ({len(run_b[1])} frames, resolve {resolve}) in {secs[label]:.1f} s")
    models["retrained"], secs["retrained"] = _fit_changes(make_net, *both, recipe, elev)
    log(f"{name}: retrained on A + B in {secs['retrained']:.1f} s")
    # the online peer: the top stage learned by IncSFA from A's, then B's sequence; the readout refitted
    models[LABEL_INCSFA], incsfa = incsfa_update(models["stale"], run_a, run_b, mca_rates=INCSFA_MCA_RATES,
                                                 n_whitened=INCSFA_WHITENED, seed=seed, like=models["updated"],
                                                 log=lambda msg: log(f"{name}: {msg}"))
    secs[LABEL_INCSFA] = incsfa["seconds_update"]
    for label in CHANGES_LABELS[:5]:
        med[label], ext[label] = _med(models[label], *test)
    for label, run in (("perfect memory A", run_a), ("perfect memory A + B", both)):
        models[label] = baselines.PerfectMemory().fit(*run)
        med[label], ext[label] = float(localization_metrics(models[label].predict(test[0]), test[1])["med"]), 0
    log(f"{name}: MED (m) on the test walk " + ", ".join(f"{k} {v:.3f}" for k, v in med.items()))
    diagonal = area_diagonal(run_a[1])
    rows: list[dict[str, Any]] = [
        flag_row({"metric": f"MED (m) on the test walk [{label}]", "thesis": None, "sfanav": med[label],
                  "configuration": label}, extrapolated=ext[label], diagonal=diagonal) for label in CHANGES_LABELS]
    shown = {r["configuration"]: r["sfanav"] for r in rows}  # None: withheld (flag_row)

    def ratio(metric: str, a: str, b: str) -> dict[str, Any]:
        if shown[a] is None or shown[b] is None:
            return {"metric": metric, "thesis": None, "sfanav": None, "flag": "a MED it divides is withheld"}
        return {"metric": metric, "thesis": None, "sfanav": med[a] / med[b]}

    for label, tag in (("updated", ""), (LABEL_ALL, f" [{LABEL_ALL}]"), (LABEL_INCSFA, f" [{LABEL_INCSFA}]")):
        rows += [{"metric": f"update time / retrain time{tag}", "thesis": None,
                  "sfanav": secs[label] / secs["retrained"]},
                 ratio(f"updated / stale MED{tag}", label, "stale"),
                 ratio(f"updated / retrained MED{tag}", label, "retrained")]
    rows.append(ratio("stale / retrained MED", "stale", "retrained"))
    rows.append({"metric": f"mean canonical correlation with the exact top stage on A's views [{LABEL_INCSFA}]",
                 "thesis": None, "sfanav": float(np.mean(incsfa["canonical_a"]))})
    path = _plot_changes(out / f"{name}-med.png", name, shown)
    changed = ds.metadata.get("gardens", {}).get("after", {}).get("objects", [])
    what = "; ".join(f"{c} " + ", ".join(r["kind"] for r in changed if r["change"] == c)
                     for c in ("moved", "removed", "added") if any(r["change"] == c for r in changed))
    notes = (f"Scene: sim preset {CHANGES_PRESET} (seed {seed}): the 16x18 m garden of thesis-6.2.1-static; run A "
             f"({len(run_a[1])} frames, grid with crossings), then the garden changed ({what or 'no record'}); run B "
             f"({len(run_b[1])} frames, crossing grid, 2 m lanes) and the test walk ({len(test[1])} frames) in the "
             f"changed garden. Models: the sfanav default ({'tiny network, 60x8' if quick else '350x40'}, 6.2.1's "
             "training: simulated rotation 5 px, no robustness) trained on A with a readout memory of "
             f"{readout_memory} views and their images (stale); updated with B at its ground-truth positions, the "
             f"top stage re-solved and the readout refitted (updated), or every layer trained again on the "
             f"remembered and the new images, each view of B paired with the nearest view of A ({LABEL_ALL}); "
             "retrained from scratch on A then B as one sequence (retrained); perfect memory (rotational image "
             f"difference) of A and of A + B. {LABEL_INCSFA}: the stale model's lower layers frozen, its top stage "
             f"replaced by IncSFA (CCIPCA whitening of {incsfa['n_whitened']} directions, CIMCA; "
             f"{models['stale'].trained_network().n_outputs_} outputs) fed the exact top stage's training sequence "
             "(the frozen stages' outputs under every simulated rotation, image after image) expanded as that stage "
             f"expands it (degree {incsfa['degree']}), {incsfa['passes']} passes over A's sequence then "
             f"{incsfa['passes']} over B's (CIMCA's step {', '.join(f'{r:g}' for r in incsfa['mca_rates'])} of its "
             "bound in successive passes); the readout (its kind, the kernel learned again: the stale kernel belongs "
             f"to other features) refitted on the IncSFA features of the {incsfa['readout_views']} remembered and new "
             f"views; its update time: the passes over B, the features and the readout (the passes over A, "
             f"{incsfa['seconds_a']:.0f} s, are its training on A). Times: each update against the retrain, same "
             "process."
             + (f" Quick: every {CHANGES_QUICK_STEP}th of the first {CHANGES_QUICK_FRAMES} frames of every run, "
                "a smoke test, not a measurement." if quick else ""))
    return ExperimentResult(name, rows, [str(path)], notes,
                            details={"models": models, "med": med, "seconds": secs, "changes": changed,
                                     "dataset": ds, "incsfa": incsfa})


def _plot_changes(path: Path, name: str, med: dict[str, float | None]) -> Path:
    """A bar per model: MED (m), None for a withheld figure (no bar)."""
    from .._plotting import figure, save_figure

    fig = figure(8, 4)
    ax = fig.add_subplot()
    labels = list(med)
    values = [med[k] for k in labels]
    bars = ax.bar(range(len(labels)), [0.0 if v is None else v for v in values],
                  color=["0.55", "C0", "C1", "C3", "C2", "C7", "C7"][: len(labels)])
    for b, v in zip(bars, values):
        ax.annotate("withheld" if v is None else f"{v:.2f}", (b.get_x() + b.get_width() / 2, b.get_height()),
                    ha="center", va="bottom", fontsize=8)
    ax.set_xticks(range(len(labels)), [k.replace(", ", ",\n").replace(" A", "\nA") for k in labels], fontsize=8)
    ax.set_ylabel("MED on the test walk (m)")
    ax.set_title(f"{name}: a garden changed between runs A and B")
    return save_figure(fig, path, 120)


@register("6.2.1-changes-online", "a garden whose objects change between runs: the sfanav default trained on run A, "
          "updated with run B after the change, beside a retrain on A + B and perfect memory")
def exp_621_changes_online(out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    return run_changes(out, quick=quick, seed=seed, progress=progress)
