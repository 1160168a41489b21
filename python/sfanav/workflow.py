"""The end-to-end localization workflow behind ``sfanav train``,
``localize``, ``evaluate``, ``demo`` and the localization experiments.

* :class:`Preprocessing`: what the network's input images look like (panorama
  size, gray or RGB, per-image normalisation); stored in the model file so
  that ``localize`` treats new images the way training did.
* :class:`Conformer`: turns images from any source into that input:
  unwarps omnidirectional images (given mirror parameters or
  :func:`sfanav.estimate_mirror`), resizes panoramas of another size, converts
  to gray, normalises; says what it did through a ``log`` function.
* :func:`open_images`: a dataset directory, a folder of images or a video
  file as an :class:`ImageSource` of batches.
* :func:`fit_localizer`: train a network under simulated rotation and fit
  the regression to metric positions.
* :func:`evaluate`: metrics of a localizer on a test run (honest protocol)
  and with the thesis's random splits, eta values, error against the number
  of outputs, the two baselines (perfect memory, Fourier signature), PNG
  plots and a Markdown report.

Units: positions in metres, image sizes as (width, height) in pixels, times
in milliseconds where named ``*_ms``.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import analysis, baselines, regression
from .dataset import Dataset, read_image
from .localizer import Localizer
from .metrics import localization_metrics
from .network import Network, Rotation

__all__ = [
    "Conformer",
    "Evaluation",
    "ImageSource",
    "Preprocessing",
    "evaluate",
    "evaluation_rows",
    "fit_localizer",
    "load_run",
    "open_images",
    "stderr_log",
]

Log = Callable[[str], None]
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv")


def stderr_log(message: str) -> None:
    """The default ``log``: one line on stderr."""
    print(message, file=sys.stderr, flush=True)


def _quiet(message: str) -> None:
    pass


# --------------------------------------------------------------------- preprocessing


@dataclass(frozen=True)
class Preprocessing:
    """The images a trained network expects.

    Attributes
    ----------
    width, height : int
        Panorama size in pixels; ``width`` is the full 360 degrees (the
        rotation period), which may be wider than the network's input
        window.
    gray : bool
        One channel (ITU-R 601 luma) instead of RGB.
    normalize : bool
        Each image shifted and scaled to zero mean and unit variance
        (thesis 5.2.1), float32.
    """

    width: int
    height: int
    gray: bool
    normalize: bool = False

    @classmethod
    def for_network(cls, network: Network, *, window: float = 1.0, normalize: bool = False) -> "Preprocessing":
        """The input of ``network`` when trained with a ``window`` (fraction of
        the panorama it sees): width = network input width / window."""
        h, v, c = network.input_shape
        width = int(round(v / window))
        if round(window * width) != v:  # pragma: no cover - rounding corner
            width += 1
        return cls(width, h, c == 1, normalize)

    def to_dict(self) -> dict[str, Any]:
        return {"width": self.width, "height": self.height, "gray": self.gray, "normalize": self.normalize}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Preprocessing":
        try:
            return cls(int(d["width"]), int(d["height"]), bool(d["gray"]), bool(d.get("normalize", False)))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"invalid preprocessing record {d!r}: {exc}") from None

    @classmethod
    def of_model(cls, loc: Localizer) -> "Preprocessing":
        """What a saved localizer expects: its stored record, or (models
        saved from Python) the network's input as it is."""
        rec = (loc.info or {}).get("preprocessing")
        if rec:
            return cls.from_dict(rec)
        if loc.network is None:
            raise ValueError("this model has no network: it localizes from features, not images")
        net = loc.network
        period = getattr(net, "_period", None)
        h, v, c = net.input_shape
        return cls(int(period or v), h, c == 1, False)

    @property
    def size(self) -> tuple[int, int]:
        return (self.width, self.height)

    def describe(self) -> str:
        return f"{self.width}x{self.height} {'gray' if self.gray else 'RGB'}{', normalized' if self.normalize else ''}"


def _to_gray(batch: np.ndarray) -> np.ndarray:
    if batch.ndim == 3:
        return batch
    import cv2

    return np.stack([cv2.cvtColor(np.ascontiguousarray(b), cv2.COLOR_RGB2GRAY) for b in batch])


