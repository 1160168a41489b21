"""A camera's gamma, estimated over the images it sends and taken back out
before localization.

The photometric normalisation (:mod:`sfanav.data.photometric`) removes a
gain, a white balance and a vignetting exactly, but not a gamma: its
low-pass acts on the intensities before the logarithm, and a low-pass does
not commute with a power. A gamma ``255 (I / 255)^g`` scales the logarithm
of the intensities by ``g``, so it shows in how widely the log intensities
of a camera's images spread, and no single image tells a gamma from a
scene of more or less contrast; a run of images does. This module measures
that spread (:func:`log_spread`: the standard deviation of ``log(I +
offset)`` once each channel's quadratic profile over the rows, a vignetting
or the sky's gradient, is removed), compares the median over recent images
with the training run's (:class:`CameraGamma`) and maps each image through
the power that brings the two together (:func:`apply_gamma`), before the
localizer sees it. A camera like the training run's gets a factor near 1
and its images are left as they were; a camera with gamma ``g`` gets about
``1 / g``.

Where it helps and what it costs (the default's network, paired seed by
seed, four gardens): docs/robustness.md, "The camera's gamma from the
stream".

Examples
--------
>>> import numpy as np
>>> from sfanav.data.camera_gamma import CameraGamma, log_spread
>>> rng = np.random.default_rng(0)
>>> sky = np.linspace(220, 60, 12)[:, None, None] * (0.8 + 0.2 * np.sin(np.linspace(0, 12, 60)))[None, :, None]
>>> run = (sky[None] * rng.uniform(0.8, 1.1, (40, 1, 60, 3))).astype(np.uint8)   # 40 panoramas, 12 x 60
>>> dark = (255 * (run / 255) ** 1.4).round().astype(np.uint8)       # the same run through a gamma of 1.4
>>> cg = CameraGamma(float(np.median(log_spread(run))), min_images=10)
>>> fixed = cg.correct(dark)
>>> round(cg.factor_, 2)                                               # about 1 / 1.4
0.72
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from .._checks import as_image_batch, check_int, check_nonneg_float, check_positive_float

OFFSET = 2.0
"""Grey levels added before the logarithm of the spread and the correction (a gamma is a scale of ``log(I)``
exactly; the offset keeps black pixels finite and bends that least at 2)."""
LOWPASS = 4.0
"""Gaussian low-pass (pixels, wrapping around the panorama's seam in columns) of the images before their log spread:
a defocus, motion blur, JPEG, noise and dead pixels change the fine structure's share of the spread (a 2 px defocus
read as a gamma of 0.6 in a suite garden without it), a gamma scales the coarse structure's as much."""
WINDOW = 200
"""Recent images whose median spread :class:`CameraGamma` compares with the training run's."""
MIN_IMAGES = 20
"""Images :class:`CameraGamma` waits for before it corrects (a factor of 1 until then)."""
DEAD_ZONE = 0.1
"""Factors within ``exp(+-DEAD_ZONE)`` (0.90..1.11) are taken as 1: a test run that keeps to part of the garden
sees a spread a few per cent off the training run's (up to 8 % over 200 images of the gardens measured,
docs/robustness.md), which is no gamma; a camera's gamma of 0.7 or 1.4 is 0.36 or 0.34 in the log."""


def log_spread(images: Any, *, offset: float = OFFSET, lowpass: float = LOWPASS) -> np.ndarray:
    """The log spread of each image (N, H, W[, C]) of 0..255 values: the
    standard deviation of ``log(I + offset)`` of the image low-passed by
    ``lowpass`` pixels (:data:`LOWPASS`; 0: none), after each channel's
    quadratic profile over the rows is removed (so that a vignetting, a white
    balance and a gain leave it, a blur, JPEG and noise nearly, and a gamma
    ``g`` scales it by about ``g``). Returns float64 (N,). Raises ValueError
    for a bad batch, offset or low-pass."""
    from scipy.ndimage import gaussian_filter

    a = as_image_batch(images)
    off = check_positive_float(offset, "offset")
    sigma = check_nonneg_float(lowpass, "lowpass")
    if a.dtype != np.uint8 and not np.isfinite(a).all():
        raise ValueError("images must be finite (NaN or infinite values found)")
    h = a.shape[1]
    t = np.linspace(-1.0, 1.0, h)
    V = np.stack([np.ones(h), t, t * t], axis=1)[:, : min(3, h)]
    P = V @ np.linalg.pinv(V)
    out = np.empty(len(a))
    sig = (sigma, sigma, 0.0)[: a.ndim - 1]
    modes = ("nearest", "wrap", "nearest")[: a.ndim - 1]
    for i, im in enumerate(a):
        v = im.astype(np.float64)
        if sigma > 0:
            v = gaussian_filter(v, sig, mode=modes)
        L = np.log(np.maximum(v, 0.0) + off)
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
        L = np.log(np.maximum(im.astype(np.float64), 0.0) + off)
        if f[i] == 1.0:
            out[i] = im
            continue
        m = L.mean(axis=axes, keepdims=axes is not None)
        out[i] = np.maximum(np.exp(m + (L - m) * f[i]) - off, 0.0)
    return out


