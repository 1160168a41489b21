"""Photometric normalisation: panoramas made independent of the camera's
exposure, white balance and gamma before the network and the signature see
them.

:func:`log_contrast` maps each image to the logarithm of its intensities,
centred per colour channel and scaled to a fixed contrast:

    L = log(I + c),   L_k -= mean(L_k) over the image (channel k),
    out = L / std(L) * S

with ``c`` = :data:`LOG_OFFSET` grey levels and ``S`` = :data:`LOG_SCALE`.
An exposure change (``g I``), a white-balance shift (``g_k I_k``) and a
gamma change (``255 (I / 255)^gamma``) are, in the log domain, an offset per
channel and a scale; centring and scaling remove them (exactly up to the
offset ``c``, rounding and clipping). Within an image nothing is moved:
relative brightness between rows and columns, the structure the network
reads, stays as it was.

What it measured against the alternatives (per-row normalisation,
per-channel gains, the thesis's zero-mean unit-variance images) and why it
is the sfanav default's: docs/robustness.md.

Examples
--------
>>> import numpy as np
>>> from sfanav.data.photometric import log_contrast
>>> img = np.random.default_rng(0).integers(20, 200, (1, 8, 30, 3)).astype(np.uint8)
>>> dark = (img * 0.6).round().astype(np.uint8)
>>> bool(np.abs(log_contrast(img) - log_contrast(dark)).mean() < 2.0)   # about 40 units per std
True
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import as_image_batch

LOG_OFFSET = 8.0
"""Grey levels added before the logarithm: keeps dark pixels' noise from being amplified without bound."""
LOG_SCALE = 40.0
"""The standard deviation of a normalised image (pixel-like units, so that networks and signatures keep their
usual scale)."""
LOWPASS_SIGMA = 2.0
"""The Gaussian low-pass of ``"lowpass-log-contrast"``, in pixels of the image it is applied to: in columns, and in
rows of a panorama whose rows span :data:`LOWPASS_ROW_DEGREES` each (:func:`lowpass_for` scales the rows' width to
other elevation spans)."""
LOWPASS_ROW_DEGREES = 1.25
"""Degrees of elevation per row at which the rows' low-pass is :data:`LOWPASS_SIGMA` pixels: the default camera's
-30..20 deg over the network's 40 rows."""
PHOTOMETRIC = ("log-contrast", "lowpass-log-contrast")
"""The photometric normalisations a :class:`sfanav.Localizer` knows (``photometric=``)."""


def log_contrast(images: Any, *, offset: float = LOG_OFFSET, scale: float = LOG_SCALE) -> np.ndarray:
    """Images (N, H, W[, C]) of 0..255 values (uint8 or float) normalised as
    the module says: float32 of the same shape. A flat image (no contrast)
    is only centred. Computed one image at a time (no float64 copy of the
    batch)."""
    a = as_image_batch(images)
    if not (np.isfinite(offset) and offset > 0 and np.isfinite(scale) and scale > 0):
        raise ValueError(f"offset and scale must be finite and > 0, got {offset!r} and {scale!r}")
    out = np.empty(a.shape, np.float32)
    axes = (0, 1) if a.ndim == 4 else None
    for i, im in enumerate(a):
        v = np.log(np.maximum(im.astype(np.float32), 0.0) + np.float32(offset))
        v -= v.mean(axis=axes, dtype=np.float64, keepdims=axes is not None).astype(np.float32)
        sd = float(v.std(dtype=np.float64))
        out[i] = v * np.float32(scale / sd) if sd > 1e-6 else v
    return out


def lowpass_log_contrast(images: Any, *, sigma: float | tuple[float, float] = LOWPASS_SIGMA,
                         offset: float = LOG_OFFSET, scale: float = LOG_SCALE, flat: bool = True) -> np.ndarray:
    """:func:`log_contrast` of images (N, H, W[, C]) after a Gaussian
    low-pass of ``sigma`` pixels (or ``(rows, columns)`` pixels; wrapping around the panorama's seam in
    columns, edge rows repeated), and with ``flat`` a flat field: the
    quadratic profile over the rows of each channel's row means removed in
    the log domain before the contrast is fixed.

    The low-pass takes away the fine structure that JPEG, sensor noise,
    defocus and dead pixels change and a flawless render keeps; the flat
    field removes a vignetting (a smooth gain per elevation row in a
    panorama: an offset per row in the log domain) exactly up to the
    quadratic's fit. What it measured against :func:`log_contrast`:
    docs/robustness.md. Returns float32 of the images' shape.

    Raises ValueError for a ``sigma`` that is not finite and >= 0, or the
    errors of :func:`log_contrast`.
    """
    a = as_image_batch(images)
    sy, sx = _sigma_pair(sigma)
    if not (np.isfinite(offset) and offset > 0 and np.isfinite(scale) and scale > 0):
        raise ValueError(f"offset and scale must be finite and > 0, got {offset!r} and {scale!r}")
    h = a.shape[1]
    P = row_profile_projector(h).astype(np.float32)
    out = np.empty(a.shape, np.float32)
    axes = (0, 1) if a.ndim == 4 else None
    for i, im in enumerate(a):
        v = im.astype(np.float32)
        if sy > 0 or sx > 0:
            v = panorama_lowpass(v, (sy, sx))
        v = np.log(np.maximum(v, 0.0) + np.float32(offset))
        if flat:
            v -= (P @ v.mean(axis=1).reshape(h, -1)).reshape((h, 1) + v.shape[2:])
        else:
            v -= v.mean(axis=axes, dtype=np.float64, keepdims=axes is not None).astype(np.float32)
        sd = float(v.std(dtype=np.float64))
        out[i] = v * np.float32(scale / sd) if sd > 1e-6 else v
    return out