def _normalize(batch: np.ndarray) -> np.ndarray:
    a = batch.astype(np.float32)
    flat = a.reshape(len(a), -1)
    mean = flat.mean(axis=1, dtype=np.float64)
    std = flat.std(axis=1, dtype=np.float64)
    std[std == 0] = 1.0
    return ((flat - mean[:, None]) / std[:, None]).astype(np.float32).reshape(a.shape)


def _parse_mirror(mirror: Any) -> tuple[float, float, float, float] | None:
    if mirror is None:
        return None
    if isinstance(mirror, str):
        parts = mirror.replace(" ", "").split(",")
    else:
        parts = list(mirror)
    try:
        vals = tuple(float(p) for p in parts)
    except (TypeError, ValueError):
        raise ValueError(f"mirror must be CX,CY,INNER,OUTER (pixels), got {mirror!r}") from None
    if len(vals) != 4 or not all(np.isfinite(vals)) or not 0 <= vals[2] < vals[3]:
        raise ValueError(f"mirror must be CX,CY,INNER,OUTER with 0 <= INNER < OUTER (pixels), got {mirror!r}")
    return vals  # type: ignore[return-value]


class Conformer:
    """Turns batches of images (uint8, (n, H, W[, 3]) RGB or (n, H, W) gray)
    into the network's input described by ``prep``.

    The first batch decides what is needed, and ``log`` says so once:

    * the panorama size already: used as it is;
    * an omnidirectional (mirror) image, recognised by its aspect ratio
      (width < 2 x height): unwarped with ``mirror = (cx, cy, inner, outer)``
      pixels, or with the mirror :func:`sfanav.estimate_mirror` finds in the
      first batch;
    * a panorama of another size: resized (area interpolation).

    Then RGB becomes gray if the network is gray, and each image is
    normalised if ``prep.normalize``.
    """

    def __init__(self, prep: Preprocessing, *, mirror: Any = None, log: Log = stderr_log) -> None:
        self.prep = prep
        self.mirror = _parse_mirror(mirror)
        self.log = log
        self.mode: str | None = None
        self._unwarper: Any = None
        self.message = ""
        self.mirror_used: tuple[float, float, float, float] | None = None

    def _decide(self, batch: np.ndarray) -> None:
        h, w = batch.shape[1], batch.shape[2]
        W, H = self.prep.size
        if (w, h) == (W, H):
            self.mode = "as-is"
            return
        if w < 2 * h:
            from .unwarp import Unwarper, estimate_mirror

            if self.mirror is not None:
                cx, cy, r0, r1 = self.mirror
                self._unwarper = Unwarper((cx, cy), r0, r1, (W, H))
                how = f"given mirror: center ({cx:.1f}, {cy:.1f}) px, radii {r0:.1f}..{r1:.1f} px"
            else:
                m = estimate_mirror(batch)
                self._unwarper = m.unwarper((W, H))
                self.mirror = (float(m.center[0]), float(m.center[1]), float(m.inner_radius), float(m.outer_radius))
                how = (f"estimated mirror center ({m.center[0]:.1f}, {m.center[1]:.1f}) px, radii "
                       f"{m.inner_radius:.1f}..{m.outer_radius:.1f} px; pass --mirror CX,CY,INNER,OUTER to set it")
            self.mode = "unwarp"
            self.mirror_used = self.mirror
            self.message = f"unwarping {w}x{h} omnidirectional images to {W}x{H} panoramas: {how}"
        else:
            self.mode = "resize"
            self.message = f"resizing {w}x{h} images to {W}x{H}, the panorama size the model was trained on"
        self.log(self.message)

    def __call__(self, batch: np.ndarray) -> np.ndarray:
        a = np.asarray(batch)
        if a.ndim not in (3, 4):
            raise ValueError(f"images must be (n, H, W) or (n, H, W, 3), got shape {a.shape}")
        if self.mode is None:
            self._decide(a)
        if self.mode == "unwarp":
            a = self._unwarper.transform(a)
        elif self.mode == "resize":
            import cv2

            a = np.stack([cv2.resize(np.ascontiguousarray(b), self.prep.size, interpolation=cv2.INTER_AREA) for b in a])
        if a.shape[1:3] != (self.prep.height, self.prep.width):
            raise ValueError(f"images are {a.shape[2]}x{a.shape[1]} after conversion, expected "
                             f"{self.prep.width}x{self.prep.height}; do all images have one size?")
        if self.prep.gray:
            a = _to_gray(a)
        elif a.ndim == 3:
            raise ValueError("the model takes RGB images, but these are gray")
        if self.prep.normalize:
            a = _normalize(a)
        return a


