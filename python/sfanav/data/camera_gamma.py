"""A camera's gamma, estimated over the images it sends and taken back out
before localization.

The photometric normalisation (:mod:`sfanav.data.photometric`) removes a
gain, a white balance and a vignetting exactly, but not a gamma: its
low-pass acts on the intensities before the logarithm, and a low-pass does
not commute with a power. A gamma ``255 (I / 255)^g`` scales the logarithm
of the intensities by ``g``, so it shows in how widely the log intensities
of an image spread (:func:`log_spread`: the standard deviation of ``log(I +
offset)`` of the low-passed image once each channel's quadratic profile
over the rows, a vignetting or the sky's gradient, is removed). But so does
the place: a view into a hedge spreads differently from a view over the
lawn, and a robot that keeps to part of the garden would read that as a
gamma. :class:`CameraGamma` therefore compares each image's spread with the
training images' *at the place the localizer puts it* (the median of its
nearest training views'), takes the median of those log ratios over recent
images, and, when it is beyond a dead zone, maps each image through the
power that brings the two together (:func:`apply_gamma`) before the
localizer sees it again. A camera like the training run's is left exactly
as it is; a camera with gamma ``g`` gets about ``1 / g``.

Where it helps and what it costs (the default's network, paired seed by
seed, four gardens; the corruption suite): docs/robustness.md, "The
camera's gamma from the stream".

Examples
--------
>>> import numpy as np
>>> from sfanav.data.camera_gamma import CameraGamma, log_spread
>>> rng = np.random.default_rng(0)
>>> sky = np.linspace(220, 60, 12)[:, None, None] * (0.8 + 0.2 * np.sin(np.linspace(0, 12, 60)))[None, :, None]
>>> run = (sky[None] * rng.uniform(0.8, 1.1, (40, 1, 60, 3))).astype(np.uint8)   # 40 panoramas, 12 x 60
>>> xy = np.c_[np.arange(40) * 0.25, np.zeros(40)]                               # where they were taken
>>> dark = (255 * (run / 255) ** 1.4).round().astype(np.uint8)       # the same run through a gamma of 1.4
>>> cg = CameraGamma(log_spread(run), xy, min_images=10)
>>> fixed = cg.correct(dark, xy)                                       # the localizer's estimates of dark
>>> round(cg.factor_, 2)                                               # about 1 / 1.4
0.72
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from .._checks import (as_image_batch, as_matrix, check_int, check_nonneg_float, check_positive_float,
                       check_same_length)
from .photometric import panorama_lowpass, row_profile_projector

OFFSET = 2.0
"""Grey levels added before the logarithm of the spread and the correction (a gamma is a scale of ``log(I)``
exactly; the offset keeps black pixels finite and bends that least at 2)."""
LOWPASS = 2.0
"""Gaussian low-pass (pixels, wrapping around the panorama's seam in columns) of the images before their log spread:
a defocus, motion blur, JPEG, noise and dead pixels change the fine structure's share of the spread (a 2 px defocus
read as a gamma of 0.63-0.67 in a suite garden without it, 0.87-0.89 with it), a gamma scales the coarse structure's
as much. The photometric normalisation's own width."""
WINDOW = 200
"""Recent images whose median log ratio :class:`CameraGamma` takes."""
MIN_IMAGES = 20
"""Ratios :class:`CameraGamma` waits for before it corrects (a factor of 1 until then, but for the images of the
batch in which they are reached)."""
NEIGHBOURS = 10
"""Training views nearest an image's estimate whose median spread is its reference."""
MAX_FACTOR = 2.0
"""Factors are clipped to ``1 / MAX_FACTOR .. MAX_FACTOR`` (gammas 0.5..2): beyond, the stream is no camera with
another gamma (a lens cap, night, a broken sensor), and a power that large would overflow."""
FLAT_SPREAD = 1e-3
"""Images whose log spread is below this (flat: black, saturated or a covered lens) add no ratio to the window."""
DEAD_ZONE = 0.2
"""Factors within ``exp(+-DEAD_ZONE)`` (0.82..1.22) are taken as 1. Measured on four gardens' test walks against
their training runs (docs/robustness.md): a flawless walk's median log ratio stays within 0.01, a 2 px defocus and
a clipped overexposure x1.5 within 0.05-0.18 (not a gamma: left alone), a gamma of 0.7 or 1.4 at 0.29-0.36."""


