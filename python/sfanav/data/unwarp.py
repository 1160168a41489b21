"""Omnidirectional (donut) images to panoramic views (thesis 3.4.1, 5.2.1).

A catadioptric camera sees the world in a ring between an inner radius (the
blind spot where the mirror reflects the camera itself) and an outer radius
(the mirror's rim). :class:`Unwarper` samples that ring on a polar grid into a
``width x height`` panorama with OpenCV's ``cv2.remap`` and precomputed
tables; it can convert to grayscale, normalise each panorama to zero mean and
unit variance (robustness to global illumination, thesis 5.2.1) and shift the
ring's center by a random offset of up to ``jitter`` px per image (the
thesis's +-5 px, which makes the learned representation invariant to the
robot's tilt on uneven ground). :func:`estimate_mirror` finds the center and
radii from a set of images.

Coordinates are OpenCV pixel coordinates: ``x`` is the column, ``y`` the row,
integer values at pixel centers, so the center of a ``W x H`` image is
``((W - 1) / 2, (H - 1) / 2)``. Sizes are ``(width, height)`` as in the thesis
("350x40").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_images, as_real_array, check_finite, check_nonneg_float

_GRAY_WEIGHTS = np.array([0.299, 0.587, 0.114])  # ITU-R BT.601 luma, R G B


def _cv2() -> Any:
    try:
        import cv2
    except ImportError as exc:  # pragma: no cover
        raise ImportError(
            "sfanav.data.unwarp needs OpenCV: pip install opencv-python-headless"
        ) from exc
    return cv2


@dataclass(frozen=True)
class Mirror:
    """Where the mirror is in the camera image.

    Attributes
    ----------
    center : (float, float)
        ``(x, y)`` of the mirror's axis in pixels (column, row).
    inner_radius : float
        Radius of the blind central spot, px (0: none).
    outer_radius : float
        Radius of the mirror's rim, px.
    """

    center: tuple[float, float]
    inner_radius: float
    outer_radius: float

    def unwarper(self, size: tuple[int, int] = (350, 40), **kwargs: Any) -> "Unwarper":
        """An :class:`Unwarper` for this mirror (keyword arguments as Unwarper's)."""
        return Unwarper(self.center, self.inner_radius, self.outer_radius, size, **kwargs)


class Unwarper:
    """Omnidirectional image -> panoramic view, by a precomputed polar remap.

    Output row 0 samples the outer radius (``top="outer"``; for a camera
    looking up at a convex mirror that is the horizon side) and the last row
    the inner radius; radii are spaced linearly at pixel centers. Column ``c``
    looks at azimuth ``azimuth_offset + 360 * c / width`` degrees, azimuth
    measured in the image from the +x axis (to the right) counter-clockwise as
    the image is displayed (towards the top), or clockwise with
    ``clockwise=True`` (a mirror flips the scene: choose the direction that
    makes the panorama read the right way round). A robot rotation is then a
    circular shift of the columns, as the simulated rotation assumes.

    Parameters
    ----------
    center : (float, float)
        ``(x, y)`` of the mirror's center, px.
    inner_radius, outer_radius : float
        Radii of the ring to unwarp, px (0 <= inner < outer).
    size : (int, int), default (350, 40)
        Panorama ``(width, height)``, e.g. (350, 40), (600, 60), (409, 40).
    azimuth_offset : float, default 0
        Azimuth of column 0, degrees.
    clockwise : bool, default False
        Direction of increasing column.
    top : {"outer", "inner"}, default "outer"
        Which radius row 0 samples.
    gray : bool, default False
        Convert RGB (or BGR, see ``channel_order``) to one channel (BT.601 luma).
    normalize : bool, default False
        Shift and scale each panorama to zero mean and unit variance over all
        its pixels (and channels); output float32. A constant panorama is only
        centred.
    jitter : float, default 0
        Maximal random shift of the center per image and axis, px (thesis
        5.2.1: 5). Offsets are uniform in ``[-jitter, jitter]``, drawn from
        ``random_state``.
    interpolation : {"linear", "cubic", "nearest"}, default "linear"
    channel_order : {"rgb", "bgr"}, default "rgb"
        Colour order for ``gray`` (``cv2.imread`` gives BGR).
    random_state : int, numpy Generator or None
        Seed of the jitter offsets; the generator advances with each call.

    Attributes
    ----------
    map_x, map_y : ndarray of shape (height, width), float32
        Source coordinates of every panorama pixel (without jitter).

    Examples
    --------
    >>> unwarp = Unwarper(center=(249.5, 249.5), inner_radius=40, outer_radius=240,
    ...                   size=(409, 40), gray=True, normalize=True, jitter=5, random_state=0)
    >>> panoramas = unwarp.transform(omni_images)      # (N, 40, 409) float32  # doctest: +SKIP
    """

    def __init__(
        self,
        center: tuple[float, float],
        inner_radius: float,
        outer_radius: float,
        size: tuple[int, int] = (350, 40),
        *,
        azimuth_offset: float = 0.0,
        clockwise: bool = False,
        top: str = "outer",
        gray: bool = False,
        normalize: bool = False,
        jitter: float = 0.0,
        interpolation: str = "linear",
        channel_order: str = "rgb",
        random_state: int | np.random.Generator | None = None,
    ) -> None:
        c = as_real_array(center, "center").astype(np.float64)
        if c.shape != (2,):
            raise ValueError(f"center must be (x, y), got {center!r}")
        check_finite(c, "center")
        self.center = (float(c[0]), float(c[1]))
        self.inner_radius = check_nonneg_float(inner_radius, "inner_radius")
        self.outer_radius = check_nonneg_float(outer_radius, "outer_radius")
        if self.outer_radius <= self.inner_radius:
            raise ValueError(
                f"outer_radius ({self.outer_radius}) must be larger than inner_radius ({self.inner_radius})"
            )
        if (
            not isinstance(size, (tuple, list))
            or len(size) != 2
            or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1 for v in size)
        ):
            raise ValueError(f"size must be (width, height), two positive integers, got {size!r}")
        self.size = (int(size[0]), int(size[1]))
        self.azimuth_offset = float(azimuth_offset)
        self.clockwise = bool(clockwise)
        if top not in ("outer", "inner"):
            raise ValueError(f"top must be 'outer' or 'inner', got {top!r}")
        self.top = top
        self.gray = bool(gray)
        self.normalize = bool(normalize)
        self.jitter = check_nonneg_float(jitter, "jitter")
        cv2 = _cv2()
        interp = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC, "nearest": cv2.INTER_NEAREST}
        if interpolation not in interp:
            raise ValueError(f"interpolation must be one of {sorted(interp)}, got {interpolation!r}")
        self.interpolation = interpolation
        self._interp = interp[interpolation]
        if channel_order not in ("rgb", "bgr"):
            raise ValueError(f"channel_order must be 'rgb' or 'bgr', got {channel_order!r}")
        self.channel_order = channel_order
        self.random_state = random_state
        self._rng = np.random.default_rng(random_state)
        self.map_x, self.map_y = self._maps()

    @classmethod
    def from_images(cls, images: Any, size: tuple[int, int] = (350, 40), **kwargs: Any) -> "Unwarper":
        """An Unwarper for the mirror :func:`estimate_mirror` finds in ``images``."""
        return estimate_mirror(images).unwarper(size, **kwargs)

    def __repr__(self) -> str:
        cx, cy = self.center
        return (
            f"Unwarper(center=({cx:g}, {cy:g}), inner_radius={self.inner_radius:g}, "
            f"outer_radius={self.outer_radius:g}, size={self.size}, gray={self.gray}, "
            f"normalize={self.normalize}, jitter={self.jitter:g})"
        )

    # ------------------------------------------------------------ geometry
    def _angles_and_radii(self) -> tuple[np.ndarray, np.ndarray]:
        w, h = self.size
        sign = -1.0 if self.clockwise else 1.0
        theta = np.deg2rad(self.azimuth_offset) + sign * 2.0 * np.pi * np.arange(w) / w
        frac = (np.arange(h) + 0.5) / h
        r0, r1 = (self.outer_radius, self.inner_radius) if self.top == "outer" else (self.inner_radius, self.outer_radius)
        return theta, r0 + (r1 - r0) * frac

    def _maps(self) -> tuple[np.ndarray, np.ndarray]:
        theta, rho = self._angles_and_radii()
        cx, cy = self.center
        map_x = cx + rho[:, None] * np.cos(theta)[None, :]
        map_y = cy - rho[:, None] * np.sin(theta)[None, :]
        return map_x.astype(np.float32), map_y.astype(np.float32)

    def draw_offsets(self, n: int) -> np.ndarray:
        """``n`` random center offsets (n, 2) in ``[-jitter, jitter]`` px (zeros
        without jitter); advances the generator as :meth:`transform` does."""
        if self.jitter == 0:
            return np.zeros((n, 2))
        return self._rng.uniform(-self.jitter, self.jitter, size=(n, 2))

    # ------------------------------------------------------------ unwarping
    def transform(self, images: Any, *, offsets: Any = None) -> np.ndarray:
        """Unwarps a batch of omnidirectional images.

        Parameters
        ----------
        images : array (N, H, W) or (N, H, W, C)
            uint8 or float (other integer types are read as float64). A 3-D
            array is always a batch of gray images; use ``unwarper(image)``
            for one image.
        offsets : array (N, 2), optional
            Center offsets ``(dx, dy)`` px per image; default: random within
            ``jitter`` (zeros without jitter).

        Returns
        -------
        ndarray (N, height, width) for gray output or one-channel input, else
        (N, height, width, C). dtype: float32 with ``normalize``, otherwise
        the input's (uint8 stays uint8; gray conversion rounds). Pixels that
        sample outside the image are 0.
        """
        cv2 = _cv2()
        imgs = as_images(images)
        if imgs.dtype == np.float16:
            imgs = imgs.astype(np.float32)
        n = len(imgs)
        channels = 1 if imgs.ndim == 3 else imgs.shape[3]
        if self.gray and channels not in (1, 3, 4):
            raise ValueError(f"gray=True needs 1, 3 or 4 channels (RGB[A]), got {channels}")
        if offsets is None:
            offs = self.draw_offsets(n)
        else:
            offs = as_real_array(offsets, "offsets").astype(np.float64)
            if offs.shape != (n, 2):
                raise ValueError(f"offsets must have shape ({n}, 2), got {offs.shape}")
            check_finite(offs, "offsets")
        w, h = self.size
        out = np.empty((n, h, w) + (() if imgs.ndim == 3 else (channels,)), dtype=imgs.dtype)
        border = (0,) * 4
        for i in range(n):
            dx, dy = offs[i]
            if dx == 0 and dy == 0:
                mx, my = self.map_x, self.map_y
            else:
                mx, my = self.map_x + np.float32(dx), self.map_y + np.float32(dy)
            res = cv2.remap(imgs[i], mx, my, self._interp, borderMode=cv2.BORDER_CONSTANT, borderValue=border)
            out[i] = res.reshape(out.shape[1:])
        if self.gray and out.ndim == 4:
            weights = _GRAY_WEIGHTS if self.channel_order == "rgb" else _GRAY_WEIGHTS[::-1]
            g = out[..., :3].astype(np.float32) @ weights.astype(np.float32)
            out = np.clip(np.rint(g), 0, 255).astype(np.uint8) if out.dtype == np.uint8 else g.astype(out.dtype)
        elif out.ndim == 4 and channels == 1:
            out = out[..., 0]
        if self.normalize:
            out = out.astype(np.float32)
            flat = out.reshape(n, -1)
            mean = flat.mean(axis=1, dtype=np.float64)
            std = flat.std(axis=1, dtype=np.float64)
            std[std == 0] = 1.0
            out = ((flat - mean[:, None]) / std[:, None]).astype(np.float32).reshape(out.shape)
        return out

    def __call__(self, image: Any, *, offset: Any = None) -> np.ndarray:
        """Unwarps one image (H, W) or (H, W, C) -> (height, width[, C])."""
        img = as_real_array(image, "image")
        if img.ndim not in (2, 3):
            raise ValueError(f"one image must have shape (H, W) or (H, W, C), got {img.shape}; "
                             "use transform() for batches")
        off = None if offset is None else np.asarray(offset, dtype=np.float64).reshape(1, 2)
        return self.transform(img[None], offsets=off)[0]

    def inverse_transform(self, panoramas: Any, image_size: tuple[int, int]) -> np.ndarray:
        """Panoramas (N, height, width[, C]) -> omnidirectional images of
        ``image_size = (W, H)``: the inverse mapping (pixels outside the ring
        are 0). For synthetic data and tests; no jitter, no normalization."""
        cv2 = _cv2()
        pans = as_images(panoramas, "panoramas")
        w, h = self.size
        if pans.shape[1:3] != (h, w):
            raise ValueError(f"panoramas must be {w}x{h} (width x height), got shape {pans.shape}")
        if pans.dtype == np.float16:
            pans = pans.astype(np.float32)
        W, H = int(image_size[0]), int(image_size[1])
        if W < 1 or H < 1:
            raise ValueError(f"image_size must be positive (W, H), got {image_size!r}")
        cx, cy = self.center
        y, x = np.mgrid[0:H, 0:W].astype(np.float64)
        dx, dy = x - cx, cy - y
        rho = np.hypot(dx, dy)
        sign = -1.0 if self.clockwise else 1.0
        theta = np.arctan2(dy, dx)
        col = np.mod(sign * (theta - np.deg2rad(self.azimuth_offset)), 2 * np.pi) / (2 * np.pi) * w
        r0, r1 = (self.outer_radius, self.inner_radius) if self.top == "outer" else (self.inner_radius, self.outer_radius)
        row = (rho - r0) / (r1 - r0) * h - 0.5
        inside = (rho >= self.inner_radius) & (rho <= self.outer_radius)
        # One wrapped column each side (azimuth is periodic), edge rows repeated.
        padded = np.concatenate([pans[:, :, -1:], pans, pans[:, :, :1]], axis=2)
        padded = np.concatenate([padded[:, :1], padded, padded[:, -1:]], axis=1)
        mx = (col + 1.0).astype(np.float32)
        my = (np.clip(row, -0.5, h - 0.5) + 1.0).astype(np.float32)
        out = np.empty((len(pans), H, W) + pans.shape[3:], dtype=pans.dtype)
        for i in range(len(pans)):
            res = cv2.remap(padded[i], mx, my, self._interp, borderMode=cv2.BORDER_REPLICATE)
            out[i] = res.reshape(out.shape[1:])
        out[:, ~inside] = 0
        return out