# --------------------------------------------------------------------- sources


@dataclass
class ImageSource:
    """Images to localize: ``batches(batch_size)`` yields uint8 arrays in
    order; ``frames`` are their ids (dataset frame ids, else 0, 1, ...);
    ``xy`` the ground truth (datasets only, else None); ``n`` the count if known."""

    kind: str
    description: str
    n: int | None
    frames: np.ndarray | None
    xy: np.ndarray | None
    _batches: Callable[[int], Iterator[np.ndarray]]

    def batches(self, batch_size: int = 64) -> Iterator[np.ndarray]:
        return self._batches(batch_size)


def _is_dataset_dir(p: Path) -> bool:
    return any((p / f).exists() for f in ("frames.csv", "metadata.json", "database_entries.csv"))


def _one_camera(ds: Dataset, camera: str | None) -> Dataset:
    if camera is not None:
        if camera not in set(ds.cameras.tolist()):
            raise ValueError(f"no camera {camera!r} in {ds.root}; cameras: {', '.join(sorted(set(ds.cameras.tolist())))}")
        return ds.select(camera=camera)
    cams = sorted(set(ds.cameras.tolist()))
    if len(cams) > 1:
        if "center" in cams:
            return ds.select(camera="center")
        raise ValueError(f"{ds.root} has several cameras ({', '.join(cams)}); choose one with --camera")
    return ds


def select_run(ds: Dataset, run: str | None, camera: str | None = None) -> Dataset:
    """The images of one run (all if ``run`` is None) and one camera."""
    if run is not None:
        runs = sorted(set(ds.runs.tolist()))
        if run not in runs:
            raise ValueError(f"no run {run!r} in {ds.root}; runs: {', '.join(runs)}")
        ds = ds.select(run=run)
    ds = _one_camera(ds, camera)
    if len(ds) == 0:
        raise ValueError(f"no images in {ds.root} for run {run!r}")
    return ds


