"""Fusing single-image estimates with odometry at run time, without ground
truth: the EKF's noise chosen on the training run by the innovations'
likelihood, and the start pose found from the first estimates.

* :func:`noise_from_run`: the :class:`OdometryEKF` noise (odometry distance
  and heading per step, measurement) for a run's estimates and odometry:
  the one whose fused track is nearest a reference track of the run
  (grid search, criterion ``"med"``), or without one the one that makes
  the estimates most likely (criterion ``"nll"``);
  :func:`noise_for_localizer` applies it to a localizer's *held-out*
  estimates of its training run (its fitted estimates there are in-sample,
  and for a model trained without ground truth they were fitted to the
  odometry itself: both make the filter overconfident), the reference
  being the positions its readout was fitted to (for a model trained
  without ground truth, the map learned from the run's images and
  odometry); computed at training time, stored in the model file. The
  filter has a fixed turn noise (:data:`TURN_NOISE`) and the same
  Mahalanobis gate (:data:`GATE_PROBABILITY`) when the noise is chosen and
  when it is used.
* :func:`start_pose_from_estimates`: the start pose (x, y, heading) of a run
  from the rigid fit of its first odometry positions to their estimates.
* :func:`fuse_images`: a localizer's estimates of a run's images and their
  fused track, the images' novelty included: the product's fused path
  (the experiments and the demo call it; ``sfanav localize --odometry``
  runs the same filter online, :class:`sfanav.odometry.StreamingLocalizer`).
* :func:`fuse`: the fused track of a run; with the images' novelty
  (:meth:`sfanav.Localizer.novelty`) each estimate's measurement noise is
  scaled by :func:`novelty_scale`, so that the filter follows the odometry
  where the test run leaves the training run's ground.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .._checks import as_matrix, check_int, check_nonneg_float, check_positive_float, check_same_length
from ..data.camera_gamma import CameraGamma, predict_corrected
from ..localization.error_metrics import align, euclidean_errors
from ..localization.novelty import NoveltyReference
from ..localization.readout_selection import block_folds, cross_val_predict
from .dead_reckoning import as_poses, wrap_angle
from .ekf import OdometryEKF, grid_search

NOISE_KEYS = ("distance_noise", "heading_noise", "measurement_noise")
TURN_NOISE = 0.1
"""The EKF's heading noise per sqrt(radian) of turn in fusion without ground
truth (:class:`OdometryEKF` ``turn_noise``): fixed, not chosen on the
training run, whose map shares its odometry and so favours trusting it."""
START_FRAMES = 30
"""Frames whose estimates fix a run's start pose."""
GATE_PROBABILITY = 0.999
"""Mahalanobis gate of the fused estimates (:class:`OdometryEKF`
``gate_probability``), the same when the noise is chosen and when it is used."""
NOVELTY_THRESHOLD = 1.0
"""Novelty (in training nearest-neighbour distances) above which an
estimate's measurement noise grows in proportion (:func:`novelty_scale`):
1, as far as training images lie from each other, so that the noise is
proportional to the novelty wherever an image is farther from the training
run than its own images are. Chosen against 0.5, 2 and 3 on the mower
surveys' test walks, the demo and three suite gardens, with the filter
noise chosen on the training run alike (docs/odometry.md, "Fusion off the
training run's ground")."""
NOVELTY_KNEE_QUANTILE = 0.75
"""Quantile of the training run's held-out novelty up to which
:func:`noise_for_localizer`'s fitted novelty exponent holds: beyond it (no
held-out image was that novel) the noise grows in proportion to the
novelty again (:func:`novelty_scale`'s ``knee``)."""
NOISE_OPTIONAL = ("turn_noise", "novelty_exponent", "novelty_knee")
"""Keys a filter noise mapping may give beside :data:`NOISE_KEYS`."""
MEASUREMENT_NOISE_GRID = (0.05, 0.1, 0.2, 0.4, 0.8)
"""Candidate ``measurement_noise`` (m) of :func:`noise_for_localizer`: that
of a familiar image, whose novelty is at most :data:`NOVELTY_THRESHOLD`
(the grid search's default ends at 0.4 m; with novelty the 0.8 m step
measured 3 % better over 13 runs, docs/odometry.md)."""
MAX_FRAMES = 2000
"""Frames of the training run the noise is chosen on (the grid search's cost grows with them)."""


