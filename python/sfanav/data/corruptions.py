"""What a robot's camera and its image transport do to the images: JPEG
compression, sensor noise, blur, exposure, gamma, vignetting, white balance,
dead columns and hot pixels.

A :class:`Corruption` maps a batch of 8-bit images (N, H, W[, 3]) to
images of the same shape and dtype, deterministically: the random part of
image ``i`` depends only on ``(seed, start + i)``, so a run corrupted in
batches equals the run corrupted at once, and a fixed-pattern defect
(dead columns, hot pixels: the sensor's) depends only on ``seed`` and the
image size, as one camera's are the same in every frame.

Panoramas are periodic in columns (360 degrees): blurs wrap around the
seam. Vignetting is the radial fall-off of the camera that took the
panorama, which in a panorama unwarped from a mirror image is a fall-off
with elevation (row); it is applied per row (the first row the outermost
ring).

:data:`CORRUPTIONS` is the suite the corruption experiment measures
(``sfanav experiment corruptions``, docs/robustness.md); :func:`corrupt`
applies one by name.

Examples
--------
>>> import numpy as np
>>> from sfanav.data.corruptions import corrupt
>>> images = np.full((2, 40, 350, 3), 128, np.uint8)
>>> corrupt(images, "jpeg-90").shape
(2, 40, 350, 3)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_image_batch, check_int


@dataclass(frozen=True)
class Corruption:
    """One corruption of a robot's images.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    params : mapping
        The kind's parameters (see :data:`KINDS`); e.g. ``{"quality": 90}``
        for ``"jpeg"``.
    """

    kind: str
    params: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown corruption kind {self.kind!r}; known: {', '.join(KINDS)}")
        required = KINDS[self.kind]
        unknown = set(self.params) - set(required)
        if unknown:
            raise ValueError(f"corruption {self.kind!r} takes {', '.join(required) or 'no parameters'}, "
                             f"got {', '.join(sorted(unknown))}")
        missing = [k for k, default in required.items() if default is None and k not in self.params]
        if missing:
            raise ValueError(f"corruption {self.kind!r} needs {', '.join(missing)}")
        p = self.param
        if self.kind == "jpeg":
            q = p("quality")
            if isinstance(q, (bool, np.bool_)) or not isinstance(q, (int, np.integer)) or not 1 <= q <= 100:
                raise ValueError(f"JPEG quality must be an integer 1..100, got {q!r}")
        for name in ("sigma", "length", "strength", "full_well", "gain", "gamma", "hot_fraction", "dead_columns"):
            if name in required:
                v = p(name)
                if (isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating))
                        or not np.isfinite(v) or v < 0):
                    raise ValueError(f"{self.kind} {name} must be a finite number >= 0, got {v!r}")
        for name in ("gain", "gamma", "full_well"):
            if name in required and p(name) <= 0:
                raise ValueError(f"{self.kind} {name} must be > 0, got {p(name)!r}")
        if self.kind == "defects" and p("hot_fraction") > 1:
            raise ValueError(f"defects hot_fraction is a share in 0..1, got {p('hot_fraction')!r}")
        if self.kind == "white-balance":
            g = np.asarray(p("gains"), dtype=object)
            if g.shape != (3,) or not all(isinstance(v, (int, float, np.integer, np.floating)) and np.isfinite(v)
                                          and v > 0 for v in g):
                raise ValueError(f"white-balance gains are three positive factors (R, G, B), got {p('gains')!r}")

    def param(self, name: str) -> Any:
        """A parameter, or its default."""
        return self.params.get(name, KINDS[self.kind][name])

    def describe(self) -> str:
        """One line: the kind and its parameters."""
        ps = ", ".join(f"{k} {self.param(k)}" for k in KINDS[self.kind])
        return f"{self.kind} ({ps})" if ps else self.kind

    def __call__(self, images: Any, *, seed: int = 0, start: int = 0) -> np.ndarray:
        """The corrupted images: (N, H, W[, 3]) uint8 in, the same shape out
        (one image (H, W[, 3]) is taken as a batch of one only when given
        as a batch). ``seed``: the random stream (and the camera's fixed
        pattern); ``start``: the index of the first image in its run, so
        that batches of a run are corrupted as the whole run is."""
        a = as_image_batch(images)
        if a.dtype != np.uint8:
            raise TypeError(f"corruptions take 8-bit images (uint8), got {a.dtype}")
        seed = check_int(seed, "seed", minimum=0)
        start = check_int(start, "start", minimum=0)
        if self.kind == "white-balance" and (a.ndim != 4 or a.shape[3] != 3):
            raise ValueError("white-balance needs RGB images (N, H, W, 3)")
        return _APPLY[self.kind](self, a, seed, start)


def _rng(seed: int, index: int, salt: int) -> np.random.Generator:
    return np.random.default_rng([seed, index, salt])


def _channels_last(a: np.ndarray) -> np.ndarray:
    return a if a.ndim == 4 else a[..., None]


def _jpeg(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    import cv2

    q = int(c.param("quality"))
    out = np.empty_like(a)
    for i, im in enumerate(a):
        colour = im.ndim == 3
        bgr = np.ascontiguousarray(im[..., ::-1]) if colour else im
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, q])
        if not ok:  # pragma: no cover - OpenCV encodes every 8-bit image
            raise RuntimeError("OpenCV could not encode the image as JPEG")
        dec = cv2.imdecode(buf, cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE)
        out[i] = dec[..., ::-1] if colour else dec
    return out


def _to_uint8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


def _gaussian_noise(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    s = float(c.param("sigma"))
    out = np.empty_like(a)
    for i, im in enumerate(a):
        out[i] = _to_uint8(im + _rng(seed, start + i, 1).normal(0.0, s, im.shape))
    return out


def _shot_noise(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    # photon counting: a pixel of value v collected v / 255 * full_well electrons (Poisson)
    k = float(c.param("full_well")) / 255.0
    out = np.empty_like(a)
    for i, im in enumerate(a):
        out[i] = _to_uint8(_rng(seed, start + i, 2).poisson(im * k) / k)
    return out


def _wrap_filter(a: np.ndarray, kernel_x: np.ndarray, kernel_y: np.ndarray | None) -> np.ndarray:
    """Separable filter: columns wrap around (the panorama's seam), rows
    reflect."""
    import cv2

    kx = np.asarray(kernel_x, np.float32)
    ky = np.ones(1, np.float32) if kernel_y is None else np.asarray(kernel_y, np.float32)
    px, py = len(kx) // 2, len(ky) // 2
    out = np.empty_like(a)
    for i, im in enumerate(_channels_last(a)):
        f = im.astype(np.float32)
        f = np.pad(f, ((0, 0), (px, px), (0, 0)), mode="wrap")
        if py:
            f = np.pad(f, ((py, py), (0, 0), (0, 0)), mode="reflect" if im.shape[0] > py else "edge")
        g = cv2.sepFilter2D(f, -1, kx, ky, borderType=cv2.BORDER_REPLICATE)
        g = g.reshape(f.shape)[py : py + im.shape[0], px : px + im.shape[1]]
        out[i] = _to_uint8(g).reshape(out[i].shape)
    return out


def _gaussian_kernel(sigma: float) -> np.ndarray:
    if sigma <= 0:
        return np.ones(1)
    r = max(1, int(np.ceil(3 * sigma)))
    x = np.arange(-r, r + 1)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


def _defocus(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    k = _gaussian_kernel(float(c.param("sigma")))
    return a.copy() if len(k) == 1 else _wrap_filter(a, k, k)


def _motion_blur(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    # the robot turning during the exposure: a horizontal (azimuthal) box of `length` px
    n = int(round(float(c.param("length"))))
    if n <= 1:
        return a.copy()
    k = np.ones(n) / n
    if n % 2 == 0:  # centre an even box: half weights at both ends
        k = np.r_[0.5, np.ones(n - 1), 0.5] / n
    return _wrap_filter(a, k, None)


def _exposure(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    return _to_uint8(a.astype(np.float32) * float(c.param("gain")))


def _gamma(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    lut = _to_uint8(255.0 * (np.arange(256) / 255.0) ** float(c.param("gamma")))
    return lut[a]


def _vignetting(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    # radial fall-off 1 - strength * (r / R)^2 of the camera; a panorama's first row is the outermost ring
    # (r = R) and its last the innermost the unwarping kept (r = R_INNER * R)
    h = a.shape[1]
    r = np.linspace(1.0, VIGNETTE_INNER_RADIUS, h)
    gain = (1.0 - float(c.param("strength")) * r**2).astype(np.float32)
    shape = (1, h) + (1,) * (a.ndim - 2)
    return _to_uint8(a.astype(np.float32) * np.maximum(gain, 0.0).reshape(shape))


def _white_balance(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    return _to_uint8(a.astype(np.float32) * np.asarray(c.param("gains"), np.float32))


def defect_pattern(shape: tuple[int, int], *, dead_columns: int, hot_fraction: float,
                   seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The fixed defects of one camera's sensor for images of ``shape``
    (H, W): the indices of its dead columns (read as 0) and a boolean (H, W)
    mask of its hot pixels (read as 255). The same for every frame."""
    h, w = (int(v) for v in shape)
    rng = _rng(seed, 0, 9)
    cols = np.sort(rng.choice(w, size=min(int(dead_columns), w), replace=False))
    hot = rng.random((h, w)) < float(hot_fraction)
    return cols, hot


def _defects(c: Corruption, a: np.ndarray, seed: int, start: int) -> np.ndarray:
    cols, hot = defect_pattern(a.shape[1:3], dead_columns=int(c.param("dead_columns")),
                               hot_fraction=float(c.param("hot_fraction")), seed=seed)
    out = a.copy()
    out[:, hot] = 255
    out[:, :, cols] = 0
    return out


VIGNETTE_INNER_RADIUS = 0.3
"""The innermost ring of the panorama, as a fraction of the image circle's radius (vignetting)."""

KINDS: dict[str, dict[str, Any]] = {
    "jpeg": {"quality": None},
    "gaussian-noise": {"sigma": None},
    "shot-noise": {"full_well": None},
    "defocus": {"sigma": None},
    "motion-blur": {"length": None},
    "exposure": {"gain": None},
    "gamma": {"gamma": None},
    "vignetting": {"strength": 0.5},
    "white-balance": {"gains": None},
    "defects": {"dead_columns": 2, "hot_fraction": 0.002},
}
"""Corruption kinds and their parameters (None: required). Units: ``sigma``
grey levels (noise) or pixels (defocus); ``length`` pixels; ``full_well``
electrons at full scale (255); ``gain`` and ``gains`` factors; ``gamma`` the
exponent on values in 0..1; ``strength`` the fall-off at the image circle's
edge; ``hot_fraction`` the share of hot pixels."""

_APPLY = {
    "jpeg": _jpeg,
    "gaussian-noise": _gaussian_noise,
    "shot-noise": _shot_noise,
    "defocus": _defocus,
    "motion-blur": _motion_blur,
    "exposure": _exposure,
    "gamma": _gamma,
    "vignetting": _vignetting,
    "white-balance": _white_balance,
    "defects": _defects,
}

CORRUPTIONS: dict[str, Corruption] = {
    "jpeg-95": Corruption("jpeg", {"quality": 95}),
    "jpeg-90": Corruption("jpeg", {"quality": 90}),
    "jpeg-75": Corruption("jpeg", {"quality": 75}),
    "jpeg-50": Corruption("jpeg", {"quality": 50}),
    "noise-2": Corruption("gaussian-noise", {"sigma": 2.0}),
    "noise-5": Corruption("gaussian-noise", {"sigma": 5.0}),
    "noise-10": Corruption("gaussian-noise", {"sigma": 10.0}),
    "shot-noise": Corruption("shot-noise", {"full_well": 1000.0}),
    "defocus-0.5": Corruption("defocus", {"sigma": 0.5}),
    "defocus-1": Corruption("defocus", {"sigma": 1.0}),
    "defocus-2": Corruption("defocus", {"sigma": 2.0}),
    "motion-blur": Corruption("motion-blur", {"length": 7}),
    "exposure-0.6": Corruption("exposure", {"gain": 0.6}),
    "exposure-1.5": Corruption("exposure", {"gain": 1.5}),
    "gamma-0.7": Corruption("gamma", {"gamma": 0.7}),
    "gamma-1.4": Corruption("gamma", {"gamma": 1.4}),
    "vignetting": Corruption("vignetting", {"strength": 0.5}),
    "white-balance": Corruption("white-balance", {"gains": (1.15, 1.0, 0.8)}),
    "dead-pixels": Corruption("defects", {"dead_columns": 2, "hot_fraction": 0.002}),
}
"""The corruption suite, by name: JPEG at quality 95 / 90 / 75 / 50; Gaussian
sensor noise of 2 / 5 / 10 grey levels; shot noise (1000 electrons at full
scale: 8 grey levels at white, 4 at quarter grey); defocus blur of 0.5 / 1 /
2 px; motion blur of a turn (7 px); exposure x0.6 and x1.5 (clipped); gamma
0.7 and 1.4; vignetting (half the light at the image circle's edge); a warm
white-balance shift (R x1.15, B x0.8); two dead columns and 0.2 % hot
pixels."""


def get(name: str | Corruption) -> Corruption:
    """A corruption of the suite by name (a :class:`Corruption` passes as
    it is); ValueError listing the names for an unknown one."""
    if isinstance(name, Corruption):
        return name
    try:
        return CORRUPTIONS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown corruption {name!r}; known: {', '.join(CORRUPTIONS)}") from None


def corrupt(images: Any, corruption: str | Corruption, *, seed: int = 0, start: int = 0) -> np.ndarray:
    """``images`` (N, H, W[, 3]) uint8 with ``corruption`` (a name of
    :data:`CORRUPTIONS` or a :class:`Corruption`) applied; see
    :meth:`Corruption.__call__`."""
    return get(corruption)(images, seed=seed, start=start)


@dataclass(frozen=True)
class CorruptionModel:
    """A random corruption per image, drawn from families of corruptions
    with ranges of strength: what a robot's camera and transport may do to
    an image, for training that should not depend on it (the readout's
    augmented copies, the network's invariance partners;
    docs/robustness.md).

    Attributes
    ----------
    families : mapping str -> mapping
        Per family, a :data:`KINDS` kind and its parameter ranges:
        ``{"kind": "jpeg", "quality": (30, 95)}``; a range ``(lo, hi)`` is
        drawn uniformly (integers for ``quality``, ``length`` and
        ``dead_columns``), a single value is fixed. Each image gets one
        family, uniformly.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.full((4, 8, 30, 3), 100, np.uint8)
    >>> CAMERA.apply(x, seed=0).shape
    (4, 8, 30, 3)
    """

    families: Mapping[str, Mapping[str, Any]]

    def __post_init__(self) -> None:
        if not self.families:
            raise ValueError("a corruption model needs at least one family")
        for name, fam in self.families.items():
            if "kind" not in fam:
                raise ValueError(f"corruption family {name!r} needs a kind")
            self._draw(name, np.random.default_rng(0))  # checks the kind and its parameters

    def _draw(self, name: str, rng: np.random.Generator) -> Corruption:
        fam = dict(self.families[name])
        kind = fam.pop("kind")
        params: dict[str, Any] = {}
        for key, value in fam.items():
            if isinstance(value, (tuple, list)) and len(value) == 2 and key != "gains":
                lo, hi = value
                params[key] = (int(rng.integers(int(lo), int(hi) + 1)) if key in _INTEGER_PARAMS
                               else float(rng.uniform(float(lo), float(hi))))
            elif key == "gains" and isinstance(value, (tuple, list)) and len(value) == 2:
                lo, hi = value  # one gain per channel
                params[key] = tuple(float(g) for g in rng.uniform(float(lo), float(hi), 3))
            else:
                params[key] = value
        return Corruption(kind, params)

    def draw(self, n: int, *, seed: int = 0, start: int = 0) -> list[Corruption]:
        """The corruptions of images ``start .. start + n - 1`` (one each;
        image ``i``'s depends only on ``(seed, i)``)."""
        names = list(self.families)
        out = []
        for i in range(start, start + check_int(n, "n", minimum=0)):
            rng = _rng(seed, i, 17)
            out.append(self._draw(names[int(rng.integers(len(names)))], rng))
        return out

    def apply(self, images: Any, *, seed: int = 0, start: int = 0) -> np.ndarray:
        """``images`` (N, H, W[, C]) uint8, each with its drawn corruption."""
        a = as_image_batch(images)
        if a.dtype != np.uint8:
            raise TypeError(f"corruptions take 8-bit images (uint8), got {a.dtype}")
        out = np.empty_like(a)
        for i, c in enumerate(self.draw(len(a), seed=seed, start=start)):
            if c.kind == "white-balance" and (a.ndim != 4 or a.shape[3] != 3):
                out[i] = a[i]
                continue
            out[i] = c(a[i : i + 1], seed=seed, start=start + i)[0]
        return out

    def describe(self) -> str:
        """One line per family."""
        return "; ".join(f"{n}: " + ", ".join(f"{k} {v}" for k, v in f.items()) for n, f in self.families.items())


_INTEGER_PARAMS = ("quality", "length", "dead_columns")

CAMERA = CorruptionModel({
    "jpeg": {"kind": "jpeg", "quality": (30, 95)},
    "noise": {"kind": "gaussian-noise", "sigma": (1.0, 10.0)},
    "defocus": {"kind": "defocus", "sigma": (0.3, 2.0)},
    "motion": {"kind": "motion-blur", "length": (3, 10)},
    "defects": {"kind": "defects", "dead_columns": (1, 3), "hot_fraction": (0.0, 0.004)},
    "clipping": {"kind": "exposure", "gain": (1.2, 1.8)},
    "vignetting": {"kind": "vignetting", "strength": (0.1, 0.6)},
})
"""The sfanav default's model of a robot camera's corruptions (a family per
image, uniformly): JPEG at quality 30..95, Gaussian noise of 1..10 grey
levels, defocus of 0.3..2 px, a turn's motion blur of 3..10 px, 1..3 dead
columns with up to 0.4 % hot pixels, overexposure x1.2..1.8 (clipping),
vignetting 0.1..0.6. Exposure, white balance and gamma themselves are left
to the photometric normalisation (:mod:`sfanav.data.photometric`), which
removes them exactly but for the clipping."""