def log_spread(images: Any, *, offset: float = OFFSET, lowpass: float = LOWPASS) -> np.ndarray:
    """The log spread of each image (N, H, W[, C]) of 0..255 values: the
    standard deviation of ``log(I + offset)`` of the image low-passed by
    ``lowpass`` pixels (:data:`LOWPASS`; 0: none), after each channel's
    quadratic profile over the rows is removed (so that a vignetting, a white
    balance and a gain leave it, a blur, JPEG and noise nearly, and a gamma
    ``g`` scales it by about ``g``). Returns float64 (N,). Raises ValueError
    for a bad batch, offset or low-pass."""
    a = as_image_batch(images)
    off = check_positive_float(offset, "offset")
    sigma = check_nonneg_float(lowpass, "lowpass")
    if a.dtype != np.uint8 and not np.isfinite(a).all():
        raise ValueError("images must be finite (NaN or infinite values found)")
    h = a.shape[1]
    P = row_profile_projector(h)
    out = np.empty(len(a))
    for i, im in enumerate(a):
        v = im.astype(np.float32)  # the low-pass in float32: half the time of float64, spreads equal to ~1e-6
        if sigma > 0:
            v = panorama_lowpass(v, (sigma, sigma))
        L = np.log(np.maximum(v.astype(np.float64), 0.0) + off)
        rows = L.mean(axis=1)  # (H[, C])
        out[i] = float((L - (P @ rows.reshape(h, -1)).reshape((h, 1) + L.shape[2:])).std())
    return out


def apply_gamma(images: Any, factors: Any, *, offset: float = OFFSET) -> np.ndarray:
    """Images (N, H, W[, C]) through the power ``factors`` (one, or one per
    image) about their own channels' mean log: ``exp(m_k + (log(I + offset)
    - m_k) f) - offset``, floored at 0 and not clipped at 255 (the power's
    gain would saturate bright pixels; the normalisation takes any level).
    ``f = 1 / g`` undoes a gamma ``g`` up to the offset and the 8-bit
    rounding. Returns float32 of the images' shape. ValueError for a
    factor that is not finite and > 0."""
    a = as_image_batch(images)
    off = check_positive_float(offset, "offset")
    f = np.broadcast_to(np.asarray(factors, dtype=np.float64), (len(a),))
    if not np.all(np.isfinite(f) & (f > 0)):
        raise ValueError(f"gamma factors must be finite and > 0, got {np.asarray(factors)!r}")
    out = np.empty(a.shape, np.float32)
    axes = (0, 1) if a.ndim == 4 else None
    for i, im in enumerate(a):
        if f[i] == 1.0:
            out[i] = im
            continue
        L = np.log(np.maximum(im.astype(np.float64), 0.0) + off)
        m = L.mean(axis=axes, keepdims=axes is not None)
        out[i] = np.maximum(np.exp(m + (L - m) * f[i]) - off, 0.0)
    return out