def panorama_lowpass(image: Any, sigma: tuple[float, float]) -> np.ndarray:
    """One panorama (H, W[, C]) low-passed by a Gaussian of ``sigma`` =
    (rows, columns) pixels, wrapping around the seam in columns and
    repeating the edge rows (the channels apart); the image's float dtype is
    kept."""
    from scipy.ndimage import gaussian_filter

    im = np.asarray(image)
    sig = (float(sigma[0]), float(sigma[1]), 0.0)[: im.ndim]
    return gaussian_filter(im, sig, mode=("nearest", "wrap", "nearest")[: im.ndim])


def row_profile_projector(height: int) -> np.ndarray:
    """(H, H) float64 projector onto the quadratic profiles over ``height``
    rows (fewer terms for fewer rows): ``P @ row_means`` is the smooth
    elevation profile a vignetting or the sky's gradient puts on a panorama,
    which the flat field removes."""
    t = np.linspace(-1.0, 1.0, height)
    V = np.stack([np.ones(height), t, t * t], axis=1)[:, : min(3, height)]
    return V @ np.linalg.pinv(V)


def lowpass_for(elevation_deg: Any, height: int) -> tuple[float, float]:
    """The (rows, columns) widths in pixels of the ``"lowpass-log-contrast"``
    low-pass for panoramas of ``height`` rows spanning ``elevation_deg``
    (lowest, highest) degrees: :data:`LOWPASS_SIGMA` columns, and in rows the
    same angle as :data:`LOWPASS_SIGMA` rows of :data:`LOWPASS_ROW_DEGREES`
    each (2.5 deg of elevation). An omnidirectional camera unwarped over
    -55..20 deg to 40 rows gets 1.33 rows: its rows are coarser in angle, and
    the 2 rows of the panoramic cameras cost it precision (docs/robustness.md,
    "The low-pass in degrees of elevation"). ValueError for a span that is
    not finite and increasing, or a height < 1.

    >>> lowpass_for((-30, 20), 40)
    (2.0, 2.0)
    >>> [round(v, 2) for v in lowpass_for((-55, 20), 40)]
    [1.33, 2.0]
    """
    lo, hi = (float(v) for v in np.asarray(elevation_deg, dtype=np.float64).reshape(2))
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
        raise ValueError(f"elevation_deg must be (lowest, highest) finite degrees, got {elevation_deg!r}")
    if int(height) < 1:
        raise ValueError(f"height must be >= 1 rows, got {height!r}")
    return LOWPASS_SIGMA * LOWPASS_ROW_DEGREES / ((hi - lo) / int(height)), LOWPASS_SIGMA


def lowpass_widths(sigma: Any) -> tuple[float, float]:
    """``sigma`` (pixels, or (rows, columns) pixels; None: :data:`LOWPASS_SIGMA`) as two floats; ValueError unless
    each is finite and >= 0."""
    return _sigma_pair(LOWPASS_SIGMA if sigma is None else sigma)


def _sigma_pair(sigma: Any) -> tuple[float, float]:
    """``sigma`` (pixels, or (rows, columns) pixels) as two floats; ValueError unless each is finite and >= 0."""
    try:
        if isinstance(sigma, (str, bytes)):
            raise TypeError
        pair = np.broadcast_to(np.asarray(sigma, dtype=np.float64), (2,))
    except (TypeError, ValueError):
        raise ValueError(f"sigma must be finite and >= 0 pixels, or (rows, columns) of them, got {sigma!r}") from None
    if not (np.all(np.isfinite(pair)) and np.all(pair >= 0)):
        raise ValueError(f"sigma must be finite and >= 0 pixels, or (rows, columns) of them, got {sigma!r}")
    return float(pair[0]), float(pair[1])


def normalize(images: Any, kind: str | None, *, lowpass: Any = None) -> Any:
    """``images`` with the photometric normalisation ``kind`` (one of
    :data:`PHOTOMETRIC`) applied, or as given for None; ``lowpass``: the
    widths of ``"lowpass-log-contrast"`` (as its ``sigma``; None: the
    default)."""
    if kind is None:
        return images
    if kind == "log-contrast":
        return log_contrast(images)
    if kind == "lowpass-log-contrast":
        return lowpass_log_contrast(images) if lowpass is None else lowpass_log_contrast(images, sigma=lowpass)
    raise ValueError(f"photometric normalisation must be one of {PHOTOMETRIC} or None, got {kind!r}")