def _estimates(estimates: Any, poses: np.ndarray) -> np.ndarray:
    Z = np.asarray(estimates, dtype=float)
    if Z.ndim != 2 or Z.shape[1] != 2:
        raise ValueError(f"estimates must have shape (N, 2) (x, y in metres), got shape {Z.shape}")
    check_same_length(poses, Z, "odometry", "estimates")
    if np.isinf(Z).any():
        raise ValueError("estimates contain infinity (use NaN rows for missing estimates)")
    return Z


def start_pose_from_estimates(odometry: Any, estimates: Any, *, n: int = START_FRAMES,
                              measurement_scale: Any = None) -> np.ndarray:
    """The pose (x m, y m, heading rad) of a run's first frame in the
    estimates' frame: the rigid transform that best fits the first ``n``
    odometry positions (with an estimate) to their estimates (refitted once
    without the estimates far off the first fit), applied to the first
    odometry pose. ``measurement_scale`` (N,), as :func:`fuse` scales the
    estimates' noise (:func:`novelty_scale`): those above 1 are left out
    where at least half of the first ``n`` (and 3 that move) remain.
    ValueError when those frames do not move (their direction is then
    unknown)."""
    P = as_poses(odometry, "odometry")
    Z = _estimates(estimates, P)
    n = check_int(n, "n", minimum=2)
    ok = np.flatnonzero(np.isfinite(Z).all(axis=1))[:n]
    if measurement_scale is not None:
        m = np.asarray(measurement_scale, dtype=np.float64).reshape(-1)
        if m.shape != (len(P),):
            raise ValueError(f"measurement_scale must have one value per frame ({len(P)}), got shape {m.shape}")
        trusted = ok[m[ok] <= 1.0]
        if 2 * len(trusted) >= len(ok) and len(trusted) >= 3 and np.ptp(P[trusted, :2], axis=0).max() >= 1e-6:
            ok = trusted
    if len(ok) < 2 or np.ptp(P[ok, :2], axis=0).max() < 1e-6:
        raise ValueError(f"the first {n} frames with estimates do not move in the odometry: the start heading "
                         "cannot be found from them")
    al = align(P[ok, :2], Z[ok])
    # one trimming round against outlying estimates: refit without those far above the median residual
    res = np.hypot(*(al.apply(P[ok, :2]) - Z[ok]).T)
    keep = ok[res <= 3.0 * max(np.median(res), 1e-9)]
    if len(keep) >= 2 and len(keep) < len(ok) and np.ptp(P[keep, :2], axis=0).max() >= 1e-6:
        al = align(P[keep, :2], Z[keep])
    xy = al.apply(P[:1, :2])[0]
    heading = float(wrap_angle(P[0, 2] + np.arctan2(al.rotation[1, 0], al.rotation[0, 0])))
    return np.array([xy[0], xy[1], heading])