def open_images(path: str | os.PathLike, *, run: str | None = None, camera: str | None = None) -> ImageSource:
    """A dataset directory (sfanav format or an insect-navigation database),
    a folder of images (``.png``, ``.jpg``, ..., in sorted name order) or a
    video file (read with ``cv2.VideoCapture``) as an :class:`ImageSource`.
    ``run`` and ``camera`` filter a dataset."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no such file or directory: {p}")
    if p.is_dir():
        if _is_dataset_dir(p):
            ds = select_run(Dataset(p), run, camera)
            gray = False

            def ds_batches(bs: int) -> Iterator[np.ndarray]:
                return ds.images(batch_size=bs, gray=gray)

            return ImageSource("dataset", f"dataset {p} ({len(ds)} images)", len(ds), ds.frames.copy(),
                               ds.poses[:, :2].copy(), ds_batches)
        if run is not None:
            raise ValueError(f"--run applies to datasets; {p} is an image folder")
        files = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise ValueError(f"{p} holds no images ({', '.join(IMAGE_SUFFIXES)}) and is not a dataset")

        def folder_batches(bs: int) -> Iterator[np.ndarray]:
            buf: list[np.ndarray] = []
            for f in files:
                img = read_image(f)
                if buf and img.shape != buf[0].shape:
                    raise ValueError(f"image {f} has shape {img.shape}, unlike {buf[0].shape} before it")
                buf.append(img)
                if len(buf) == bs:
                    yield np.stack(buf)
                    buf = []
            if buf:
                yield np.stack(buf)

        return ImageSource("folder", f"image folder {p} ({len(files)} images)", len(files),
                           np.arange(len(files)), None, folder_batches)
    if run is not None:
        raise ValueError(f"--run applies to datasets; {p} is a file")
    import cv2

    cap = cv2.VideoCapture(str(p))
    ok = cap.isOpened()
    count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0) if ok else 0
    cap.release()
    if not ok:
        raise ValueError(f"{p} is not a dataset, an image folder or a video OpenCV can read")

    def video_batches(bs: int) -> Iterator[np.ndarray]:
        cap = cv2.VideoCapture(str(p))
        buf: list[np.ndarray] = []
        try:
            while True:
                ok, frame = cap.read()
                if not ok:
                    break
                buf.append(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB) if frame.ndim == 3 else frame)
                if len(buf) == bs:
                    yield np.stack(buf)
                    buf = []
        finally:
            cap.release()
        if buf:
            yield np.stack(buf)

    return ImageSource("video", f"video {p} (~{count} frames)", count or None, None, None, video_batches)


def load_run(ds: Dataset, prep: Preprocessing, *, mirror: Any = None, log: Log = stderr_log,
             progress: bool = False, batch_size: int = 64,
             conformer: Conformer | None = None) -> tuple[np.ndarray, np.ndarray]:
    """All images of a (one-camera) dataset as the network's input array and
    their positions (N, 2) in metres (converted by ``conformer``, or a new
    :class:`Conformer` with ``mirror``)."""
    conform = conformer or Conformer(prep, mirror=mirror, log=log)
    out: np.ndarray | None = None
    bar = _bar(progress, len(ds), "reading images")
    i = 0
    for batch in ds.images(batch_size=batch_size):
        b = conform(batch)
        if out is None:
            out = np.empty((len(ds),) + b.shape[1:], b.dtype)
        out[i : i + len(b)] = b
        i += len(b)
        if bar is not None:
            bar.update(len(b))
    if bar is not None:
        bar.close()
    if out is None:
        raise ValueError(f"no images in {ds.root}")
    return out, ds.poses[:, :2].copy()


def _bar(enabled: bool, total: int | None, desc: str) -> Any:
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="img", leave=False)


# --------------------------------------------------------------------- training


def fit_localizer(
    network: Network,
    images: np.ndarray,
    xy: np.ndarray,
    *,
    rotation: Rotation | None = None,
    n_outputs: int | None = None,
    readout: str | dict[str, Any] = "auto",
    rows: Any = None,
    prep: Preprocessing | None = None,
    progress: bool = True,
    info: dict[str, Any] | None = None,
    rotation_pooling: int | str | None = "auto",
) -> Localizer:
    """Trains ``network`` on ``images`` (the training run, in temporal order)
    under simulated rotation and fits the readout of its slowest outputs to
    ``xy`` (N, 2) metres.

    ``readout``, ``n_outputs``: as :class:`Localizer` (default ``"auto"``:
    the sfanav default's GP, or kernel ridge / kNN by blocked CV, on this
    run; ``readout="quadratic", n_outputs=8`` is the thesis's). ``rows``: an
    :class:`sfanav.imagerows.ImageRows` applied to the images before the
    network, in training and (stored in the localizer) at every query.
    ``rotation_pooling``: as :class:`Localizer` (``"auto"``: 8 rotations
    unless the readout is the thesis's quadratic one). The
    returned localizer's ``info`` records preprocessing, rotation, training
    time (seconds: network) and readout selection time."""
    rotation = rotation or Rotation()
    if rows is not None and not rows.identity:
        images = rows(images)
    else:
        rows = None
    t0 = time.perf_counter()
    network.fit(images, rotation, progress=progress)
    fit_s = time.perf_counter() - t0
    if n_outputs is not None and n_outputs > network.n_outputs_:
        raise ValueError(f"n_outputs={n_outputs}, but the network has only {network.n_outputs_} outputs")
    loc = Localizer(network, n_outputs=n_outputs, readout=readout, rows=rows, rotation_pooling=rotation_pooling)
    t1 = time.perf_counter()
    loc.fit_features(loc.transform_rows(images), xy)
    readout_s = time.perf_counter() - t1
    loc.info = dict(info or {})
    if prep is not None:
        loc.info["preprocessing"] = prep.to_dict()
    loc.info.update({"rotation": {"step": rotation.step, "window": rotation.window},
                     "n_train_images": int(len(images)), "fit_seconds": round(fit_s, 2),
                     "readout_seconds": round(readout_s, 2), "readout": loc.describe_readout(),
                     "rotation_pooling": int(loc.rotation_pooling_)})
    if loc.selection_ is not None:
        loc.info["readout_rule"] = loc.selection_.rule
    return loc


# --------------------------------------------------------------------- evaluation


@dataclass
class Evaluation:
    """What :func:`evaluate` measured.

    Attributes
    ----------
    metrics : dict
        Test-run metrics of the SFA localizer
        (:func:`sfanav.metrics.localization_metrics`, metres and %), plus
        ``query_ms`` per image.
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
        :func:`sfanav.baselines.benchmark` results (metrics, ``query_ms``,
        ``bytes_per_place``).
    predictions : ndarray (N, 2)
    plots : list of (caption, path)
    report : Path or None
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
    log: Log = _quiet,
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
    net = loc._network()
    n_out = net.n_outputs_
    raw_test, raw_train = test_images, train_images  # the baselines see the panoramas as they are
    if loc.rows is not None and not loc.rows.identity:  # the network sees the rows the localizer applies
        test_images = loc.rows(test_images)
        train_images = None if train_images is None else loc.rows(train_images)
    t0 = time.perf_counter()
    F_test = loc.transform_rows(test_images)  # rotation pooled if the localizer pools
    sfa_ms = 1000.0 * (time.perf_counter() - t0) / len(test_images)
    pred = loc.predict_features(F_test)
    crange = coordinate_range(test_xy)
    m = localization_metrics(pred, test_xy, coordinate_range=crange)
    m["query_ms"] = sfa_ms
    ev = Evaluation(metrics=m, predictions=pred)
    ev.model_bytes = _model_bytes(loc)
    n_reg = loc.n_outputs_
    spec = loc.readout_spec_
    log(f"test run: MED {m['med']:.3f} m, MAE x {m['mae_x_pct']:.2f} %, y {m['mae_y_pct']:.2f} % "
        f"(readout {loc.describe_readout()})")
    if len(test_xy) >= 8:
        try:
            if spec["kind"] == "quadratic":
                ev.splits = regression.evaluate_random_splits(F_test, test_xy, n_outputs=n_reg,
                                                              ridge=float(spec.get("ridge", 0.0)),
                                                              n_repeats=n_repeats, random_state=seed)
            else:
                ev.splits = random_splits_readout(spec, F_test, test_xy, n_repeats=n_repeats, seed=seed)
        except ValueError as exc:  # too few samples for the expansion
            log(f"random splits skipped: {exc}")
    ns = range(2, n_out + 1)
    n_eta = min(n_eta, n_out)
    rot_angles = None
    R = None
    if train_images is not None and train_xy is not None:
        R = net.transform(train_images, rotations=True)
        ep, ef = analysis.eta_values(R[:, :, :n_eta])
        ev.eta_source = "training views under all simulated rotations (thesis 3.5)"
        F_train = loc.transform_rows(train_images)
        ev.curve = regression.error_vs_n(F_train, train_xy, F_test, test_xy, ns=ns)
        map_xy = train_xy
    else:
        R = net.transform(test_images, rotations=True)
        ep, ef = analysis.eta_values(R[:, :, :n_eta], normalize=True)
        ev.eta_source = "test views under all simulated rotations, normalised by each output's variance"
        map_xy = test_xy
    ev.eta_p, ev.eta_phi = ep, ef
    step = getattr(net, "_step", None)
    period = getattr(net, "_period", None) or test_images.shape[2]
    rot_angles = analysis.orientation_angles(R.shape[1], step=step, width=period) if step else None
    try:
        ev.curve_splits = regression.error_vs_n(F_test, test_xy, ns=ns, n_repeats=n_repeats, random_state=seed)
    except ValueError as exc:
        log(f"random-split error curve skipped: {exc}")
    if run_baselines and train_images is not None and train_xy is not None:
        q = np.arange(len(test_images))
        if baseline_queries is not None and len(q) > baseline_queries:
            q = np.unique(np.linspace(0, len(q) - 1, int(baseline_queries)).round().astype(int))
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
                         analysis.plot_firing_maps(R, map_xy, out / f"{prefix}firing_maps.png", which=which,
                                                   angles=rot_angles)))
        ev.plots.append(("test run: ground truth and estimates",
                         analysis.plot_trajectory(test_xy, pred, out / f"{prefix}trajectory.png", connect=False,
                                                  error_lines=True)))
        curve = ev.curve or ev.curve_splits
        if curve is not None:
            ev.plots.append((f"error vs number of outputs ({curve.protocol})", curve.plot(out / f"{prefix}error_vs_n.png")))
        ev.plots.append(("eta_p and eta_phi per output", analysis.plot_eta(ep, ef, out / f"{prefix}eta.png")))
        if report:
            ev.report = write_evaluation_report(ev, out / f"{prefix}report.md", title=title, text=text)
    return ev


