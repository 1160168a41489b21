"""The texture and colour statistics around a keypoint (thesis 6.1.2).

For each keypoint a ``PATCH`` x ``PATCH`` (48 x 48) pixel patch centred on
it gives a 77-dimensional vector:

* a 59-bin histogram of uniform local binary patterns (8 neighbours at
  radius 1, the non-rotation-invariant uniform patterns of
  ``skimage.feature.local_binary_pattern(..., method="nri_uniform")``), and
* an 18-bin hue histogram (20 degrees per bin, HSV hue of the RGB image),

both weighted by a Gaussian window (standard deviation ``PATCH / 4``
pixels) centred on the keypoint and each normalised to sum 1, so the vector
sums to 2. The patch wraps around the panorama horizontally and is mirrored
at the top and bottom. The thesis resizes a SURF keypoint's descriptor
window to 48 x 48; here the patch is 48 x 48 pixels for every detector.

>>> import numpy as np
>>> img = (np.random.default_rng(0).random((60, 200, 3)) * 255).astype(np.uint8)
>>> v = robustness_vectors(img, np.array([[10.0, 30.0], [150.5, 2.0]]))
>>> v.shape, bool(np.allclose(v[:, :59].sum(1), 1))
((2, 77), True)
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: patch edge (pixels)
PATCH = 48
#: bins of the uniform LBP histogram (P = 8)
LBP_BINS = 59
#: bins of the hue histogram
HUE_BINS = 18
#: length of a robustness vector
DIM = LBP_BINS + HUE_BINS


def _window(patch: int) -> np.ndarray:
    r = np.arange(patch) - (patch - 1) / 2
    g = np.exp(-0.5 * (r / (patch / 4)) ** 2)
    w = np.outer(g, g)
    return (w / w.sum()).ravel()


def lbp_and_hue(image: Any) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel LBP codes (0..58) and hue bins (0..17) of an RGB image
    (H, W, 3), both int (H, W). The LBP is computed on the padded panorama
    so the seam has no border effect."""
    import cv2
    from skimage.feature import local_binary_pattern

    from .detectors import as_uint8, pad_panorama

    a = np.asarray(image)
    if a.dtype.kind not in "uif" or a.dtype == bool:
        raise TypeError(f"image must be an array of numbers, got dtype {a.dtype}")
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"robustness vectors need an RGB image (H, W, 3) for the hue, got shape {a.shape}")
    if min(a.shape[:2]) < 8:
        raise ValueError(f"image must be at least 8x8 pixels, got {a.shape[1]}x{a.shape[0]}")
    rgb = as_uint8(a)
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    p = 2
    codes = local_binary_pattern(pad_panorama(gray, p), 8, 1, method="nri_uniform")[p:-p, p:-p]
    hue = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV_FULL)[:, :, 0].astype(np.int64)  # 0..255 for 0..360 deg
    return codes.astype(np.int64), hue * HUE_BINS // 256


def robustness_vectors(image: Any, xy: Any, *, patch: int = PATCH) -> np.ndarray:
    """The 77-dimensional texture and colour vectors of keypoints.

    Parameters
    ----------
    image : ndarray (H, W, 3)
        RGB panorama (uint8, or floats in [0, 1] or [0, 255]).
    xy : array (n, 2)
        Keypoint positions (x = column, y = row, pixels).
    patch : int
        Patch edge in pixels (even, >= 4; default 48).

    Returns
    -------
    ndarray (n, 77) float64
        Columns 0..58: LBP histogram, 59..76: hue histogram; each sums to 1.

    Raises
    ------
    ValueError
        A gray image or another shape, keypoints not (n, 2) finite numbers.
    TypeError
        A non-numeric image.
    """
    from .._checks import as_real_array, check_int

    patch = check_int(patch, "patch", minimum=4)
    codes, hue = lbp_and_hue(image)
    pts = as_real_array(xy, "keypoints")
    if pts.size == 0:
        return np.zeros((0, DIM))
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"keypoints must be an (n, 2) array of x, y, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("keypoints must be finite")
    h, w = codes.shape
    off = np.arange(patch) - patch // 2
    cx = np.floor(pts[:, 0]).astype(np.int64)
    cy = np.floor(pts[:, 1]).astype(np.int64)
    cols = (cx[:, None] + off[None, :]) % w  # (n, patch)
    rows = cy[:, None] + off[None, :]
    period = 2 * h - 2
    rows = np.abs(((rows % period) + period) % period)
    rows = np.where(rows >= h, period - rows, rows)  # mirrored at the top and bottom
    r = np.repeat(rows, patch, axis=1)  # (n, patch*patch), row-major over the patch
    c = np.tile(cols, (1, patch))
    weight = np.broadcast_to(_window(patch), r.shape)
    n = len(pts)
    base = np.arange(n)[:, None]
    lbp = np.bincount((base * LBP_BINS + codes[r, c]).ravel(), weight.ravel(), n * LBP_BINS).reshape(n, LBP_BINS)
    hh = np.bincount((base * HUE_BINS + hue[r, c]).ravel(), weight.ravel(), n * HUE_BINS).reshape(n, HUE_BINS)
    return np.hstack([lbp / lbp.sum(1, keepdims=True), hh / hh.sum(1, keepdims=True)])