def noise_from_run(odometry: Any, estimates: Any, *, reference: Any = None, start_pose: Any = None,
                   max_frames: int | None = MAX_FRAMES, turn_noise: float = TURN_NOISE, progress: bool = False,
                   measurement_scale: Any = None, **grid: Any) -> dict[str, float]:
    """The EKF noise for a run's odometry (N, 3) and estimates (N, 2), by
    :func:`sfanav.odometry.grid_search` on the run's first ``max_frames``
    frames (None: all; the grid runs the filter once per candidate).

    With ``reference`` (N, 2), positions of the run in the estimates' frame
    (metres; ground truth, or a map learned without it): the noise whose
    fused track is nearest to them (criterion ``"med"``). Without: the noise
    that makes the estimates most likely (``"nll"``), which trusts
    estimates whose errors are correlated in time (a smooth bias along the
    run) too much. ``start_pose`` defaults to
    :func:`start_pose_from_estimates`; ``grid`` overrides the candidate
    standard deviations; every candidate runs with ``turn_noise`` (rad per
    sqrt(rad) of turn, default :data:`TURN_NOISE`). ``measurement_scale``
    (N,): per-frame factors on the measurement noise, as :func:`fuse`
    applies them (:func:`novelty_scale`); the chosen ``measurement_noise``
    is then that of a frame with factor 1. Returns
    ``{"distance_noise", "heading_noise", "measurement_noise",
    "turn_noise"}``. Raises ValueError on mismatched or non-finite input."""
    P = as_poses(odometry, "odometry")
    Z = _estimates(estimates, P)
    T = None
    if reference is not None:
        T = as_matrix(reference, "reference", n_cols=2)
        check_same_length(P, T, "odometry", "reference")
    ms = None
    if measurement_scale is not None:
        ms = np.asarray(measurement_scale, dtype=np.float64).reshape(-1)
        if ms.shape != (len(P),):
            raise ValueError(f"measurement_scale must have one value per frame ({len(P)}), got shape {ms.shape}")
    if max_frames is not None:
        m = check_int(max_frames, "max_frames", minimum=2)
        P, Z = P[:m], Z[:m]
        T = None if T is None else T[:m]
        ms = None if ms is None else ms[:m]
    s0 = start_pose_from_estimates(P, Z, measurement_scale=ms) if start_pose is None else start_pose
    turn = check_nonneg_float(turn_noise, "turn_noise")
    res = grid_search(P, Z, s0, T, criterion="nll" if T is None else "med", progress=progress,
                      ekf_params={"turn_noise": turn, "gate_probability": GATE_PROBABILITY},
                      measurement_scale=ms, **grid)
    return {**{k: float(res.best_params[k]) for k in NOISE_KEYS}, "turn_noise": turn}