class CameraGamma:
    """The gamma of a stream of images relative to a training run's, taken
    out image by image, causally: each image's log ratio is the log of the
    median spread of the ``neighbours`` training views nearest its position
    estimate over its own :func:`log_spread`; its factor is the exponential
    of the median log ratio of the last ``window`` images up to and
    including it, 1 while that median is within the ``dead_zone``, and at
    most :data:`MAX_FACTOR` (or at least its inverse); flat images
    (:data:`FLAT_SPREAD`) add no ratio. Before ``min_images`` ratios the
    factor is 1, except for the images of the batch in which the window
    fills: they take its first factor (a recording localized in batches
    has no uncorrected start; a live stream of single images does).

    Parameters
    ----------
    spreads : array (M,)
        The training images' log spreads (:func:`reference_spread`, stored in
        a photometric model's ``info["camera_gamma"]``; :meth:`for_localizer`).
    positions : array (M, 2)
        Their positions, in the frame of the localizer's estimates (metres).
    window, min_images, neighbours : int
        See above (:data:`WINDOW`, :data:`MIN_IMAGES`, :data:`NEIGHBOURS`).
    dead_zone : float
        A median log ratio within +-``dead_zone`` gives a factor of 1
        (:data:`DEAD_ZONE`; 0: every factor applies).
    offset, lowpass : float
        As :func:`log_spread` (the training spreads' own).

    Attributes
    ----------
    factor_ : float
        The last image's factor (1 before any).
    log_ratio_ : float
        The last median log ratio (0 before ``min_images``).
    n_images_ : int
        Images seen.
    novelty_gain_ : float
        The median, over the last ``window`` corrected images, of how much
        nearer the training views the correction brought each one (its
        novelty as it came minus its novelty corrected,
        :meth:`sfanav.Localizer.novelty`; NaN before any); see :meth:`keeps`.
    n_reverted_ : int
        Corrected images whose estimates were left uncorrected by :meth:`keeps`.

    Raises ValueError for spreads that are not finite and > 0, positions of
    another length or shape, or bad window sizes.
    """

    def __init__(self, spreads: Any, positions: Any, *, window: int = WINDOW, min_images: int = MIN_IMAGES,
                 neighbours: int = NEIGHBOURS, dead_zone: float = DEAD_ZONE, offset: float = OFFSET,
                 lowpass: float = LOWPASS) -> None:
        from scipy.spatial import cKDTree

        sp = np.asarray(spreads, dtype=np.float64).reshape(-1)
        if len(sp) == 0 or not np.all(np.isfinite(sp) & (sp > 0)):
            raise ValueError("spreads must be a non-empty array of finite values > 0")
        xy = as_matrix(positions, "positions", n_cols=2)
        check_same_length(sp, xy, "spreads", "positions")
        self.window = check_int(window, "window", minimum=1)
        self.min_images = check_int(min_images, "min_images", minimum=1)
        if self.min_images > self.window:
            raise ValueError(f"min_images ({self.min_images}) must be at most window ({self.window})")
        self.neighbours = min(check_int(neighbours, "neighbours", minimum=1), len(sp))
        self.dead_zone = check_nonneg_float(dead_zone, "dead_zone")
        self.offset = check_positive_float(offset, "offset")
        self.lowpass = check_nonneg_float(lowpass, "lowpass")
        self.spreads, self.positions = sp, xy
        self._tree = cKDTree(xy)
        self._ratios: deque[float] = deque(maxlen=self.window)
        self._gains: deque[float] = deque(maxlen=self.window)
        self.factor_, self.log_ratio_ = 1.0, 0.0
        self.novelty_gain_ = float("nan")
        self.n_reverted_ = 0
        self.n_images_ = 0

    @classmethod
    def for_localizer(cls, localizer: Any, **kwargs: Any) -> "CameraGamma | None":
        """The tracker for a localizer's training run, or None when its model
        holds no reference (trained without a photometric normalisation, or
        before 2026-12-07)."""
        ref = (getattr(localizer, "info", None) or {}).get("camera_gamma")
        if not ref or "spreads" not in ref:
            return None
        return cls(ref["spreads"], ref["positions"], offset=float(ref.get("offset", OFFSET)),
                   lowpass=float(ref.get("lowpass", LOWPASS)), **kwargs)

    def factors(self, images: Any, positions: Any) -> np.ndarray:
        """The factors (N,) of the next images of the stream (N, H, W[, C],
        the localizer's input format), in order, with the localizer's
        estimates of them (N, 2): each image's ratio joins the window, and
        its factor is the window's as it stands then (see the class)."""
        a = as_image_batch(images)
        xy = as_matrix(positions, "positions", n_cols=2)
        check_same_length(a, xy, "images", "positions")
        _, nn = self._tree.query(xy, k=self.neighbours)
        ref = np.median(self.spreads[np.asarray(nn).reshape(len(xy), -1)], axis=1)
        factors = np.ones(len(a))
        warming: list[int] = []  # images of this batch seen before the window had min_images ratios
        for i, s in enumerate(log_spread(a, offset=self.offset, lowpass=self.lowpass)):
            self.n_images_ += 1
            if s >= FLAT_SPREAD:  # a flat image tells nothing about the gamma
                self._ratios.append(float(np.log(ref[i] / s)))
            if len(self._ratios) >= self.min_images:
                self.log_ratio_ = float(np.median(self._ratios))
                lr = float(np.clip(self.log_ratio_, -np.log(MAX_FACTOR), np.log(MAX_FACTOR)))
                self.factor_ = float(np.exp(lr)) if abs(lr) > self.dead_zone else 1.0
                if warming:  # the window's first factor for the images of this batch that came before it
                    factors[warming] = self.factor_
                    warming = []
            else:
                warming.append(i)
            factors[i] = self.factor_
        return factors

    def correct(self, images: Any, positions: Any) -> np.ndarray:
        """The next images of the stream (N, H, W[, C]), in order, with the
        localizer's estimates of them (N, 2), each through its factor
        (:meth:`factors`, :func:`apply_gamma`): float32, or the images as
        given while every factor is 1."""
        a = as_image_batch(images)
        f = self.factors(a, positions)
        return a if np.all(f == 1.0) else apply_gamma(a, f, offset=self.offset)

    def keeps(self, novelty_before: Any, novelty_after: Any) -> bool:
        """Whether the corrected images of the last :meth:`factors` are to be
        localized as corrected, from their novelty (N,) as they came and once
        corrected (:meth:`sfanav.Localizer.predict_with_novelty`): True while
        the median over the last ``window`` corrected images of ``before -
        after`` is above 0, i.e. the correction brings the images nearer the
        training views. A camera with another gamma does; a walk the
        localizer cannot place (off the training run, a model too coarse to
        place it) can read as a gamma, and correcting it moves the images
        away from every training view: those stay as they came (measured:
        docs/robustness.md, "The camera's gamma by default"). Raises
        ValueError for arrays of different lengths."""
        b = np.asarray(novelty_before, dtype=np.float64).reshape(-1)
        a = np.asarray(novelty_after, dtype=np.float64).reshape(-1)
        if len(a) != len(b):
            raise ValueError(f"novelty before ({len(b)}) and after ({len(a)}) the correction must have one value "
                             "per image")
        d = b - a
        self._gains.extend(float(v) for v in d[np.isfinite(d) & (d != 0.0)])
        if not self._gains:
            return True
        self.novelty_gain_ = float(np.median(self._gains))
        if self.novelty_gain_ > 0:
            return True
        self.n_reverted_ += int(np.count_nonzero(d))  # the images the correction changed
        return False


