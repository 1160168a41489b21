"""The product path beside the thesis configuration and the peers, on one split.

Every localization experiment reports, on its own training and test runs:

* ``thesis configuration``: the estimates of the thesis's configuration as
  the experiment trains it (passed in, scored here alike);
* ``sfanav default [ground truth]``: :func:`sfanav.pipeline.train_localizer`
  (the one training recipe, what ``sfanav train`` runs) with the readout
  fitted to ground truth;
* ``sfanav default [no ground truth]``: the same recipe with
  ``supervision="odometry"`` (positions learned from the training run's
  images and odometry, and its yaw gyro where it has one, as ``sfanav
  train`` reads a dataset's ``gyro_heading``), only where the training run has odometry that
  fixes a map (else the note says why); its
  estimates are in the training run's odometry frame and are moved into the
  world frame for scoring only, by the rigid transform fitted on the
  training run (as ``sfanav demo`` and :func:`sfanav.localization.evaluate`
  do); both sfanav rows localize a test run as ``sfanav localize`` does, the
  camera's gamma estimated over the run and taken out
  (:class:`sfanav.data.camera_gamma.CameraGamma`: a factor of 1, the images
  as they are, on every scene measured);
* ``..., fused]``: where the test run has odometry, the single-image
  estimates fused with it (:func:`sfanav.odometry.fuse_images`: the
  measurement noise scaled by each image's novelty) with the EKF noise
  the recipe chose on the training run (the no-ground-truth model's for
  both; the supervised model's own where there is no such model);
* ``peer perfect memory`` and ``peer Fourier signature``
  (:mod:`sfanav.localization.baselines`), storing the training run's views
  and ground-truth positions;
* ratios: ``MED ratio sfanav default [ground truth] / best peer``, the same
  for the other sfanav rows, and ``MED ratio sfanav default [no ground
  truth] / [ground truth]``;
* ``training (s) sfanav default [ground truth]`` / ``[no ground truth]``
  and their ratio: the recipe's wall time on the training run, same
  process (a ratio: the machines are shared).

The sfanav rows and the peers see the same images: the run in the default
network's input format (:func:`product_runs` loads a dataset's runs so,
gray panoramas repeated into three channels for the RGB network, as ``sfanav
train`` would resize them through
:meth:`sfanav.data.Preprocessing.for_network`). Why and what was measured:
docs/experiments.md.

Example
-------
>>> train, tests = product_runs(dataset, default_network())            # doctest: +SKIP
>>> res = product_rows(train, tests, camera_elevation=(-30, 20))       # doctest: +SKIP
>>> print(format_rows(res.rows))                                       # doctest: +SKIP
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_images, as_matrix, check_same_length
from .._progress import Log, quiet_log
from .._sampling import evenly_spaced
from ..data.camera_gamma import CameraGamma, predict_corrected
from ..localization import baselines
from ..localization.error_metrics import align, localization_metrics
from ..localization.evaluation import coordinate_range
from ..localization.recipe import CAMERA_ELEVATION, Recipe, default_network, recipe_for
from ..sfa.network import Network

THESIS = "thesis configuration"
DEFAULT = "sfanav default"
PEERS = ("perfect memory", "Fourier signature")
MEASURES = (("MED (m)", "med"), ("MAE x (%)", "mae_x_pct"), ("MAE y (%)", "mae_y_pct"))
"""The measures every configuration gets: row prefix, key of
:func:`sfanav.localization.error_metrics.localization_metrics`."""


@dataclass
class ProductRun:
    """One run of a scene as the product rows take it.

    Attributes
    ----------
    images : array (N, H, W[, C])
        Panoramas in the sfanav network's input format, in temporal order.
    xy : array (N, 2)
        Ground-truth positions (m): the training run's for the supervised
        model, the peers and the frame alignment; the test run's for scoring.
    odometry : array (N, 3) or None
        Wheel odometry (x m, y m, heading rad); None (or any NaN) means the
        run has none.
    label : str
        Names a test run in the row names (``""`` for a scene's only test run).
    gyro : array (N,) or None
        A yaw gyro's integrated heading (rad), if the run has one: the
        training run's goes to the pose graph as ``sfanav train`` passes it.
    groups : array (N,) or None
        The recording each frame comes from, when the training run is
        several recordings of the same places: the default's readout is then
        chosen by holding out one recording at a time (``train_localizer``'s
        ``groups``).
    """

    images: Any
    xy: Any
    odometry: Any = None
    label: str = ""
    gyro: Any = None
    groups: Any = None

    def __post_init__(self) -> None:
        self.images = as_images(self.images, "images")
        self.xy = as_matrix(self.xy, "xy", n_cols=2)
        check_same_length(self.images, self.xy, "images", "xy")
        if self.odometry is not None:
            odo = np.asarray(self.odometry, dtype=float)
            if odo.ndim != 2 or odo.shape[1] < 3 or len(odo) != len(self.images):
                raise ValueError(f"odometry must have shape ({len(self.images)}, 3), got {odo.shape}")
            self.odometry = odo[:, :3] if np.isfinite(odo[:, :3]).all() else None
        if self.gyro is not None:
            g = np.asarray(self.gyro, dtype=float).reshape(-1)
            if len(g) != len(self.images):
                raise ValueError(f"gyro must have {len(self.images)} values, got {len(g)}")
            self.gyro = g if np.isfinite(g).all() else None
        if self.groups is not None:
            self.groups = np.asarray(self.groups)
            if self.groups.shape != (len(self.images),):
                raise ValueError(f"groups must hold one label per frame ({len(self.images)}), got shape "
                                 f"{self.groups.shape}")

    @property
    def has_odometry(self) -> bool:
        return self.odometry is not None


@dataclass
class ProductResult:
    """What :func:`product_rows` returns.

    Attributes
    ----------
    rows : list of dict
        ``{"metric", "thesis": None, "sfanav", "configuration", ...}``.
    note : str
        A paragraph for the experiment's notes (what each row is).
    models : dict
        ``"ground truth"`` / ``"no ground truth"``: the trained localizers.
    meds : dict
        Row name without the measure (``"sfanav default [ground truth]"``)
        -> MED (m), per test run.
    """

    rows: list[dict[str, Any]]
    note: str
    models: dict[str, Any] = field(default_factory=dict)
    meds: dict[str, float] = field(default_factory=dict)


def product_runs(dataset: Any, network: Network, *, train: str = "train", tests: Sequence[str] = ("test",),
                 labels: Sequence[str] | None = None, mirror: Any = None,
                 log: Log = quiet_log) -> tuple[ProductRun, list[ProductRun]]:
    """A dataset's training run and test runs (selected by ``run=``) in
    ``network``'s input format, with their ground truth, odometry and gyro
    (omnidirectional images unwarped about ``mirror``, as
    :func:`sfanav.data.sources.load_run` takes it).
    Panoramas are resized to the network's input
    (:meth:`sfanav.data.Preprocessing.for_network`); gray panoramas for an
    RGB network are read gray and repeated into three channels. ``labels``
    name the test runs in the rows (default: ``""`` for one test run, else
    the run names)."""
    from ..data.preprocessing import Preprocessing
    from ..data.sources import load_run

    prep = Preprocessing.for_network(network)
    h, w, c = network.input_shape
    gray_source = not bool(dataset.metadata.get("camera", {}).get("rgb", True))
    if gray_source and c == 3:
        prep = Preprocessing(prep.width, prep.height, True, prep.normalize)
    if labels is None:
        labels = [""] if len(tests) == 1 else list(tests)
    if len(labels) != len(tests):
        raise ValueError(f"{len(tests)} test runs but {len(labels)} labels")

    def one(run: str, label: str) -> ProductRun:
        part = dataset.select(run=run)
        X, xy = load_run(part, prep, mirror=mirror, log=log)
        if X.ndim == 3 and c == 3:
            X = np.repeat(X[..., None], 3, axis=3)
        return ProductRun(X, xy, part.odometry, label, part.gyro)

    return one(train, ""), [one(t, lab) for t, lab in zip(tests, labels)]


def _name(config: str, qualifiers: Sequence[str], label: str) -> str:
    q = [s for s in (*qualifiers, label) if s]
    return f"{config} [{', '.join(q)}]" if q else config


def _peer_queries(n: int, limit: int | None) -> np.ndarray:
    return np.arange(n) if limit is None else evenly_spaced(n, int(limit))


def product_rows(train: ProductRun, tests: Sequence[ProductRun], *, thesis: Sequence[Any] | None = None,
                 network: Callable[[], Network] | None = None, recipe: Recipe | None = None,
                 camera_elevation: Sequence[float] | None = None, peer_queries: int | None = 1000,
                 closures: str | None = None, seed: int = 0, progress: bool = False,
                 log: Log = quiet_log) -> ProductResult:
    """Trains the sfanav default on ``train`` (with ground truth and, where
    the run has odometry, without), scores it on every test run beside the
    thesis configuration's estimates and the peers, and returns the rows.

    Parameters
    ----------
    train : ProductRun
        The training run (images in ``network``'s input format).
    tests : sequence of ProductRun
        Test runs (same image format); their ``label`` names their rows and
        must be unique.
    thesis : sequence of arrays (N_i, 2) or None
        The thesis configuration's estimates (m, world frame) on each test run.
    network : callable returning an unfitted Network, or None
        Called once per model (default :func:`default_network`, 350x40 RGB).
    recipe : Recipe or None
        As :func:`sfanav.pipeline.train_localizer` takes it (None: the
        default's; a tiny quick network on 8-row panoramas needs
        ``recipe_for(rows="all")``).
    camera_elevation : (float, float) or None
        Elevations (deg) of the panoramas' lowest and highest rows.
    peer_queries : int or None
        The peers answer at most this many evenly spaced test images; the
        ratios to the best peer compare on those images.
    closures : "relative-pose", "min-warping", "auto", "heading" or None
        The pose graph's closures of the model without ground truth
        (:func:`sfanav.pipeline.train_localizer`; None: its default).
    seed, progress, log
        As :func:`~sfanav.pipeline.train_localizer`.

    Returns
    -------
    ProductResult

    Raises
    ------
    ValueError
        When test images differ in shape from the training images, labels
        repeat, or ``thesis`` does not match ``tests``.
    """
    from ..odometry.fusion import fuse_images
    from ..pipeline import train_localizer

    tests = list(tests)
    if not tests:
        raise ValueError("product_rows needs at least one test run")
    if len({t.label for t in tests}) != len(tests):
        raise ValueError(f"test run labels must be unique, got {[t.label for t in tests]}")
    for t in tests:
        if t.images.shape[1:] != train.images.shape[1:]:
            raise ValueError(f"test images {t.label!r} have shape {t.images.shape[1:]}, training images "
                             f"{train.images.shape[1:]}")
    if thesis is not None:
        thesis = [as_matrix(p, "thesis estimates", n_cols=2) for p in thesis]
        if len(thesis) != len(tests) or any(len(p) != len(t.xy) for p, t in zip(thesis, tests)):
            raise ValueError("thesis must give one (N, 2) array of estimates per test run, N its frames")
    make = network or default_network
    kw = dict(network=None, recipe=recipe, camera_elevation=camera_elevation, seed=seed, progress=progress, log=log)
    models: dict[str, Any] = {}
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    models["ground truth"] = train_localizer(train.images, xy=train.xy, odometry=train.odometry,
                                             supervision="ground-truth", groups=train.groups,
                                             **{**kw, "network": make()})
    seconds["ground truth"] = time.perf_counter() - t0
    frames = {"ground truth": None}
    missing = ""
    if train.has_odometry:
        try:
            t0 = time.perf_counter()
            ngt = train_localizer(train.images, odometry=train.odometry, gyro=train.gyro, supervision="odometry",
                                  closures=closures, groups=train.groups, **{**kw, "network": make()})
            seconds["no ground truth"] = time.perf_counter() - t0
        except ValueError as exc:  # the run's odometry fixes no metric map (too short, never straight, ...)
            missing = f"no '[no ground truth]' rows: the training run's odometry fixes no map ({exc}); "
            log(missing)
        else:
            models["no ground truth"] = ngt
            frames["no ground truth"] = align(ngt.predict(train.images), train.xy)  # scoring only
    noise = next((m.info["ekf_noise"] for k, m in reversed(list(models.items())) if "ekf_noise" in m.info), None)
    peers = {name: model.fit(train.images, train.xy) for name, model in (
        ("perfect memory", baselines.PerfectMemory()),
        ("Fourier signature", baselines.FourierSignature(
            min(baselines.FourierSignature().n_coefficients, train.images.shape[2] // 2 + 1))))}

    rows: list[dict[str, Any]] = []
    meds: dict[str, float] = {}
    scene = tests[0].label if len(tests) == 1 else ""  # an experiment with one training per test run names it
    for sup, sec in seconds.items():
        rows.append({"metric": f"training (s) {_name(DEFAULT, (sup,), scene)}", "thesis": None, "sfanav": sec,
                     "configuration": DEFAULT, "supervision": sup})
    for sup, loc in models.items():  # the recipe's feedback decision (sfanav.pipeline.FEEDBACK)
        change = loc.info.get("revisit change")
        if change is not None:
            rows.append({"metric": f"revisit ratio {_name(DEFAULT, (sup,), scene)}", "thesis": None,
                         "sfanav": change.get("ratio"), "configuration": DEFAULT, "supervision": sup,
                         "feedback closures": (loc.info.get("feedback") or {}).get("count", 0)})
    if len(seconds) == 2:
        rows.append({"metric": "training time ratio sfanav default [no ground truth] / [ground truth]"
                               + (f" [{scene}]" if scene else ""), "thesis": None,
                     "sfanav": seconds["no ground truth"] / max(seconds["ground truth"], 1e-9),
                     "configuration": DEFAULT})

    def add(name: str, config: str, pred: np.ndarray, xy: np.ndarray, crange: np.ndarray, **extra: Any) -> None:
        m = localization_metrics(pred, xy, coordinate_range=crange)
        for label, key in MEASURES:
            rows.append({"metric": f"{label} {name}", "thesis": None, "sfanav": m[key], "configuration": config,
                         **extra})
        meds[name] = m["med"]

    for i, t in enumerate(tests):
        crange = coordinate_range(t.xy)
        q = _peer_queries(len(t.xy), peer_queries)
        errors: dict[str, np.ndarray] = {}
        if thesis is not None:
            add(_name(THESIS, (), t.label), THESIS, thesis[i], t.xy, crange)
        for sup, loc in models.items():
            if t.has_odometry and noise is not None:  # the estimates and their fused track: the product's path
                est, fused = fuse_images(loc, t.images, t.odometry, noise)
            else:  # the camera's gamma over the run taken out, as sfanav localize does (1 on a camera like training's)
                est, fused = predict_corrected(loc, CameraGamma.for_localizer(loc), t.images), None
            world = frames[sup]
            scored = world.apply(est) if world is not None else est
            name = _name(DEFAULT, (sup,), t.label)
            add(name, DEFAULT, scored, t.xy, crange, supervision=sup)
            errors[name] = np.hypot(*(scored - t.xy).T)
            if fused is not None:
                fused = fused[:, :2]
                fused = world.apply(fused) if world is not None else fused
                name = _name(DEFAULT, (sup, "fused"), t.label)
                add(name, DEFAULT, fused, t.xy, crange, supervision=sup)
                errors[name] = np.hypot(*(fused - t.xy).T)
        peer_meds = {}
        for pname, peer in peers.items():
            pred = peer.predict(t.images[q])
            m = localization_metrics(pred, t.xy[q], coordinate_range=crange)
            name = _name("peer " + pname, (), t.label)
            for label, key in MEASURES:
                rows.append({"metric": f"{label} {name}", "thesis": None, "sfanav": m[key], "baseline": pname,
                             "configuration": "peer"})
            meds[name] = peer_meds[pname] = m["med"]
        best = min(peer_meds, key=peer_meds.get)
        for name, err in errors.items():
            rows.append({"metric": f"MED ratio {name} / best peer", "thesis": None,
                         "sfanav": float(err[q].mean() / peer_meds[best]) if peer_meds[best] > 0 else float("inf"),
                         "configuration": DEFAULT, "best peer": best})
        for fused in ((), ("fused",)):
            a, b = _name(DEFAULT, ("no ground truth", *fused), t.label), _name(DEFAULT, ("ground truth", *fused),
                                                                                t.label)
            if a in meds and b in meds:
                qual = ", ".join(s for s in (*fused, t.label) if s)
                rows.append({"metric": "MED ratio sfanav default [no ground truth] / [ground truth]"
                             + (f" [{qual}]" if qual else ""), "thesis": None,
                             "sfanav": meds[a] / meds[b] if meds[b] > 0 else float("inf"), "configuration": DEFAULT})
        log(f"product rows{' ' + t.label if t.label else ''}: "
            + ", ".join(f"{k} {v:.3f} m" for k, v in meds.items() if k in errors or k.startswith("peer ")))
    fused_any = any(t.has_odometry for t in tests) and noise is not None
    note = (
        "Product rows (same split; images "
        f"{'x'.join(str(s) for s in train.images.shape[1:])}, the sfanav network's input): 'sfanav default "
        "[ground truth]' is sfanav.pipeline.train_localizer (what sfanav train runs) with the readout fitted to "
        "ground truth; "
        + ("'[no ground truth]' the same recipe fitted to the positions learned from the training run's images and "
           "odometry (pose graph), its estimates moved into the world frame for scoring only by the rigid "
           "transform fitted on the training run; " if "no ground truth" in models else
           missing or "no '[no ground truth]' rows: the training run has no odometry; ")
        + ("'..., fused]' the single-image estimates fused with the test run's odometry (EKF, noise chosen on the "
           "training run by the recipe); " if fused_any else "no fused rows: no test run has odometry; ")
        + f"'peer ...' perfect memory and the Fourier signature store the same training views with their "
        f"ground-truth positions and answer at most {peer_queries or 'all'} evenly spaced test images; 'MED ratio "
        "... / best peer' compares on those images."
    )
    return ProductResult(rows, note, models, meds)


QUICK_TRAIN_FRAMES = 80
"""At most this many training frames in the ``--quick`` product rows (every k-th frame of the run)."""


def quick_network() -> Network:
    """The tiny network of the experiments' ``--quick`` product rows: 60x8
    RGB, two layers (seconds to train; numbers not meaningful)."""
    return Network({
        "input": {"width": 60, "height": 8, "channels": 3},
        "network": {"precision": "mixed"},
        "layers": [{"rf": [6, 4], "stride": [3, 4], "out": 8}, {"rf": "full", "out": 8}],
    })


def configuration(quick: bool) -> tuple[Callable[[], Network], Recipe | None]:
    """(network factory, recipe) of the product rows: the sfanav default's
    (None: :func:`sfanav.pipeline.train_localizer`'s default recipe), or for
    ``quick`` the tiny :func:`quick_network` on all its 8 rows without the
    Fourier signature beside the slow features (the readout's selection,
    with the signature's hundreds of dimensions, would take minutes)."""
    if quick:
        return quick_network, recipe_for(rows="all", signature=None)
    return default_network, None


def quick_subsample(run: ProductRun, limit: int = QUICK_TRAIN_FRAMES) -> ProductRun:
    """Every k-th frame of ``run`` (images, positions, odometry, gyro and
    recordings alike), at most ``limit`` frames: a quick run's training set."""
    step = -(-len(run.xy) // limit)
    if step <= 1:
        return run

    def every(a: Any) -> Any:
        return None if a is None else a[::step]

    return ProductRun(run.images[::step], run.xy[::step], every(run.odometry), run.label, every(run.gyro),
                      every(run.groups))


def scene_rows(dataset: Any, *, quick: bool, thesis: Sequence[Any] | None = None, tests: Sequence[str] = ("test",),
               labels: Sequence[str] | None = None, peer_queries: int | None = 1000, seed: int = 0,
               progress: bool = False, mirror: Any = None, log: Log = quiet_log) -> ProductResult:
    """:func:`product_rows` on a simulated dataset's ``train`` run and its
    ``tests`` runs: the sfanav default network (350x40 RGB; ``quick``: the
    tiny :func:`quick_network` on all its 8 rows) on the panoramas resized to
    its input, the horizon band placed by the dataset's camera elevation;
    ``quick``: :func:`configuration` and :func:`quick_subsample`;
    ``mirror``: for omnidirectional images, the mirror they are unwarped
    about."""
    net, recipe = configuration(quick)
    train, runs = product_runs(dataset, net(), tests=tests, labels=labels, mirror=mirror, log=log)
    train = quick_subsample(train) if quick else train
    elevation = tuple(dataset.metadata.get("camera", {}).get("elevation_deg", CAMERA_ELEVATION))
    return product_rows(train, runs, thesis=thesis, network=net, recipe=recipe,
                        camera_elevation=elevation, peer_queries=peer_queries, seed=seed, progress=progress,
                        log=log)
