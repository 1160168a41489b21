"""Localizing live: image and odometry events in, one fused pose per image
out, independent of any transport (ROS, a socket, a recording).

:class:`StreamingLocalizer` takes image events and odometry events, each
with an integer stamp in nanoseconds, in any order within a configurable
reordering window and at any rates. For each image it emits one
:class:`LiveEstimate`, stamped with the image's exact stamp: the
single-image estimate of a fitted :class:`sfanav.Localizer`, the odometry
pose interpolated to that stamp and the pose of the EKF
(:class:`sfanav.OdometryEKF`, its online :meth:`~sfanav.OdometryEKF.step`)
with its covariance.

The filter is the one ``sfanav localize --odometry`` runs, and that command
is this object run over a recording: the start pose comes from the first
``start_frames`` images (:func:`sfanav.odometry.fusion.start_pose_from_estimates`),
so those images are emitted together once the start pose is known; the
nominal odometry step, against which a step over dropped frames (gap) or a
jump is told, is the median moving step of those images. Measurements and
the rules are in ``docs/live.md``.
"""

from __future__ import annotations

import heapq
from collections import Counter, deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .._checks import as_real_array, check_int, check_nonneg_float, check_positive_float
from ..data.camera_gamma import CameraGamma, predict_corrected
from ..data.preprocessing import Preprocessing, Preprocessor
from .dead_reckoning import increments, wrap_angle
from .ekf import FilterStep, OdometryEKF
from .fusion import (GATE_PROBABILITY, NOISE_KEYS, NOVELTY_THRESHOLD, START_FRAMES, check_noise, noise_novelty_scale,
                     start_pose_from_estimates)
from .recovery import step_anomalies

DROP_REASONS = ("late", "duplicate", "before_odometry", "no_odometry", "odometry_overflow")
"""Why an event was dropped (:attr:`StreamingLocalizer.dropped_`): ``late``
(older than the reordering window allows: an event of its kind with a later
stamp was already processed), ``duplicate`` (a second image, or odometry,
with the same stamp), ``before_odometry`` (an image older than the first
odometry kept: no pose to interpolate), ``no_odometry`` (an image still
waiting for the odometry after it when ``max_pending`` newer images waited
too, or at :meth:`StreamingLocalizer.flush`), ``odometry_overflow`` (the
oldest odometry pose when ``max_odometry`` newer ones wait for an image)."""


@dataclass(frozen=True)
class LiveEstimate:
    """What :class:`StreamingLocalizer` emits for one image.

    Attributes
    ----------
    stamp_ns : int
        The image's stamp, exactly as given (nanoseconds).
    estimate : ndarray (2,)
        The single-image estimate ``(x, y)`` in metres, map frame.
    odometry : ndarray (3,)
        The odometry pose ``(x [m], y [m], heading [rad])`` interpolated to the
        stamp (odometry frame).
    pose : ndarray (3,) or None
        The fused pose ``(x [m], y [m], heading [rad])``, map frame; None when
        the stream ended before a start pose could be found.
    covariance : ndarray (3, 3) or None
        Its covariance (m^2, m rad, rad^2).
    step : FilterStep or None
        The filter's account of the frame (gating, re-initialisation, events).
    """

    stamp_ns: int
    estimate: np.ndarray
    odometry: np.ndarray
    pose: np.ndarray | None
    covariance: np.ndarray | None
    step: FilterStep | None


def as_stamp(stamp: Any, what: str = "stamp") -> int:
    """An integer stamp in nanoseconds (Python or NumPy integer; TypeError
    for anything else: a float stamp loses nanoseconds)."""
    if isinstance(stamp, (bool, np.bool_)) or not isinstance(stamp, (int, np.integer)):
        raise TypeError(f"{what} must be an integer number of nanoseconds, got {type(stamp).__name__} {stamp!r}")
    return int(stamp)