def predict_corrected(localizer: Any, tracker: "CameraGamma | None", images: Any, *, novelty: bool = False,
                      source: Any = None, conform: Callable[[Any], Any] | None = None, **kwargs: Any) -> Any:
    """``localizer.predict(images, **kwargs)`` with the camera's gamma taken
    out by ``tracker`` (None: plain): the images are localized once as they
    are, which places them for the tracker, and again once corrected when
    any factor is not 1; with a localizer that holds a novelty reference the
    corrected estimates are kept only while the correction brings the images
    nearer the training views (:meth:`CameraGamma.keeps`). Returns the
    estimates (N, 2); with ``novelty``, ``(estimates, novelty (N,))`` from
    :meth:`sfanav.Localizer.predict_with_novelty` of the images whose
    estimates are returned.

    ``source`` (N, H', W'[, C]) and ``conform``: the images as the camera
    sent them and the callable that made ``images`` of them (a
    :class:`sfanav.data.Preprocessor`): the factors are then applied to the
    camera's own pixels and conformed again. A gamma acts on the camera's
    pixels; a resize or an unwarping averages them, and a power of an
    average is not the average of the powers, so a correction after them
    leaves part of the gamma (docs/robustness.md, "The camera's gamma by
    default")."""
    if (source is None) != (conform is None):
        raise ValueError("source and conform go together: the camera's images and the callable that conformed them")
    if source is not None and len(source) != len(images):
        raise ValueError(f"source has {len(source)} images, images {len(images)}: one source image per image")
    with_novelty = novelty or (tracker is not None and getattr(localizer, "novelty_", None) is not None)

    def run(x: Any) -> Any:
        if with_novelty:
            xy, nov = localizer.predict_with_novelty(x, **kwargs)
            return np.atleast_2d(xy), nov
        return np.atleast_2d(localizer.predict(x, **kwargs)), None

    xy, nov = run(images)
    if tracker is not None:
        f = tracker.factors(images, xy)
        if not np.all(f == 1.0):
            fixed = (apply_gamma(images, f, offset=tracker.offset) if source is None
                     else conform(apply_gamma(source, f, offset=tracker.offset)))
            xy2, nov2 = run(fixed)
            if nov is None or tracker.keeps(nov, nov2):
                xy, nov = xy2, nov2
    return (xy, nov) if novelty else xy


def reference_spread(images: Any, positions: Any, *, offset: float = OFFSET,
                     lowpass: float = LOWPASS) -> dict[str, Any]:
    """What a model stores of its training images (N, H, W[, C]) at their
    positions (N, 2) for :meth:`CameraGamma.for_localizer`: ``{"spreads":
    (N,) list, "positions": (N, 2) list, "offset", "lowpass"}`` (rounded to
    1e-5 and a millimetre)."""
    xy = as_matrix(positions, "positions", n_cols=2)
    sp = log_spread(images, offset=offset, lowpass=lowpass)
    check_same_length(sp, xy, "images", "positions")
    return {"spreads": [round(float(v), 5) for v in sp], "positions": np.round(xy, 3).tolist(),
            "offset": float(offset), "lowpass": float(lowpass)}