def noise_for_localizer(localizer: Any, features: Any, targets: Any, odometry: Any, *, block: int = 20,
                        n_folds: int = 5, novelty_threshold: float | None = NOVELTY_THRESHOLD,
                        fit_exponent: bool = True, **kwargs: Any) -> dict[str, float]:
    """The EKF noise for a fitted localizer, chosen on its training run:
    :func:`noise_from_run` on the odometry (N, 3) and the *held-out*
    estimates of the run (:func:`sfanav.localization.cross_val_predict` of
    ``block`` consecutive frames, fewer on short runs, of
    the localizer's readout on ``features`` (N, m), its rotation-pooled
    features of the run, and ``targets`` (N, 2), the positions its readout
    was fitted to: ground truth, or the learned positions), the noise whose
    fused track of the run is nearest ``targets``. With the localizer's
    novelty reference (and ``novelty_threshold`` not None) each held-out
    estimate's noise is scaled by :func:`novelty_scale` of its novelty
    against the other folds' features, as :func:`fuse_images` scales a test
    run's: the chosen ``measurement_noise`` is then that of a novelty at
    most ``novelty_threshold``, from :data:`MEASUREMENT_NOISE_GRID` unless
    ``kwargs`` give one. How the held-out errors grow with the novelty
    decides how the noise does (:func:`novelty_exponent`, returned as
    ``novelty_exponent``, up to the held-out novelty's
    :data:`NOVELTY_KNEE_QUANTILE`, returned as ``novelty_knee``; in
    proportion beyond): a scene whose estimates stay precise on novel
    images keeps trusting them (``fit_exponent`` False: in proportion
    throughout, as in models whose noise predates the exponent, without
    those keys). ``kwargs`` go to :func:`noise_from_run`.
    Raises ValueError as those."""
    n = len(np.asarray(targets))
    block = max(1, min(int(block), n // (2 * n_folds)))  # short runs: shorter blocks, each fold held out twice
    held = cross_val_predict(localizer.readout_spec_, features, targets, n_folds=n_folds, block=block)
    ref = getattr(localizer, "novelty_", None)
    if novelty_threshold is None or ref is None or "measurement_scale" in kwargs:
        return noise_from_run(odometry, held, reference=targets, **kwargs)
    F = as_matrix(features, "features")[:, : ref.reference_.shape[1]]
    nov = np.empty(n)
    for train, out in block_folds(n, n_folds, block):
        nov[out] = NoveltyReference().fit(F[train]).score(F[out])
    shape = {}
    if fit_exponent:
        shape = {"novelty_exponent": novelty_exponent(euclidean_errors(held, targets), nov),
                 "novelty_knee": max(float(novelty_threshold), float(np.quantile(nov, NOVELTY_KNEE_QUANTILE)))}
    kwargs["measurement_scale"] = noise_novelty_scale(shape, nov, novelty_threshold)
    kwargs.setdefault("measurement_noise", MEASUREMENT_NOISE_GRID)
    return {**noise_from_run(odometry, held, reference=targets, **kwargs), **shape}


def novelty_scale(novelty: Any, threshold: float = NOVELTY_THRESHOLD, *, exponent: float = 1.0,
                  knee: float = np.inf) -> np.ndarray:
    """The factor (N,) on each estimate's measurement noise from the images'
    novelty (N,) (:meth:`sfanav.Localizer.novelty`): 1 up to ``threshold``,
    ``(novelty / threshold) ** exponent`` up to ``knee`` (at least
    ``threshold``) and in proportion to the novelty beyond it, continuous
    (NaN novelty, a frame without an estimate: 1). ``exponent`` in [0, 1]
    (1, the default: proportional throughout; :func:`novelty_exponent` fits
    it on a training run). Raises ValueError for a non-positive threshold or
    knee, an exponent outside [0, 1] or negative novelty.

    >>> novelty_scale([0.5, 3.0, 9.0], 3.0).tolist()
    [1.0, 1.0, 3.0]
    >>> novelty_scale([4.0, 16.0, 32.0], 1.0, exponent=0.5, knee=16.0).tolist()
    [2.0, 4.0, 8.0]
    """
    t = check_positive_float(threshold, "novelty_threshold")
    p = check_nonneg_float(exponent, "novelty_exponent")
    if p > 1:
        raise ValueError(f"novelty_exponent must be in [0, 1], got {exponent!r}")
    k = float(knee)
    if not k > 0:
        raise ValueError(f"novelty_knee must be > 0, got {knee!r}")
    k = max(k, t)
    v = np.asarray(novelty, dtype=np.float64).reshape(-1)
    if (v[np.isfinite(v)] < 0).any() or np.isinf(v).any():
        raise ValueError("novelty must be finite and >= 0 (NaN where a frame has no estimate)")
    v = np.nan_to_num(v, nan=0.0)
    inner = np.maximum(1.0, np.minimum(v, k) / t) ** p
    return np.where(v > k, inner * v / k, inner)


def novelty_exponent(errors: Any, novelty: Any, *, bins: int = 10) -> float:
    """How an estimate's error grows with its image's novelty: the slope of
    the log mean error (N,) against the log median novelty (N,) over
    ``bins`` quantile bins of the novelty, clipped to [0, 1] (1: the error
    is proportional to the novelty; 0: unrelated). Fitted on a training
    run's held-out estimates (:func:`noise_for_localizer`), it tells a scene
    whose estimates stay precise off the training images (an indoor room
    whose test path runs between its training path's, docs/odometry.md)
    from one where they extrapolate. Frames with a NaN error or novelty are
    left out; fewer than three usable bins give 1. Raises ValueError for
    arrays of different lengths or negative values.

    >>> nov = np.linspace(1.0, 8.0, 200)
    >>> round(novelty_exponent(0.1 * nov ** 0.5, nov), 2)
    0.5
    """
    e = np.asarray(errors, dtype=np.float64).reshape(-1)
    v = np.asarray(novelty, dtype=np.float64).reshape(-1)
    if len(e) != len(v):
        raise ValueError(f"errors ({len(e)}) and novelty ({len(v)}) must have the same length")
    ok = np.isfinite(e) & np.isfinite(v)
    e, v = e[ok], v[ok]
    if (e < 0).any() or (v < 0).any():
        raise ValueError("errors and novelty must be >= 0")
    bins = check_int(bins, "bins", minimum=3)
    if len(v) < 3 * bins:
        return 1.0
    x = np.log(np.maximum(v, 1e-3))
    edges = np.quantile(x, np.linspace(0.0, 1.0, bins + 1))
    xs, ys = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        m = (x >= a) & (x <= b)
        mean = float(e[m].mean()) if m.sum() >= 3 else 0.0
        if mean > 0:
            xs.append(float(np.median(x[m])))
            ys.append(np.log(mean))
    if len(xs) < 3 or np.ptp(xs) <= 0:
        return 1.0
    return float(np.clip(np.polyfit(xs, ys, 1)[0], 0.0, 1.0))


def check_noise(noise: Mapping[str, float]) -> dict[str, float]:
    """A filter noise mapping as :func:`noise_from_run` and
    :func:`noise_for_localizer` return it, checked: :data:`NOISE_KEYS`
    required, :data:`NOISE_OPTIONAL` allowed, every value a float. Returns a
    new dict; ValueError for missing or unknown keys and for values that are
    not numbers."""
    if not isinstance(noise, Mapping):
        raise ValueError(f"noise must be a mapping of {', '.join(NOISE_KEYS)}, got {type(noise).__name__}")
    unknown = set(noise) - set(NOISE_KEYS) - set(NOISE_OPTIONAL)
    if unknown or not set(NOISE_KEYS) <= set(noise):
        raise ValueError(f"noise must give {', '.join(NOISE_KEYS)} (and optionally {', '.join(NOISE_OPTIONAL)}), "
                         f"got {sorted(noise)}")
    try:
        return {k: float(v) for k, v in noise.items()}
    except (TypeError, ValueError):
        raise ValueError(f"noise values must be numbers, got {dict(noise)!r}") from None


def noise_novelty_scale(noise: Mapping[str, float], novelty: Any,
                        threshold: float = NOVELTY_THRESHOLD) -> np.ndarray:
    """:func:`novelty_scale` of ``novelty`` (N,) with the exponent and knee a
    filter noise mapping holds (``novelty_exponent``, ``novelty_knee``;
    without them, as in models whose noise predates these keys: proportional)."""
    return novelty_scale(novelty, threshold, exponent=noise.get("novelty_exponent", 1.0),
                         knee=noise.get("novelty_knee", np.inf))


def fuse(odometry: Any, estimates: Any, noise: Mapping[str, float], *, start_pose: Any = None,
         gate_probability: float | None = GATE_PROBABILITY, stamps: Any = None, recovery: bool = True,
         return_filter: bool = False, gyro: Any = None, novelty: Any = None,
         novelty_threshold: float = NOVELTY_THRESHOLD) -> Any:
    """The fused track (N, 3): x, y in the estimates' frame (metres) and
    heading (radians), from a run's odometry (N, 3) and single-image
    estimates (N, 2; NaN rows missing) with the EKF noise ``noise`` (as
    :func:`noise_from_run` returns). ``start_pose`` defaults to
    :func:`start_pose_from_estimates`; outlying estimates are gated.

    ``stamps`` (N,), frame times in seconds, find steps over dropped frames
    by their duration. ``recovery`` (default True): the filter re-initialises
    from the estimates when it has lost the robot, scales the noise of
    steps over dropped frames and treats jumps as unknown displacements
    (:class:`OdometryEKF` defaults); False: none of that. With
    ``return_filter`` returns ``(poses, ekf)``, the fitted
    :class:`OdometryEKF` (``n_reinitializations_``, ``events_``). ``gyro``
    (N,), a yaw gyro's integrated heading (rad), is fused into the
    prediction's turns (:meth:`OdometryEKF.run`). ``novelty`` (N,), the
    images' novelty (:meth:`sfanav.Localizer.novelty`), scales each
    estimate's measurement noise by :func:`novelty_scale` with
    ``novelty_threshold`` and the noise's ``novelty_exponent`` and
    ``novelty_knee`` where it gives them; the start pose's fit then skips
    estimates above it where at least half of the first ones remain.

    Example
    -------
    >>> poses, ekf = fuse(odometry, estimates, noise, return_filter=True)  # doctest: +SKIP
    >>> print(f"{ekf.n_reinitializations_} re-initialisations")             # doctest: +SKIP
    """
    noise = check_noise(noise)
    P = as_poses(odometry, "odometry")
    Z = _estimates(estimates, P)
    ms = None
    if novelty is not None:
        ms = noise_novelty_scale(noise, novelty, novelty_threshold)
        if len(ms) != len(P):
            raise ValueError(f"novelty must have one value per frame ({len(P)}), got {len(ms)}")
    s0 = start_pose if start_pose is not None else start_pose_from_estimates(P, Z, measurement_scale=ms)
    off = {} if recovery else {"reinit_after": None, "gap_factor": None, "jump_factor": None}
    ekf = OdometryEKF(**{k: float(noise[k]) for k in NOISE_KEYS}, turn_noise=float(noise.get("turn_noise", 0.0)),
                      gate_probability=gate_probability, **off)
    poses = ekf.run(P, Z, s0, stamps=stamps, gyro=gyro, measurement_scale=ms)
    return (poses, ekf) if return_filter else poses


def fuse_images(localizer: Any, images: Any, odometry: Any, noise: Mapping[str, float] | None = None, *,
                novelty_threshold: float | None = NOVELTY_THRESHOLD, camera_gamma: bool = True,
                source: Any = None, conform: Any = None, **kwargs: Any) -> tuple[np.ndarray, np.ndarray]:
    """A fitted :class:`sfanav.Localizer`'s estimates (N, 2) of ``images``
    (N, H, W[, C], the model's input format, in the order they were taken)
    and their fused track (N, 3) with ``odometry`` (N, 3): :func:`fuse` with
    the model's filter noise (``localizer.info["ekf_noise"]`` unless
    ``noise`` is given) and the images' novelty
    (:meth:`sfanav.Localizer.predict_with_novelty`; None
    ``novelty_threshold``, or a model without a novelty reference: not
    scaled). ``camera_gamma`` (default True, as ``sfanav localize``): the
    camera's gamma estimated over the images so far and taken out
    (:class:`sfanav.data.camera_gamma.CameraGamma`, where the model holds
    its reference; a camera like the training run's is left as it is;
    ``source`` and ``conform``, the camera's images and the callable that
    made ``images`` of them, correct the camera's own pixels:
    :func:`sfanav.data.camera_gamma.predict_corrected`).
    ``kwargs`` go to :func:`fuse` (``gyro``, ``stamps``, ``start_pose``,
    ...). Returns ``(estimates, fused)``. Raises ValueError for a model
    without filter noise and no ``noise``, and as :func:`fuse`.

    >>> xy, track = fuse_images(loc, test_images, test_odometry)   # doctest: +SKIP
    """
    if noise is None:
        noise = getattr(localizer, "info", {}).get("ekf_noise")
        if noise is None:
            raise ValueError("the model holds no EKF noise (its training run had no odometry): pass noise")
    tracker = CameraGamma.for_localizer(localizer) if camera_gamma else None
    if novelty_threshold is not None and getattr(localizer, "novelty_", None) is not None:
        est, nov = predict_corrected(localizer, tracker, images, novelty=True, source=source, conform=conform)
        return est, fuse(odometry, est, noise, novelty=nov, novelty_threshold=novelty_threshold, **kwargs)
    est = predict_corrected(localizer, tracker, images, source=source, conform=conform)
    return est, fuse(odometry, est, noise, **kwargs)