class StreamingLocalizer:
    """Image and odometry events in, one fused pose per image out.

    Parameters
    ----------
    localizer : Localizer
        A fitted :class:`sfanav.Localizer` (the single-image estimates).
    noise : mapping, optional
        The EKF noise (``distance_noise``, ``heading_noise``,
        ``measurement_noise``, optionally ``turn_noise``; as
        :func:`sfanav.odometry.noise_from_run` returns). Default: the
        model's, ``localizer.info["ekf_noise"]``; ValueError when it has none.
    window_ns : int, default 0
        Reordering window in nanoseconds: an event is processed once an
        event at least this much newer has arrived (or at :meth:`flush`), so
        images, or odometry poses, arriving out of order by less than this
        are put back in order. An image older than an image already
        processed is dropped (``late``), and so is an odometry pose older
        than one processed. Images and odometry need no window between
        them: an image waits for the odometry after its stamp, and the
        odometry since the last image is kept. 0: events are processed as
        they come (the right choice for a recording).
    start_frames : int, default 30
        Images whose estimates fix the start pose (and the nominal
        odometry step).
    max_pending : int, default 100
        Images that may wait for the odometry after their stamp; beyond, the
        oldest is dropped (``no_odometry``).
    max_odometry : int, default 1000
        Odometry poses kept for images still to come (those after the last
        image); beyond, the oldest is dropped (``odometry_overflow``).
    gate_probability : float or None, default 0.999
        The filter's Mahalanobis gate (as ``localize``).
    recovery : bool, default True
        Re-initialise a lost filter, scale the noise of gaps and treat jumps
        as unknown displacements (:class:`sfanav.OdometryEKF` defaults).
    image_shape : tuple, optional
        The shape every image must have; default: the first image's.
    mirror, log
        For the :class:`sfanav.data.preprocessing.Preprocessor` that conforms
        images to the model (omnidirectional mirror; where its one line goes).
    rotations : bool, default False
        :meth:`sfanav.Localizer.predict` averaged over rotations.
    novelty_threshold : float or None, default :data:`~sfanav.odometry.fusion.NOVELTY_THRESHOLD`
        Each estimate's measurement noise is scaled by
        :func:`~sfanav.odometry.fusion.novelty_scale` of its image's novelty
        (:meth:`sfanav.Localizer.novelty`) with the noise's
        ``novelty_exponent`` and ``novelty_knee``, as
        :func:`sfanav.odometry.fuse` does. None, or a model file without a
        novelty reference (one line through ``log`` says so): not scaled.
    camera_gamma : bool or None, default None
        Take the camera's gamma out of each image before the localizer sees
        it, as estimated over the stream so far against the training views
        where the images are placed (:class:`sfanav.data.camera_gamma.CameraGamma`;
        a factor of 1 for the first images and within its dead zone, so a
        camera like the training run's is left exactly as it is; a batch is
        localized again only while a factor applies). None (the default):
        wherever the model file holds the training run's reference; True:
        the same, and a model without it (trained without a photometric
        normalisation, or before 2026-12-07) gets one line through ``log``;
        False: never.
    on_estimate : callable, optional
        Called as ``on_estimate(stamp_ns, estimate)`` (estimate: ndarray (2,),
        metres, map frame) as soon as an image's single-image estimate is
        computed, in the order the images come: before its
        :class:`LiveEstimate`, which waits for the odometry after the image
        and, at the start, for the first ``start_frames`` images. A live
        node publishes the single-image estimate from it without that delay.

    Attributes
    ----------
    n_images_ : int
        Images pushed (with a valid shape).
    n_emitted_ : int
        :class:`LiveEstimate` objects emitted.
    dropped_ : Counter
        Dropped events by reason (:data:`DROP_REASONS`).
    initialized_ : bool
        Whether the start pose is known.
    n_reinitializations_, n_jumps_, n_gaps_ : int
        Filter events so far.
    n_novel_ : int
        Images whose estimate's measurement noise their novelty scaled up
        (0 without novelty scaling).
    max_measurement_scale_ : float
        The largest such factor so far (1 when none).
    init_error_ : str or None
        Why no start pose was found when :meth:`flush` emitted images
        without a fused pose.

    Raises
    ------
    ValueError, TypeError
        Bad parameters; per event, an image of another shape than the first
        or a non-finite odometry pose (naming the stamp), a non-integer stamp.

    Example
    -------
    >>> live = StreamingLocalizer(loc, window_ns=50_000_000)        # doctest: +SKIP
    >>> live.push_odometry(t_ns, (x, y, heading))                    # doctest: +SKIP
    >>> for est in live.push_image(t_ns, image):                     # doctest: +SKIP
    ...     publish(est.stamp_ns, est.pose, est.covariance)
    """

    def __init__(self, localizer: Any, noise: Mapping[str, float] | None = None, *, window_ns: int = 0,
                 start_frames: int = START_FRAMES, max_pending: int = 100, max_odometry: int = 1000,
                 gate_probability: float | None = GATE_PROBABILITY, recovery: bool = True,
                 image_shape: Iterable[int] | None = None, mirror: Any = None,
                 log: Callable[[str], None] | None = None, rotations: bool = False,
                 on_estimate: Callable[[int, np.ndarray], None] | None = None,
                 novelty_threshold: float | None = NOVELTY_THRESHOLD, camera_gamma: bool | None = None) -> None:
        if noise is None:
            noise = getattr(localizer, "info", {}).get("ekf_noise")
            if noise is None:
                raise ValueError("the model holds no EKF noise (its training run had no odometry): pass noise, "
                                 "or retrain it on a run with odometry")
        noise = check_noise(noise)
        self.localizer = localizer
        self.noise = noise
        self.window_ns = as_stamp(window_ns, "window_ns")
        if self.window_ns < 0:
            raise ValueError(f"window_ns must be >= 0, got {window_ns}")
        self.start_frames = check_int(start_frames, "start_frames", minimum=2)
        self.max_pending = check_int(max_pending, "max_pending", minimum=1)
        self.max_odometry = check_int(max_odometry, "max_odometry", minimum=2)
        self.rotations = bool(rotations)
        self.novelty_threshold = (None if novelty_threshold is None
                                  else check_positive_float(novelty_threshold, "novelty_threshold"))
        if self.novelty_threshold is not None and getattr(localizer, "novelty_", None) is None:
            if log is not None:
                log("the model holds no novelty reference (a Localizer file written before 2026-12-06, or another "
                    "kind of model): the filter's measurement noise is not scaled by novelty")
            self.novelty_threshold = None
        self.camera_gamma = CameraGamma.for_localizer(localizer) if camera_gamma is not False else None
        if camera_gamma is True and self.camera_gamma is None and log is not None:
            log("the model holds no camera gamma reference (trained without a photometric normalisation, or before "
                "2026-12-07): the images' gamma is not corrected")
        if on_estimate is not None and not callable(on_estimate):
            raise TypeError(f"on_estimate must be callable or None, got {type(on_estimate).__name__}")
        self.on_estimate = on_estimate
        self.image_shape = None if image_shape is None else tuple(int(v) for v in image_shape)
        off = {} if recovery else {"reinit_after": None, "gap_factor": None, "jump_factor": None}
        self.filter = OdometryEKF(**{k: float(noise[k]) for k in NOISE_KEYS},
                                  turn_noise=check_nonneg_float(noise.get("turn_noise", 0.0), "turn_noise"),
                                  gate_probability=gate_probability, **off)
        self.filter.start((0.0, 0.0, 0.0))  # validates the noise and gate now, not at the first image
        self._last_pose: np.ndarray | None = None
        self._log = log
        self._said_gamma: tuple[float, bool] = (1.0, False)  # the tracker's factor and reverting, as last logged
        kw = {} if log is None else {"log": log}
        self._conform = Preprocessor(Preprocessing.of_model(localizer), mirror=mirror, **kw)
        self._events: list[tuple[int, int, int, Any]] = []  # heap of (stamp, kind, seq, payload); kind 0 odometry, 1 image
        self._seq = 0
        self._newest: int | None = None
        self._last: dict[int, int | None] = {0: None, 1: None}  # last processed stamp per kind
        self._odometry: deque[tuple[int, np.ndarray]] = deque()
        self._pending: deque[tuple[int, np.ndarray]] = deque()
        self._init: list[tuple[int, np.ndarray, np.ndarray]] = []
        self._nominal = 0.0
        self.n_images_ = 0
        self.n_emitted_ = 0
        self.dropped_: Counter = Counter()
        self.initialized_ = False
        self.n_reinitializations_ = self.n_jumps_ = self.n_gaps_ = 0
        self.n_novel_ = 0
        self.max_measurement_scale_ = 1.0
        self.init_error_: str | None = None

    # ------------------------------------------------------------------ input
    def push_image(self, stamp_ns: int, image: Any) -> list[LiveEstimate]:
        """One image (H, W) or (H, W, C) stamped ``stamp_ns``: its estimate is
        computed now; returns the :class:`LiveEstimate` objects ready (this
        image's once the odometry after its stamp has arrived)."""
        return self.push_images([stamp_ns], np.asarray(image)[None])

    def push_images(self, stamps_ns: Iterable[int], images: Any) -> list[LiveEstimate]:
        """Several images (N, H, W[, C]) at once (one batch through the
        network: a recording's path), with their stamps (N,)."""
        stamps = [as_stamp(s, "image stamp") for s in stamps_ns]
        imgs = np.asarray(images)
        if imgs.ndim < 3 or len(imgs) != len(stamps):
            raise ValueError(f"images must be a batch (N, H, W[, C]) with one stamp each, got shape {imgs.shape} "
                             f"and {len(stamps)} stamps")
        if self.image_shape is None:
            self.image_shape = tuple(imgs.shape[1:])
        if tuple(imgs.shape[1:]) != self.image_shape:
            raise ValueError(f"image at stamp {stamps[0]} ns has shape {tuple(imgs.shape[1:])}, but this stream's "
                             f"images have shape {self.image_shape}")
        keep = [i for i, s in enumerate(stamps) if not self._late(s, 1)]
        out: list[LiveEstimate] = []
        if keep:
            raw = imgs[keep]
            batch = self._conform(raw)
            # localized again once the camera's gamma is taken out (of the camera's own pixels, then conformed)
            scaled = self.novelty_threshold is not None
            got = predict_corrected(self.localizer, self.camera_gamma, batch, novelty=scaled, source=raw,
                                    conform=self._conform, rotations=self.rotations)
            xy, nov = got if scaled else (got, None)
            self._say_gamma()
            if nov is None:
                ms = np.ones(len(xy))
            else:
                ms = noise_novelty_scale(self.noise, nov, self.novelty_threshold)
                self.n_novel_ += int((ms > 1).sum())
                self.max_measurement_scale_ = max(self.max_measurement_scale_, float(ms.max(initial=1.0)))
            self.n_images_ += len(keep)
            for i, z, m in zip(keep, xy, ms):
                z = np.asarray(z, dtype=np.float64)
                if self.on_estimate is not None and stamps[i] != self._last[1]:  # not a processed stamp again
                    self.on_estimate(stamps[i], z.copy())
                self._add(stamps[i], 1, np.r_[z, m])  # the estimate and its measurement scale
            out = self._release()
        return out

    def _say_gamma(self) -> None:
        """One line through ``log`` when the camera-gamma tracker starts, changes (by 5 % or more) or stops
        correcting, or its guard starts or stops leaving the images as they came."""
        cg = self.camera_gamma
        if cg is None or self._log is None:
            return
        reverting = cg.novelty_gain_ <= 0  # NaN (no correction judged yet) compares False
        f0, r0 = self._said_gamma
        if abs(np.log(cg.factor_ / f0)) < np.log(1.05) and reverting == r0:
            return
        self._said_gamma = (cg.factor_, reverting)
        if cg.factor_ == 1.0:
            self._log(f"camera gamma: as the training run's (log spread ratio {np.exp(-cg.log_ratio_):.2f}); "
                      "images as they come")
        elif reverting:
            self._log(f"camera gamma: a power of {cg.factor_:.2f} would take it out, but the corrected images are "
                      "farther from the training views: images as they come")
        else:
            self._log(f"camera gamma: the images are taken through a power of {cg.factor_:.2f} (their log spread "
                      f"{np.exp(-cg.log_ratio_):.2f}x the training views')")

    def push_odometry(self, stamp_ns: int, pose: Any) -> list[LiveEstimate]:
        """One odometry pose ``(x [m], y [m], heading [rad])`` stamped
        ``stamp_ns`` (odometry frame; any rate). Returns the estimates ready."""
        s = as_stamp(stamp_ns, "odometry stamp")
        p = as_real_array(pose, "odometry pose").astype(np.float64).ravel()
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"odometry at stamp {s} ns must be a finite (x [m], y [m], heading [rad]), got {pose!r}")
        if self._late(s, 0):
            return []
        self._add(s, 0, p)
        return self._release()

    def flush(self) -> list[LiveEstimate]:
        """End of stream: processes every buffered event, emits what can be
        (images without odometry after them are dropped, ``no_odometry``) and,
        when the stream ended before ``start_frames`` images, starts the
        filter on the images there are (without a fused pose if they do not
        move: :attr:`init_error_` says why)."""
        out = self._release(everything=True)
        for _ in range(len(self._pending)):
            self._pending.popleft()
            self.dropped_["no_odometry"] += 1
        if not self.initialized_ and self._init:
            out += self._start(final=True)
        return out

    # --------------------------------------------------------------- internals
    def _late(self, stamp: int, kind: int) -> bool:
        last = self._last[kind]
        if last is not None and stamp < last:
            self.dropped_["late"] += 1
            return True
        return False

    def _add(self, stamp: int, kind: int, payload: np.ndarray) -> None:
        heapq.heappush(self._events, (stamp, kind, self._seq, payload))
        self._seq += 1
        self._newest = stamp if self._newest is None else max(self._newest, stamp)

    def _release(self, everything: bool = False) -> list[LiveEstimate]:
        out: list[LiveEstimate] = []
        assert self._newest is not None or not self._events
        while self._events and (everything or self._events[0][0] <= self._newest - self.window_ns):
            stamp, kind, _, payload = heapq.heappop(self._events)
            last = self._last[kind]
            if last is not None and stamp <= last:  # late events are refused on arrival: an equal stamp
                self.dropped_["duplicate"] += 1
                continue
            self._last[kind] = stamp
            if kind == 0:
                self._odometry.append((stamp, payload))
                if len(self._odometry) > self.max_odometry:
                    self._odometry.popleft()
                    self.dropped_["odometry_overflow"] += 1
            else:
                self._pending.append((stamp, payload))
                if len(self._pending) > self.max_pending:
                    self._pending.popleft()
                    self.dropped_["no_odometry"] += 1
            out += self._match()
        return out

    def _match(self) -> list[LiveEstimate]:
        """Pairs the waiting images with the odometry interpolated to their stamps."""
        out: list[LiveEstimate] = []
        odo = self._odometry
        while self._pending and odo:
            t, zm = self._pending[0]
            z, m = zm[:2], float(zm[2])
            if odo[0][0] > t:
                self._pending.popleft()
                self.dropped_["before_odometry"] += 1
                continue
            if odo[-1][0] < t:
                break
            while len(odo) > 1 and odo[1][0] <= t:
                odo.popleft()
            t0, p0 = odo[0]
            if t0 == t:
                pose = p0.copy()
            else:
                t1, p1 = odo[1]
                f = (t - t0) / (t1 - t0)
                pose = np.array([p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]),
                                 p0[2] + f * wrap_angle(p1[2] - p0[2])])
            self._pending.popleft()
            out += self._frame(t, pose, z, m)
        t_img = self._last[1]
        if not self._pending and t_img is not None:  # later images come after t_img: the pose before it suffices
            while len(odo) > 1 and odo[1][0] <= t_img:
                odo.popleft()
        return out

    def _frame(self, stamp: int, pose: np.ndarray, z: np.ndarray, m: float) -> list[LiveEstimate]:
        if self.initialized_:
            return [self._step(stamp, pose, z, m)]
        self._init.append((stamp, pose, z, m))
        if sum(bool(np.isfinite(e).all()) for _, _, e, _ in self._init) >= self.start_frames:
            return self._start(final=False)
        return []

    def _start(self, *, final: bool) -> list[LiveEstimate]:
        P = np.array([p for _, p, _, _ in self._init])
        Z = np.array([z for _, _, z, _ in self._init])
        M = np.array([m for _, _, _, m in self._init])
        try:
            s0 = start_pose_from_estimates(P, Z, n=self.start_frames, measurement_scale=M) if len(P) >= 2 else None
            if s0 is None:
                raise ValueError("one image is not enough for a start heading")
        except ValueError as exc:
            if not final:  # not moving yet: the oldest image goes out without a fused pose, the next may start
                stamp, pose, z, _ = self._init.pop(0)
                return [self._emit(stamp, pose, z, None)]
            self.init_error_ = str(exc)
            out = [self._emit(s, p, z, None) for s, p, z, _ in self._init]
            self._init = []
            return out
        d = np.abs(increments(P)[:, 0]) if len(P) > 1 else np.zeros(0)
        moving = d[d > 1e-9]
        self._nominal = float(np.median(moving)) if len(moving) else 0.0
        self.filter.start(s0)
        self.initialized_ = True
        frames, self._init = self._init, []
        return [self._step(s, p, z, m) for s, p, z, m in frames]

    def _step(self, stamp: int, pose: np.ndarray, z: np.ndarray, m: float = 1.0) -> LiveEstimate:
        scale, jump = 1.0, False
        if self._last_pose is not None:
            sc, jp = step_anomalies(increments(np.stack([self._last_pose, pose])), gap_factor=self.filter.gap_factor,
                                    jump_factor=self.filter.jump_factor, nominal=self._nominal)
            scale, jump = float(sc[0]), bool(jp[0])
        st = self.filter.step(pose, z, scale=scale, jump=jump, measurement_scale=m)
        self._last_pose = pose
        self.n_reinitializations_ += int(st.reinitialized)
        self.n_jumps_ += int(st.jumped)
        self.n_gaps_ += int(scale > 1)
        return self._emit(stamp, pose, z, st)

    def _emit(self, stamp: int, pose: np.ndarray, z: np.ndarray, st: FilterStep | None) -> LiveEstimate:
        self.n_emitted_ += 1
        return LiveEstimate(stamp, z, pose, None if st is None else st.pose, None if st is None else st.covariance, st)