def random_splits_readout(spec: dict[str, Any], features: np.ndarray, xy: np.ndarray, *, n_repeats: int = 100,
                          seed: int = 0) -> Any:
    """The thesis 5.1.1 protocol (random 50/50 splits of one run, mean over
    ``n_repeats``) with any readout ``spec`` (:func:`sfanav.readout.make_readout`;
    its hyperparameters as chosen on the training run). Returns a
    :class:`sfanav.regression.RegressionResult`; optimistic on a continuous walk."""
    from .readout import make_readout

    F = np.asarray(features, float)
    Y = np.asarray(xy, float)
    crange = coordinate_range(Y)
    rng = np.random.default_rng(seed)
    ms, tms = [], []
    pred_sum = np.zeros_like(Y)
    count = np.zeros(len(Y))
    for _ in range(n_repeats):
        perm = rng.permutation(len(F))
        tr, te = perm[: len(F) // 2], perm[len(F) // 2 :]
        r = make_readout(spec).fit(F[tr], Y[tr])
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
    from .readout import describe_spec

    return regression.RegressionResult(
        protocol=regression.RANDOM_SPLITS,
        description=f"random 50/50 splits of one run with readout {describe_spec(spec)}, {n_repeats} repeats "
                    "(thesis 5.1.1 protocol; optimistic on a continuous walk)",
        n_outputs=int(spec.get("n_outputs", F.shape[1])), ridge=float(spec.get("ridge", 0.0)), metrics=mean,
        metrics_std=std, train_metrics=tmean, predictions=pred, n_repeats=n_repeats)


def _fmt_list(a: np.ndarray) -> str:
    return ", ".join(f"{v:.3f}" for v in a)


def write_evaluation_report(ev: Evaluation, path: Path, *, title: str, text: Sequence[str] = ()) -> Path:
    """A Markdown report of an :class:`Evaluation`: metrics table (SFA on the
    test run, random splits, baselines), eta values, error curve, plots."""
    rows: dict[str, Any] = {"sfanav (test run)": {"protocol": regression.TEST_RUN, **ev.metrics,
                                                  "bytes_per_place": None}}
    if ev.splits is not None:
        rows["sfanav (random 50/50 splits of the test run)"] = ev.splits
    for name, b in ev.baselines.items():
        rows[f"{name} (test run)"] = {"protocol": regression.TEST_RUN, **b}
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
    return analysis.write_report(
        path, title=title, metrics=rows,
        columns=["protocol", "med", "mae_x", "mae_y", "mae_x_pct", "mae_y_pct", "p90", "query_ms", "bytes_per_place"],
        figures=ev.plots, text=paras,
    )


# --------------------------------------------------------------------- rows


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
    tr = {"protocol": regression.TEST_RUN}
    add("MAE x (%)", m["mae_x_pct"], **tr)
    add("MAE y (%)", m["mae_y_pct"], **tr)
    add("MAE x (m)", m["mae_x"], **tr)
    add("MAE y (m)", m["mae_y"], **tr)
    add("MED (m)", m["med"], **tr)
    if ev.splits is not None:
        s = ev.splits.metrics
        rs = {"protocol": regression.RANDOM_SPLITS}
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
        add("best n (random splits)", int(ev.curve_splits.best_n), protocol=regression.RANDOM_SPLITS)
    add("query ms", float(m["query_ms"]))
    if ev.model_bytes is not None:
        add("model bytes", int(ev.model_bytes))
    if baselines_rows:
        for name, b in ev.baselines.items():
            extra = {"protocol": regression.TEST_RUN, "baseline": name}
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
