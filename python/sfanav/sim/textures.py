"""Textures of the garden simulator: photographic and procedural.

Photographic textures come from scikit-image's bundled sample images
(``data.grass()``, ``data.gravel()``, ``data.brick()``: 512 x 512 gray
photographs shipped inside the package, nothing is downloaded); everything
else is procedural (periodic fractal noise, planks, facades, roof tiles,
ArUco markers). A texture is described by a small JSON-able
:class:`Texture` spec and synthesised deterministically from it, so a world
file stores specs, never pixels.

Every texture is an RGBA float32 image in [0, 1] that tiles seamlessly
(photographs are replaced by their periodic component, Moisan 2011). The
renderer samples it through a mip-map pyramid (:class:`Pyramid`) to keep
distant surfaces from aliasing.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

PHOTOS = ("grass", "gravel", "brick")


KINDS = PHOTOS + ("noise", "bark", "leaves", "planks", "facade", "roof", "marker", "stripes")


@dataclass
class Texture:
    """A texture spec.

    Attributes
    ----------
    kind : str
        One of ``KINDS``: ``"grass"``, ``"gravel"``, ``"brick"`` (photographs),
        ``"noise"``, ``"bark"``, ``"leaves"``, ``"planks"`` (fence boards with
        transparent gaps), ``"facade"`` (brick wall with a window), ``"roof"``,
        ``"marker"`` (an ArUco marker, ``params["id"]``), ``"stripes"``.
    color : tuple of 3 floats
        Mean albedo (R, G, B) in [0, 1].
    contrast : float
        Strength of the texture's modulation around ``color`` (0: flat).
    seed : int
        Seed of the procedural parts.
    tile : tuple of 2 floats
        World size of one texture tile (width, height) in metres. A
        ``"marker"`` is stretched over the face it is on instead.
    params : dict
        Kind-specific extras (``"id"`` and ``"dictionary"`` for markers,
        ``"color2"`` for two-tone kinds).
    """

    kind: str
    color: tuple[float, float, float] = (0.5, 0.5, 0.5)
    contrast: float = 0.5
    seed: int = 0
    tile: tuple[float, float] = (1.0, 1.0)
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown texture kind {self.kind!r}; available: {', '.join(KINDS)}")
        self.color = tuple(float(c) for c in self.color)  # type: ignore[assignment]
        self.tile = tuple(float(t) for t in self.tile)  # type: ignore[assignment]
        if len(self.color) != 3:
            raise ValueError(f"texture color must be (R, G, B), got {self.color!r}")
        if len(self.tile) != 2 or min(self.tile) <= 0:
            raise ValueError(f"texture tile must be two positive sizes in metres, got {self.tile!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Texture":
        return cls(**d)


def periodic_component(img: np.ndarray) -> np.ndarray:
    """The periodic component of a 2-D image (Moisan, "Periodic plus smooth
    image decomposition", 2011): same content, no seams when tiled."""
    u = np.asarray(img, dtype=np.float64)
    h, w = u.shape
    v = np.zeros_like(u)
    v[0, :] += u[-1, :] - u[0, :]
    v[-1, :] += u[0, :] - u[-1, :]
    v[:, 0] += u[:, -1] - u[:, 0]
    v[:, -1] += u[:, 0] - u[:, -1]
    cy = np.cos(2 * np.pi * np.arange(h) / h)[:, None]
    cx = np.cos(2 * np.pi * np.arange(w) / w)[None, :]
    denom = 2 * cx + 2 * cy - 4
    denom[0, 0] = 1.0
    s_hat = np.fft.fft2(v) / denom
    s_hat[0, 0] = 0.0
    smooth = np.real(np.fft.ifft2(s_hat))
    return u - smooth


@lru_cache(maxsize=None)
def photo(name: str) -> np.ndarray:
    """A scikit-image sample photograph as a seamless float32 array
    (512, 512) with mean 1 (``brick`` is turned so its courses run
    horizontally)."""
    if name not in PHOTOS:
        raise ValueError(f"no photographic texture {name!r}; available: {', '.join(PHOTOS)}")
    try:
        from skimage import data
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ImportError("photographic textures need scikit-image (pip install scikit-image)") from exc
    img = getattr(data, name)().astype(np.float64)
    if img.ndim == 3:
        img = img.mean(axis=2)
    if name == "brick":
        img = img.T.copy()
    img = periodic_component(img)
    img = img / img.mean()
    out = img.astype(np.float32)
    out.setflags(write=False)
    return out


def fractal_noise(shape: tuple[int, int], rng: np.random.Generator, beta: float = 2.0,
                  aspect: float = 1.0, fmin: float = 1.0) -> np.ndarray:
    """Periodic fractal noise with a 1/f**beta power spectrum, zero mean and
    unit standard deviation, shape (h, w). ``aspect`` > 1 stretches features
    vertically; ``fmin`` is the lowest frequency kept (cycles per image)."""
    h, w = shape
    fy = np.fft.fftfreq(h)[:, None] * h
    fx = np.fft.rfftfreq(w)[None, :] * w
    f = np.sqrt(fx**2 + (fy * aspect) ** 2)
    amp = np.where(f >= fmin, np.maximum(f, 1e-9) ** (-beta / 2), 0.0)
    spec = amp * (rng.standard_normal(amp.shape) + 1j * rng.standard_normal(amp.shape))
    n = np.fft.irfft2(spec, s=(h, w))
    n -= n.mean()
    sd = n.std()
    return (n / sd if sd > 0 else n).astype(np.float32)


def _resample(img: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Nearest-area resampling of a periodic 2-D image to ``shape``."""
    h, w = shape
    iy = (np.arange(h) * img.shape[0] / h).astype(int)
    ix = (np.arange(w) * img.shape[1] / w).astype(int)
    if h <= img.shape[0] and w <= img.shape[1]:
        # box-average so the downsampled photo keeps its mean and loses aliasing
        fy, fx = img.shape[0] // h, img.shape[1] // w
        if fy >= 1 and fx >= 1 and img.shape[0] % h == 0 and img.shape[1] % w == 0:
            return img.reshape(h, fy, w, fx).mean(axis=(1, 3))
    return img[iy][:, ix]


def marker_image(marker_id: int, dictionary: str = "DICT_ARUCO_ORIGINAL", bits_px: int = 8) -> np.ndarray:
    """An ArUco marker (0 black, 1 white) with a one-cell white quiet zone,
    float32 (n, n), generated with ``cv2.aruco``."""
    try:
        import cv2
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ImportError("ArUco markers need OpenCV (pip install opencv-python-headless)") from exc
    if not hasattr(cv2, "aruco"):  # pragma: no cover
        raise ImportError("this OpenCV build has no cv2.aruco module; install opencv-python-headless >= 4.7")
    if not hasattr(cv2.aruco, dictionary):
        raise ValueError(f"unknown ArUco dictionary {dictionary!r} (e.g. DICT_ARUCO_ORIGINAL, DICT_4X4_250)")
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    n_ids = d.bytesList.shape[0]
    if not (0 <= int(marker_id) < n_ids):
        raise ValueError(f"marker id {marker_id} is outside {dictionary} (ids 0..{n_ids - 1})")
    cells = d.markerSize + 2
    img = cv2.aruco.generateImageMarker(d, int(marker_id), cells * bits_px)
    quiet = np.full((img.shape[0] + 2 * bits_px,) * 2, 255, np.uint8)
    quiet[bits_px:-bits_px, bits_px:-bits_px] = img
    return (quiet / 255.0).astype(np.float32)


def _rgba(albedo: np.ndarray, color: tuple[float, float, float], alpha: np.ndarray | None = None) -> np.ndarray:
    """Gray modulation (mean ~1) times an RGB color -> (h, w, 4) float32."""
    rgb = albedo[..., None] * np.asarray(color, np.float32)[None, None, :]
    a = np.ones(albedo.shape, np.float32) if alpha is None else alpha.astype(np.float32)
    return np.clip(np.concatenate([rgb, a[..., None]], axis=2), 0.0, 1.0).astype(np.float32)


def make_texture(spec: Texture) -> np.ndarray:
    """Synthesises a texture: RGBA float32 (h, w, 4) in [0, 1]."""
    rng = np.random.default_rng(spec.seed)
    k, c, con = spec.kind, spec.color, spec.contrast
    if k in PHOTOS:
        p = photo(k)
        return _rgba(1.0 + con * (p - 1.0), c)
    if k == "noise":
        n = fractal_noise((256, 256), rng, beta=spec.params.get("beta", 2.0))
        return _rgba(1.0 + 0.5 * con * n, c)
    if k == "bark":
        n = fractal_noise((256, 128), rng, beta=1.6, aspect=0.15)
        return _rgba(1.0 + 0.4 * con * n, c)
    if k == "leaves":
        # clumps of foliage: the gravel photo's blobs plus large-scale light/shade
        g = photo("gravel")[::2, ::2]
        g = g.reshape(256, 256)
        n = fractal_noise((256, 256), rng, beta=2.5)
        shift = rng.integers(0, 256, size=2)
        g = np.roll(g, tuple(int(s) for s in shift), axis=(0, 1))
        mod = 1.0 + con * (0.6 * (g - 1.0) + 0.25 * n)
        return _rgba(mod, c)
    if k == "planks":
        # vertical boards with transparent gaps (a picket fence), wood grain
        w_px, h_px = 128, 128
        boards = int(spec.params.get("boards", 8))
        gap = float(spec.params.get("gap", 0.3))  # fraction of a board period
        x = (np.arange(w_px) + 0.5) / w_px * boards
        alpha = ((x % 1.0) < 1.0 - gap).astype(np.float32)[None, :].repeat(h_px, 0)
        grain = fractal_noise((h_px, w_px), rng, beta=1.5, aspect=0.1)
        shade = 1.0 + 0.15 * rng.standard_normal(boards)
        mod = (1.0 + 0.3 * con * grain) * shade[np.minimum(x.astype(int), boards - 1)][None, :]
        return _rgba(mod, c, alpha)
    if k == "facade":
        # a brick wall tile (tile metres) with one window: frame, dark glass, cross bars
        w_px, h_px = 256, 256
        tw, th = spec.tile
        brick_tile = float(spec.params.get("brick_tile", 0.6))
        reps_x = max(1, round(tw / brick_tile))
        reps_y = max(1, round(th / brick_tile))
        b = photo("brick")
        sub = _resample(b, (max(1, h_px // reps_y), max(1, w_px // reps_x)))
        wall = np.tile(sub, (reps_y + 1, reps_x + 1))[:h_px, :w_px]
        mod = 1.0 + con * (wall - 1.0)
        rgb = mod[..., None] * np.asarray(c, np.float32)
        yy = (np.arange(h_px)[::-1, None] + 0.5) / h_px * th  # metres above the tile's bottom
        xx = (np.arange(w_px)[None, :] + 0.5) / w_px * tw
        win_w, win_h = 0.45 * tw, 0.4 * th
        x0, y0 = 0.5 * (tw - win_w), 0.3 * th
        inside = (xx > x0) & (xx < x0 + win_w) & (yy > y0) & (yy < y0 + win_h)
        frame_t = 0.06
        glass = (xx > x0 + frame_t) & (xx < x0 + win_w - frame_t) & (yy > y0 + frame_t) & (yy < y0 + win_h - frame_t)
        bars = glass & ((np.abs(xx - (x0 + win_w / 2)) < frame_t / 2) | (np.abs(yy - (y0 + win_h / 2)) < frame_t / 2))
        frame_col = np.asarray(spec.params.get("frame", (0.9, 0.9, 0.88)), np.float32)
        glass_col = np.asarray(spec.params.get("glass", (0.12, 0.16, 0.22)), np.float32)
        rgb = np.where(inside[..., None], frame_col, rgb)
        reflection = 1.0 + 0.5 * np.clip(fractal_noise((h_px, w_px), rng, beta=3.0), -1, 1)
        rgb = np.where((glass & ~bars)[..., None], glass_col * reflection[..., None], rgb)
        a = np.ones((h_px, w_px, 1), np.float32)
        return np.clip(np.concatenate([rgb, a], axis=2), 0, 1).astype(np.float32)
    if k == "roof":
        h_px, w_px = 128, 128
        rows = int(spec.params.get("rows", 8))
        y = (np.arange(h_px) + 0.5) / h_px * rows
        course = 1.0 - 0.35 * con * (y % 1.0)[:, None]
        n = fractal_noise((h_px, w_px), rng, beta=2.0)
        return _rgba(course * (1.0 + 0.15 * con * n), c)
    if k == "stripes":
        h_px, w_px = 64, 128
        n_str = int(spec.params.get("n", 4))
        c2 = spec.params.get("color2", (1.0, 1.0, 1.0))
        x = (np.arange(w_px) + 0.5) / w_px * n_str
        band = ((x % 1.0) < 0.5)[None, :].repeat(h_px, 0)
        n = fractal_noise((h_px, w_px), rng, beta=2.0)
        mod = 1.0 + 0.2 * con * n
        rgb = np.where(band[..., None], np.asarray(c, np.float32), np.asarray(c2, np.float32)) * mod[..., None]
        a = np.ones((h_px, w_px, 1), np.float32)
        return np.clip(np.concatenate([rgb, a], axis=2), 0, 1).astype(np.float32)
    if k == "marker":
        m = marker_image(int(spec.params.get("id", 0)), spec.params.get("dictionary", "DICT_ARUCO_ORIGINAL"))
        # nearest resampling to 128 x 128 (a power of two, for fast mip levels); cells stay sharp
        idx = (np.arange(128) * m.shape[0] / 128).astype(int)
        m = m[idx][:, idx]
        rgb = np.repeat(m[..., None], 3, axis=2) * np.asarray(c, np.float32)
        a = np.ones(m.shape + (1,), np.float32)
        return np.concatenate([rgb, a], axis=2)
    raise AssertionError(k)  # pragma: no cover - checked in Texture


class Pyramid:
    """A mip-map pyramid of one texture, for nearest-texel sampling.

    Level ``l`` has ``2**l`` times coarser texels; each level is stored flat,
    shape (h_l * w_l, C), for a single ``np.take`` per lookup.

    Parameters
    ----------
    image : ndarray (h, w, C) float32
    tile : (width, height) in metres
        World size of the whole image (texel size = tile / shape).
    """

    def __init__(self, image: np.ndarray, tile: tuple[float, float]):
        img = np.ascontiguousarray(image, dtype=np.float32)
        if img.ndim == 2:
            img = img[..., None]
        self.channels = img.shape[2]
        self.tile = (float(tile[0]), float(tile[1]))
        self.levels: list[np.ndarray] = []
        self.shapes: list[tuple[int, int]] = []
        while True:
            h, w = img.shape[:2]
            self.levels.append(img.reshape(h * w, self.channels))
            self.shapes.append((h, w))
            if h == 1 and w == 1:
                break
            h2, w2 = max(1, h // 2), max(1, w // 2)
            img = img[: h2 * (h // h2), : w2 * (w // w2)]
            img = img.reshape(h2, h // h2, w2, w // w2, self.channels).mean(axis=(1, 3))
            img = np.ascontiguousarray(img, dtype=np.float32)
        self.texel = min(self.tile[0] / self.shapes[0][1], self.tile[1] / self.shapes[0][0])
        self.has_alpha = self.channels == 4 and bool((self.levels[0][:, 3] < 0.999).any())

    def level_for(self, footprint: float) -> int:
        """Mip level whose texels are about ``footprint`` metres wide."""
        if footprint <= self.texel:
            return 0
        return int(min(len(self.levels) - 1, np.log2(footprint / self.texel)))

    def sample(self, u: np.ndarray, v: np.ndarray, level: int, stretch: bool = False) -> np.ndarray:
        """Texels at world coordinates ``u`` (along the surface, metres) and
        ``v`` (up, metres), wrapping; with ``stretch`` u, v are fractions of
        the tile in [0, 1] (clamped). Returns (n, C)."""
        h, w = self.shapes[level]
        if stretch:
            iu = np.clip((u * w).astype(np.int64), 0, w - 1)
            iv = np.clip(((1.0 - v) * h).astype(np.int64), 0, h - 1)
        else:
            iu = np.floor(u * (w / self.tile[0])).astype(np.int64) % w
            iv = (-1 - np.floor(v * (h / self.tile[1])).astype(np.int64)) % h  # row 0 is the top
        return self.levels[level][iv * w + iu]