class CameraGamma:
    """The gamma of a stream of images relative to a training run's, taken
    out image by image, causally: each image's factor is ``reference`` over
    the median :func:`log_spread` of the last ``window`` images up to and
    including it, 1 until ``min_images`` have been seen and while it is
    within the ``dead_zone``.

    Parameters
    ----------
    reference : float
        The training run's median log spread (``Localizer.info["camera_gamma"]
        ["reference"]`` of a model trained with a photometric normalisation;
        :meth:`for_localizer`).
    window, min_images : int
        See above (:data:`WINDOW`, :data:`MIN_IMAGES`).
    dead_zone : float
        A factor whose log is within +-``dead_zone`` is 1 (:data:`DEAD_ZONE`; 0: every factor applies).
    offset : float
        Grey levels before the logarithm (:data:`OFFSET`).

    Attributes
    ----------
    factor_ : float
        The last image's factor (1 before any).
    n_images_ : int
        Images seen.

    Raises ValueError for a reference that is not finite and > 0, or bad
    window sizes.
    """

    def __init__(self, reference: float, *, window: int = WINDOW, min_images: int = MIN_IMAGES,
                 dead_zone: float = DEAD_ZONE, offset: float = OFFSET) -> None:
        self.reference = check_positive_float(reference, "reference")
        self.window = check_int(window, "window", minimum=1)
        self.min_images = check_int(min_images, "min_images", minimum=1)
        if self.min_images > self.window:
            raise ValueError(f"min_images ({self.min_images}) must be at most window ({self.window})")
        self.offset = check_positive_float(offset, "offset")
        self.dead_zone = check_nonneg_float(dead_zone, "dead_zone")
        self._spreads: deque[float] = deque(maxlen=self.window)
        self.factor_ = 1.0
        self.n_images_ = 0

    @classmethod
    def for_localizer(cls, localizer: Any, **kwargs: Any) -> "CameraGamma | None":
        """The tracker for a localizer's training run, or None when its model
        holds no reference (trained without a photometric normalisation, or
        before 2026-12-07)."""
        ref = (getattr(localizer, "info", None) or {}).get("camera_gamma")
        if not ref:
            return None
        return cls(float(ref["reference"]), offset=float(ref.get("offset", OFFSET)), **kwargs)

    def correct(self, images: Any) -> np.ndarray:
        """The next images of the stream (N, H, W[, C]), in order, each
        through its factor: float32, or the images as given while every
        factor is 1."""
        a = as_image_batch(images)
        factors = np.ones(len(a))
        for i, s in enumerate(log_spread(a, offset=self.offset)):
            self._spreads.append(float(s))
            self.n_images_ += 1
            if len(self._spreads) >= self.min_images:
                med = float(np.median(self._spreads))
                f = self.reference / med if med > 1e-9 else 1.0
                self.factor_ = f if abs(np.log(f)) > self.dead_zone else 1.0
            factors[i] = self.factor_
        if np.all(factors == 1.0):
            return a
        return apply_gamma(a, factors, offset=self.offset)


def reference_spread(images: Any, *, offset: float = OFFSET) -> dict[str, float]:
    """What a model stores of its training images (N, H, W[, C]) for
    :meth:`CameraGamma.for_localizer`: ``{"reference": median log spread,
    "offset": offset}``."""
    return {"reference": float(np.median(log_spread(images, offset=offset))), "offset": float(offset)}