def _gray_stack(imgs: np.ndarray) -> np.ndarray:
    g = imgs.astype(np.float32)
    if g.ndim == 4:
        g = g[..., :3].mean(axis=3) if g.shape[3] >= 3 else g.mean(axis=3)
    return g


def _fit_circle(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Algebraic (Kasa) least-squares circle through points."""
    A = np.c_[x, y, np.ones_like(x)]
    b = -(x**2 + y**2)
    (D, E, F), *_ = np.linalg.lstsq(A, b, rcond=None)
    cx, cy = -D / 2, -E / 2
    return float(cx), float(cy), float(np.sqrt(max(cx**2 + cy**2 - F, 0.0)))


def _otsu(a: np.ndarray) -> np.ndarray:
    cv2 = _cv2()
    hi = float(np.percentile(a, 99.5))
    if hi <= 0:
        return np.zeros(a.shape, dtype=np.uint8)
    u8 = np.clip(a / hi * 255.0, 0, 255).astype(np.uint8)
    _, mask = cv2.threshold(u8, 0, 1, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return mask


def estimate_mirror(images: Any, *, max_images: int = 50) -> Mirror:
    """Estimates the mirror's center and inner/outer radii from omnidirectional
    images (N, H, W[, C]), N >= 1.

    Heuristic, assuming what catadioptric images usually show: the mirror
    disc is brighter and/or more textured than a dark background around it,
    and the blind central spot (the camera's own reflection) has little
    texture and, over a moving run, little temporal change.

    1. Activity per pixel: local standard deviation (3x3) averaged over the
       images, plus the standard deviation over the images (N >= 2).
    2. Mirror disc: Otsu thresholds of the mean image and of the activity
       (either), cleaned by a morphological opening; the outer rim is a
       least-squares circle through the largest blob's outer contour (points
       on the image border left out, so a clipped disc works; refitted
       without outlying points): center and outer radius.
    3. Inner radius: the smallest radius at which at least half of the circle
       around that center is active (0 if the center is active).

    Check the result visually (e.g. unwarp one image) before long runs.
    Uses up to ``max_images`` images, evenly spaced.
    """
    cv2 = _cv2()
    imgs = as_images(images)
    if len(imgs) > max_images:
        imgs = imgs[np.linspace(0, len(imgs) - 1, max_images).round().astype(int)]
    g = _gray_stack(imgs)
    n, H, W = g.shape
    act = np.zeros((H, W), dtype=np.float64)
    for im in g:
        im = cv2.medianBlur(im, 3)  # pixel noise would make static parts look textured
        m = cv2.blur(im, (3, 3))
        m2 = cv2.blur(im * im, (3, 3))
        act += np.sqrt(np.clip(m2 - m * m, 0, None))
    act /= n
    if n >= 2:
        act += g.std(axis=0)
    mean = g.mean(axis=0)
    # The 3x3 window spreads activity one pixel beyond textured regions: erode it back.
    # Otsu on log activity: texture spans decades, the static parts sit near zero.
    hi = float(act.max())
    if hi <= 0:
        raise ValueError("estimate_mirror: the images are uniform (no texture, no change)")
    log_act = np.log(act + 1e-3 * hi)
    act_mask = cv2.erode(_otsu(log_act - log_act.min()), np.ones((3, 3), np.uint8))
    disc = np.maximum(_otsu(mean), act_mask)
    disc = cv2.morphologyEx(disc, cv2.MORPH_OPEN, np.ones((5, 5), np.uint8))
    contours, _ = cv2.findContours(disc, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise ValueError("estimate_mirror: found no mirror disc (the images look uniform)")
    cnt = max(contours, key=cv2.contourArea).reshape(-1, 2).astype(np.float64)
    on_border = (cnt[:, 0] <= 0) | (cnt[:, 1] <= 0) | (cnt[:, 0] >= W - 1) | (cnt[:, 1] >= H - 1)
    pts = cnt[~on_border]
    if len(pts) < 10:
        raise ValueError("estimate_mirror: the mirror's rim is not visible inside the image")
    cx, cy, r_out = _fit_circle(pts[:, 0], pts[:, 1])
    for _ in range(3):  # refit without outliers (noise blobs stuck to the rim)
        res = np.abs(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) - r_out)
        keep = res <= max(1.5, 3.0 * float(np.median(res)))
        if keep.all() or keep.sum() < 10:
            break
        pts = pts[keep]
        cx, cy, r_out = _fit_circle(pts[:, 0], pts[:, 1])
    r_out += 0.5  # contour points are the centers of the disc's boundary pixels
    # Inner radius: radial profile of the active fraction.
    yy, xx = np.mgrid[0:H, 0:W]
    rr = np.hypot(xx - cx, yy - cy)
    bins = np.floor(rr).astype(int).ravel()
    nb = int(np.ceil(r_out))
    sel = bins < nb
    cnt_r = np.bincount(bins[sel], minlength=nb).astype(float)
    act_r = np.bincount(bins[sel], weights=act_mask.ravel()[sel].astype(float), minlength=nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(cnt_r > 0, act_r / cnt_r, np.nan)
    r_in = 0.0
    valid = np.flatnonzero(np.nan_to_num(frac, nan=0.0) >= 0.5)
    if len(valid) and valid[0] > 0:
        k = int(valid[0])
        # linear interpolation of the 0.5 crossing between bin centers k-1 and k
        f0, f1 = np.nan_to_num(frac[k - 1]), frac[k]
        r_in = (k - 0.5) + (0.5 - f0) / max(f1 - f0, 1e-9)
    if r_in >= r_out:
        raise ValueError("estimate_mirror: no active ring found between the blind spot and the rim")
    return Mirror(center=(cx, cy), inner_radius=float(r_in), outer_radius=float(r_out))
