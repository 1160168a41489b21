"""Ray casting of garden worlds: panoramic and omnidirectional cameras.

One ray caster serves both cameras. It renders a separable ray grid, a
vector of azimuths (one per column, relative to the camera's heading) times a
vector of elevations (one per row), from a camera at ``mount_height`` metres
above the ground:

* sky and distant tree line above the horizon (at infinity: no parallax);
* the ground below it, hit at horizontal distance ``h / tan(-elevation)``,
  textured by a photographic lawn detail times a large-scale colour map,
  mip-mapped by distance, with the shadows of the objects;
* every object primitive (vertical cylinder, oriented box, ellipsoid),
  intersected exactly within its screen bounding block; the nearest hit wins
  (occlusion), so views change with position by true parallax.

The :class:`PanoramicCamera` image *is* such a grid (360 degree cylindrical,
equiangular rows). The :class:`OmniCamera` renders the grid on the polar
samples of a curved mirror (one row per pixel of radius, one column per
pixel of circumference) and resamples it into the donut image the mirror
shows, with a blind central disc; :meth:`OmniCamera.unwarp` turns such an
image back into a panorama.

Angles: pose headings in radians (counter-clockwise from +x); camera fields
of view and sun directions in degrees (their names say ``_deg``). Image
convention: the middle column of a panorama looks straight ahead, the robot's
left is left of the middle, and turning the robot left by ``2 pi k / W``
radians rolls the panorama by ``k`` columns to the right (``np.roll(img, k,
axis=1)``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .textures import Pyramid, fractal_noise, make_texture, photo
from .world import Primitive, World

_LUMA = np.array([0.299, 0.587, 0.114], np.float32)
FOG_DISTANCE = 250.0  # m; aerial perspective: far surfaces fade to the horizon colour


@dataclass(frozen=True)
class Lighting:
    """A lighting condition.

    Attributes
    ----------
    intensity : float
        Overall light (1: a bright overcast-to-sunny day); scales every pixel.
    tint : (R, G, B)
        Colour of the light, multiplies the channels (e.g. red 0.5..1 as in
        thesis 6.2.2).
    sun_azimuth_deg, sun_elevation_deg : float
        Sun direction in degrees (azimuth counter-clockwise from +x). Sides of
        objects facing the sun are brighter; objects cast shadows on the ground.
    ambient : float
        Share of sky light that reaches every surface, in [0, 1].
    shadows : bool
        Ground shadows of the static objects.
    """

    intensity: float = 1.0
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    sun_azimuth_deg: float = 135.0
    sun_elevation_deg: float = 40.0
    ambient: float = 0.6
    shadows: bool = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.intensity) and self.intensity >= 0):
            raise ValueError(f"light intensity must be finite and >= 0, got {self.intensity}")
        tint = tuple(float(t) for t in self.tint)
        if len(tint) != 3 or min(tint) < 0:
            raise ValueError(f"light tint must be three non-negative numbers, got {self.tint!r}")
        object.__setattr__(self, "tint", tint)
        if not 0 < self.sun_elevation_deg <= 90:
            raise ValueError(f"sun_elevation_deg must be in (0, 90], got {self.sun_elevation_deg}")
        if not 0 <= self.ambient <= 1:
            raise ValueError(f"ambient must be in [0, 1], got {self.ambient}")

    @property
    def sun(self) -> np.ndarray:
        """Unit vector towards the sun (x, y, z)."""
        az, el = np.radians(self.sun_azimuth_deg), np.radians(self.sun_elevation_deg)
        return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])

    @property
    def rgb(self) -> np.ndarray:
        return (self.intensity * np.asarray(self.tint)).astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        return {
            "intensity": self.intensity,
            "tint": list(self.tint),
            "sun_azimuth_deg": self.sun_azimuth_deg,
            "sun_elevation_deg": self.sun_elevation_deg,
            "ambient": self.ambient,
            "shadows": self.shadows,
        }


# ------------------------------------------------------------------ cameras


class _Grid:
    """A separable ray grid: bearings (W,) relative to the heading (rad,
    counter-clockwise), elevations (H,) strictly decreasing (rad)."""

    def __init__(self, bearings: np.ndarray, elevations: np.ndarray, mount_height: float):
        self.bearings = np.asarray(bearings, np.float64)
        self.elev = np.asarray(elevations, np.float64)
        if np.any(np.diff(self.elev) >= 0):
            raise ValueError("ray grid elevations must decrease from the top row down")
        self.h = float(mount_height)
        self.tan = np.tan(self.elev)
        self.W, self.H = len(self.bearings), len(self.elev)
        self.pixel_angle = 2 * np.pi / self.W


def _check_size(v: Any, name: str, lo: int = 2) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
    return int(v)


def _check_elevation(el: Sequence[float]) -> tuple[float, float]:
    try:
        lo, hi = (float(e) for e in el)
    except (TypeError, ValueError):
        raise ValueError(f"elevation_deg must be (lowest, highest) in degrees, got {el!r}") from None
    if not -90 <= lo < hi <= 90:
        raise ValueError(f"elevation_deg must satisfy -90 <= lowest < highest <= 90, got {el!r}")
    return lo, hi


class PanoramicCamera:
    """A 360 degree cylindrical panorama camera.

    Parameters
    ----------
    width, height : int
        Image size in pixels; column ``j`` looks at bearing
        ``-2 pi (j + 0.5 - width / 2) / width`` relative to the heading
        (middle column ahead, left half = robot's left).
    elevation_deg : (lowest, highest)
        Vertical field of view in degrees; rows are equiangular, row 0 the
        highest.
    mount_height : float
        Height of the camera above the ground (m).
    rgb : bool
        (H, W, 3) uint8 images if True, else (H, W) gray.
    """

    kind = "panorama"

    def __init__(self, width: int = 600, height: int = 60, elevation_deg: Sequence[float] = (-30.0, 20.0),
                 mount_height: float = 0.5, rgb: bool = True):
        self.width = _check_size(width, "width", 8)
        self.height = _check_size(height, "height", 1)
        self.elevation_deg = _check_elevation(elevation_deg)
        if not mount_height > 0:
            raise ValueError(f"mount_height must be positive (m), got {mount_height}")
        self.mount_height = float(mount_height)
        self.rgb = bool(rgb)
        lo, hi = np.radians(self.elevation_deg)
        step = (hi - lo) / self.height
        self.elevations = hi - (np.arange(self.height) + 0.5) * step
        self.bearings = bearings(self.width)
        self._grid = _Grid(self.bearings, self.elevations, self.mount_height)

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.height, self.width, 3) if self.rgb else (self.height, self.width)

    def column_of_bearing(self, bearing: Any) -> np.ndarray:
        """Fractional column of a bearing (rad, relative to the heading)."""
        return column_of_bearing(bearing, self.width)

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": self.kind,
            "width": self.width,
            "height": self.height,
            "elevation_deg": list(self.elevation_deg),
            "mount_height": self.mount_height,
            "rgb": self.rgb,
        }


def bearings(width: int) -> np.ndarray:
    """Bearing (rad, counter-clockwise from the heading) of each panorama column."""
    return -2 * np.pi * (np.arange(width) + 0.5 - width / 2) / width


def column_of_bearing(bearing: Any, width: int) -> np.ndarray:
    """Fractional panorama column of a bearing (inverse of :func:`bearings`), in [-0.5, width - 0.5)."""
    b = np.asarray(bearing, float)
    return (width / 2 - 0.5 - np.angle(np.exp(1j * b)) * width / (2 * np.pi) + 0.5) % width - 0.5


MIRRORS = ("spherical", "equiangular")


class OmniCamera:
    """A catadioptric camera: a camera looking up into a curved mirror.

    The image is a donut of outer radius ``size / 2 - 1`` pixels: the
    mirror's rim sees elevation ``elevation_deg[1]``, its inner edge sees
    ``elevation_deg[0]``; inside is the blind disc where the mirror shows the
    camera itself (black), outside the donut the image is black. The robot's
    heading points up in the image and its left is left.

    Mirror models (``rho`` = radius / outer radius):

    * ``"spherical"``: a spherical mirror seen from far below; a ray hitting
      it at incidence ``a`` leaves at elevation ``2 a - 90 deg``, and
      ``rho = sin(a) / sin(a_max)`` with ``a_max`` set by the rim elevation.
      Elevation resolution is densest near the rim (the horizon), as in real
      mirrors.
    * ``"equiangular"``: elevation linear in radius.

    Parameters
    ----------
    size : int
        Image width and height (pixels).
    elevation_deg : (lowest, highest)
        Elevations (degrees) at the inner and outer edge of the donut.
    mirror : str
        ``"spherical"`` or ``"equiangular"``.
    mount_height : float
        Height of the mirror's viewpoint above the ground (m).
    rgb : bool
        (size, size, 3) uint8 if True, else (size, size) gray.
    """

    kind = "omni"

    def __init__(self, size: int = 500, elevation_deg: Sequence[float] = (-55.0, 20.0), mirror: str = "spherical",
                 mount_height: float = 0.5, rgb: bool = True, inner_fraction: float = 0.25):
        self.size = _check_size(size, "size", 16)
        self.elevation_deg = _check_elevation(elevation_deg)
        if mirror not in MIRRORS:
            raise ValueError(f"unknown mirror {mirror!r}; available: {', '.join(MIRRORS)}")
        self.mirror = mirror
        if not mount_height > 0:
            raise ValueError(f"mount_height must be positive (m), got {mount_height}")
        self.mount_height = float(mount_height)
        self.rgb = bool(rgb)
        if not 0 <= inner_fraction < 1:
            raise ValueError(f"inner_fraction must be in [0, 1), got {inner_fraction}")
        self.outer_radius = self.size / 2 - 1.0
        lo, hi = np.radians(self.elevation_deg)
        if mirror == "spherical":
            self._a_max = (hi + np.pi / 2) / 2
            rho_in = np.sin((lo + np.pi / 2) / 2) / np.sin(self._a_max)
        else:
            rho_in = float(inner_fraction)
        self.inner_radius = float(rho_in * self.outer_radius)
        # polar ray grid: one row per pixel of radius (outer first), one column per pixel of circumference
        n_rad = int(np.ceil(self.outer_radius - self.inner_radius)) + 2
        radii = self.outer_radius + 0.5 - np.arange(n_rad)  # descending; first row just outside the rim
        radii = np.clip(radii, self.inner_radius, self.outer_radius)
        self._radii = self.outer_radius + 0.5 - np.arange(n_rad)
        n_az = int(np.ceil(2 * np.pi * self.outer_radius / 8) * 8)
        el = self.elevation_of_radius(radii)
        el = el - np.arange(n_rad) * 1e-9  # strictly decreasing after clipping
        self._grid = _Grid(bearings(n_az), el, self.mount_height)
        self._maps = self._donut_maps()

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.size, self.size, 3) if self.rgb else (self.size, self.size)

    def elevation_of_radius(self, r: Any) -> np.ndarray:
        """Elevation (rad) seen at image radius ``r`` (pixels from the centre)."""
        rho = np.asarray(r, float) / self.outer_radius
        lo, hi = np.radians(self.elevation_deg)
        if self.mirror == "spherical":
            return 2 * np.arcsin(np.clip(rho * np.sin(self._a_max), -1, 1)) - np.pi / 2
        rho_in = self.inner_radius / self.outer_radius
        return lo + (rho - rho_in) / (1 - rho_in) * (hi - lo)

    def radius_of_elevation(self, elevation: Any) -> np.ndarray:
        """Image radius (pixels) that sees ``elevation`` (rad); inverse of
        :meth:`elevation_of_radius`."""
        e = np.asarray(elevation, float)
        lo, hi = np.radians(self.elevation_deg)
        if self.mirror == "spherical":
            rho = np.sin((e + np.pi / 2) / 2) / np.sin(self._a_max)
        else:
            rho_in = self.inner_radius / self.outer_radius
            rho = rho_in + (e - lo) / (hi - lo) * (1 - rho_in)
        return rho * self.outer_radius

    def _donut_maps(self) -> tuple[np.ndarray, np.ndarray]:
        c = (self.size - 1) / 2
        yy, xx = np.mgrid[0 : self.size, 0 : self.size].astype(np.float64)
        dx, dy = xx - c, c - yy
        r = np.hypot(dx, dy)
        b = np.arctan2(-dx, dy)  # bearing: up = ahead, left = left
        W = self._grid.W
        col = column_of_bearing(b, W)
        col = np.where(col < 0, col + W, col)  # [0, W): the grid is padded by one wrapped column
        row = self.outer_radius + 0.5 - r
        outside = (r > self.outer_radius + 0.5) | (r < self.inner_radius)
        col[outside] = -10
        row[outside] = -10
        return col.astype(np.float32), row.astype(np.float32)

    def _finish(self, grid_img: np.ndarray) -> np.ndarray:
        import cv2

        padded = np.concatenate([grid_img, grid_img[:, :1]], axis=1)
        return cv2.remap(padded, self._maps[0], self._maps[1], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def unwarp(self, image: np.ndarray, width: int = 600, height: int = 55,
               elevation_deg: Sequence[float] | None = None) -> np.ndarray:
        """Unwarps an omni image of this camera into a panorama.

        Parameters
        ----------
        image : ndarray (size, size[, C])
        width, height : int
            Panorama size (thesis 6.2.1: 600 x 55).
        elevation_deg : (lowest, highest), optional
            Vertical field of the panorama in degrees; default the donut's.

        Returns
        -------
        ndarray (height, width[, C]), same dtype: the same column and row
        convention as :class:`PanoramicCamera`.
        """
        import cv2

        img = np.asarray(image)
        if img.shape[:2] != (self.size, self.size):
            raise ValueError(f"omni image must be {self.size} x {self.size}, got shape {img.shape}")
        pano = PanoramicCamera(_check_size(width, "width", 8), _check_size(height, "height", 1),
                               elevation_deg or self.elevation_deg, self.mount_height, rgb=True)
        r = self.radius_of_elevation(pano.elevations)[:, None]
        b = pano.bearings[None, :]
        c = (self.size - 1) / 2
        mx = (c - r * np.sin(b)).astype(np.float32)
        my = (c - r * np.cos(b)).astype(np.float32)
        return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": self.kind,
            "size": self.size,
            "elevation_deg": list(self.elevation_deg),
            "mirror": self.mirror,
            "mount_height": self.mount_height,
            "rgb": self.rgb,
            "inner_radius_px": self.inner_radius,
            "outer_radius_px": self.outer_radius,
        }


Camera = PanoramicCamera | OmniCamera


def camera_from_dict(d: dict[str, Any]) -> Camera:
    """Rebuilds a camera from :meth:`to_dict` output."""
    d = dict(d)
    kind = d.pop("type", None)
    d.pop("inner_radius_px", None)
    d.pop("outer_radius_px", None)
    if kind == "panorama":
        return PanoramicCamera(**d)
    if kind == "omni":
        return OmniCamera(**d)
    raise ValueError(f"unknown camera type {kind!r}; available: 'panorama', 'omni'")


# ------------------------------------------------------------------ renderer


class _Prims:
    """Static primitive parameters as arrays, for per-frame vector work."""

    def __init__(self, prims: list[Primitive], pyramids: dict[str, Pyramid]):
        self.list = prims
        n = len(prims)
        self.x = np.array([p.x for p in prims], float).reshape(n)
        self.y = np.array([p.y for p in prims], float).reshape(n)
        self.z0 = np.array([p.z0 for p in prims], float).reshape(n)
        self.z1 = np.array([p.z1 for p in prims], float).reshape(n)
        self.rb = np.array([p.bound_radius for p in prims], float).reshape(n)
        self.tex = [pyramids[p.texture] for p in prims]
        self.front = [pyramids[p.front] if p.front else None for p in prims]


class Renderer:
    """Renders a :class:`~sfanav.sim.world.World` for any camera.

    Building a renderer synthesises the textures and the ground and sky maps
    (about a second for a garden); each lighting condition's sun direction
    adds a shadow map (cached). Rendering is then pure NumPy.

    Parameters
    ----------
    world : World
    lighting : Lighting
        Default lighting of :meth:`render`.
    """

    def __init__(self, world: World, lighting: Lighting | None = None):
        if not isinstance(world, World):
            raise TypeError(f"Renderer needs a World, got {type(world).__name__}")
        self.world = world
        self.lighting = lighting or Lighting()
        self.pyramids = {name: Pyramid(make_texture(spec), spec.tile) for name, spec in world.textures.items()}
        self._static = _Prims(world.primitives(0.0)[: sum(len(o.parts) for o in world.objects)], self.pyramids)
        self._build_ground()
        self._build_sky()
        self._ground_cache: dict[tuple, np.ndarray] = {}
        self._grid_cache: dict[int, dict[str, Any]] = {}

    # ------------------------------------------------------------ ground

    def _build_ground(self) -> None:
        g = self.world.ground
        rng = np.random.default_rng(g.seed)
        det = photo(g.detail) if g.detail in ("grass", "gravel", "brick") else None
        if det is None:  # pragma: no cover - GroundSpec.detail is a photo name
            raise ValueError(f"ground detail must be a photographic texture, got {g.detail!r}")
        det = 1.0 + g.contrast * (det - 1.0)
        self._detail = Pyramid(det[..., None], (g.detail_tile, g.detail_tile))
        # flat concatenation of the detail pyramid for one gather per pixel
        self._det_flat = np.concatenate([lv[:, 0] for lv in self._detail.levels]).astype(np.float32)
        sizes = np.array([s[0] for s in self._detail.shapes])
        self._det_off = np.concatenate([[0], np.cumsum(sizes**2)[:-1]]).astype(np.int64)
        self._det_n = sizes.astype(np.int64)
        # colour map: power-of-two cells covering the world, periodic beyond
        extent = 2 * (self.world.outer_radius + 4.0)
        n = int(2 ** np.ceil(np.log2(extent / g.resolution)))
        self._gmap_n = n
        self._gmap_res = g.resolution
        self._gmap_origin = -n * g.resolution / 2
        big = fractal_noise((n, n), rng, beta=3.0, fmin=2.0)
        mid = fractal_noise((n, n), rng, beta=2.2, fmin=8.0)
        mix = np.clip(0.5 + 0.35 * big + 0.15 * mid, 0, 1)[..., None]
        col = mix * np.asarray(g.green, np.float32) + (1 - mix) * np.asarray(g.green2, np.float32)
        patches = fractal_noise((n, n), rng, beta=3.0, fmin=3.0)
        thr = np.quantile(patches, 1 - g.dry_fraction) if g.dry_fraction > 0 else np.inf
        dry = np.clip((patches - thr) / 0.3, 0, 1)[..., None]
        col = (1 - dry) * col + dry * np.asarray(g.dry, np.float32)
        self._gmap = col.astype(np.float32)  # (n, n, 3), row = y index, col = x index

    def _shadow_map(self, light: Lighting) -> np.ndarray:
        """Fraction of direct sun blocked, (n, n) in [0, 1], on the ground map grid."""
        import cv2

        n, res, o = self._gmap_n, self._gmap_res, self._gmap_origin
        shadow = np.zeros((n, n), np.float32)
        if not light.shadows:
            return shadow
        s = light.sun
        horiz = np.hypot(s[0], s[1])
        cot = horiz / s[2]
        sx, sy = (s[0] / horiz, s[1] / horiz) if horiz > 1e-9 else (1.0, 0.0)
        P = self._static
        for i, p in enumerate(P.list):
            top = max(P.z1[i], 0.0)
            reach = top * cot
            # bounding box of the shadow: footprint swept away from the sun
            xs = [p.x - P.rb[i], p.x + P.rb[i], p.x - P.rb[i] - sx * reach, p.x + P.rb[i] - sx * reach]
            ys = [p.y - P.rb[i], p.y + P.rb[i], p.y - P.rb[i] - sy * reach, p.y + P.rb[i] - sy * reach]
            i0, i1 = int((min(xs) - o) / res) - 1, int((max(xs) - o) / res) + 2
            j0, j1 = int((min(ys) - o) / res) - 1, int((max(ys) - o) / res) + 2
            i0, j0 = max(i0, 0), max(j0, 0)
            i1, j1 = min(i1, n), min(j1, n)
            if i1 <= i0 or j1 <= j0:
                continue
            gx = o + (np.arange(i0, i1) + 0.5) * res
            gy = o + (np.arange(j0, j1) + 0.5) * res
            X, Y = np.meshgrid(gx, gy)
            # ray from the ground point towards the sun, horizontal direction (sx, sy), rise tan(el)
            d = _hit_distance(p, X - p.x, Y - p.y, sx, sy, s[2] / horiz if horiz > 1e-9 else 1e9)
            shadow[j0:j1, i0:i1] = np.maximum(shadow[j0:j1, i0:i1], np.isfinite(d).astype(np.float32))
        k = max(3, int(0.25 / res) | 1)
        return cv2.GaussianBlur(shadow, (k, k), 0)

    def _lit_ground(self, light: Lighting) -> np.ndarray:
        key = (light.sun_azimuth_deg, light.sun_elevation_deg, light.ambient, light.shadows)
        lit = self._ground_cache.get(key)
        if lit is None:
            s = light.sun
            direct = (1 - light.ambient) * max(s[2], 0.0) / np.sin(np.radians(50.0))
            shade = light.ambient + direct * (1.0 - self._shadow_map(light))
            lit = (self._gmap * shade[..., None]).reshape(-1, 3).astype(np.float32)
            if len(self._ground_cache) > 32:
                self._ground_cache.clear()
            self._ground_cache[key] = lit
        return lit

    # ------------------------------------------------------------ sky

    def _build_sky(self) -> None:
        sk = self.world.sky
        rng = np.random.default_rng(sk.seed)
        n_az, n_el = 2048, 180  # 0.5 degree rows from the horizon to the zenith
        self._sky_n_az = n_az
        el = (np.arange(n_el) + 0.5) / n_el * (np.pi / 2)
        t = np.sqrt(np.sin(el))[:, None, None]
        base = (1 - t) * np.asarray(sk.horizon, np.float32) + t * np.asarray(sk.zenith, np.float32)
        base = np.broadcast_to(base, (n_el, n_az, 3)).astype(np.float32)
        clouds = fractal_noise((n_el * 2, n_az), rng, beta=2.6, fmin=2.0)[:n_el]
        thr = np.quantile(clouds, 1 - sk.cloud_cover) if sk.cloud_cover > 0 else np.inf
        cover = np.clip((clouds - thr) / 0.8, 0, 1)
        cover *= np.clip(el / np.radians(3.0), 0, 1)[:, None]  # thin out at the horizon
        shade = 0.8 + 0.2 * np.clip(fractal_noise((n_el * 2, n_az), rng, beta=2.0)[:n_el], -1, 1)
        cloud_col = (0.96 * shade)[..., None] * np.ones(3, np.float32)
        sky = base * (1 - cover[..., None]) + cloud_col * cover[..., None]
        # distant tree line / hills at infinity
        prof = fractal_noise((1, n_az), rng, beta=1.8, fmin=1.0)[0]
        lo, hi = np.radians(sk.treeline_deg)
        prof = lo + (hi - lo) * (prof - prof.min()) / max(prof.max() - prof.min(), 1e-9)
        tex = 1.0 + 0.25 * fractal_noise((n_el, n_az), rng, beta=1.2)
        tree = (np.asarray(sk.treeline, np.float32)[None, None, :] * tex[..., None]).astype(np.float32)
        below = el[:, None] < prof[None, :]
        sky = np.where(below[..., None], tree, sky)
        self._sky = sky.astype(np.float32)
        self._sky_el = el
        self._horizon_rgb = np.asarray(sk.horizon, np.float32)

    # ------------------------------------------------------------ per-grid data

    def _grid_data(self, grid: _Grid) -> dict[str, Any]:
        key = id(grid)
        gd = self._grid_cache.get(key)
        if gd is not None and gd["grid"] is grid:
            return gd
        gd = {"grid": grid}
        sky_rows = np.nonzero(grid.elev >= 0)[0]
        gnd_rows = np.nonzero(grid.elev < 0)[0]
        gd["sky_rows"] = slice(int(sky_rows[0]), int(sky_rows[-1]) + 1) if len(sky_rows) else slice(0, 0)
        gd["gnd_rows"] = slice(int(gnd_rows[0]), int(gnd_rows[-1]) + 1) if len(gnd_rows) else slice(0, 0)
        if len(sky_rows):
            k = np.clip(np.searchsorted(self._sky_el, grid.elev[sky_rows]), 0, len(self._sky_el) - 1)
            gd["sky_panel"] = np.ascontiguousarray(self._sky[k])  # (Hs, n_az, 3)
        if len(gnd_rows):
            t = grid.tan[gnd_rows]
            d = grid.h / -t  # horizontal distance of the ground hit, per row
            # texel footprint: the larger of the radial and tangential pixel extents
            de = np.abs(np.gradient(grid.elev))[gnd_rows] if grid.H > 1 else np.full(len(gnd_rows), 0.01)
            foot = np.maximum(d * d / grid.h * de, d * grid.pixel_angle)
            lev = np.clip(np.log2(np.maximum(foot / self._detail.texel, 1.0)).astype(int), 0,
                          len(self._det_n) - 1)
            n_l = self._det_n[lev]
            gd["gnd_d"] = d
            gd["gnd_d_col"] = d[:, None].astype(np.float64)
            gd["det_inv"] = (n_l / self._detail.tile[0])[:, None].astype(np.float64)
            gd["det_mask"] = (n_l - 1)[:, None]
            gd["det_n"] = n_l[:, None]
            gd["det_off"] = self._det_off[lev][:, None]
            fog = 1.0 - np.exp(-d / FOG_DISTANCE)
            gd["gnd_fog"] = fog[:, None, None].astype(np.float32)
            gd["depth_init"] = np.concatenate(
                [np.full(len(sky_rows), np.inf), d]
            )[:, None] * np.ones((1, grid.W))
        else:
            gd["depth_init"] = np.full((grid.H, grid.W), np.inf)
        gd["neg_elev"] = -grid.elev
        if len(self._grid_cache) > 16:
            self._grid_cache.clear()
        self._grid_cache[key] = gd
        return gd

    # ------------------------------------------------------------ rendering

    def render(self, camera: Camera, pose: Sequence[float], time: float = 0.0,
               lighting: Lighting | None = None) -> np.ndarray:
        """Renders one image.

        Parameters
        ----------
        camera : PanoramicCamera or OmniCamera
        pose : (x, y, heading)
            Camera position (m) and heading (rad).
        time : float
            Seconds, for the dynamic objects.
        lighting : Lighting, optional
            Default: the renderer's.

        Returns
        -------
        ndarray uint8, ``camera.shape``.
        """
        if not isinstance(camera, (PanoramicCamera, OmniCamera)):
            raise TypeError(f"camera must be a PanoramicCamera or OmniCamera, got {type(camera).__name__}")
        x, y, heading = _pose3(pose)
        light = lighting or self.lighting
        img = self.render_grid(camera._grid, x, y, heading, time, light)
        if isinstance(camera, OmniCamera):
            img = camera._finish(img)
        return _to_uint8(img, camera.rgb)

    def render_grid(self, grid: _Grid, x: float, y: float, heading: float, time: float,
                    light: Lighting) -> np.ndarray:
        """Linear RGB float32 image (H, W, 3) of a ray grid (internal; see :meth:`render`)."""
        gd = self._grid_data(grid)
        H, W, h = grid.H, grid.W, grid.h
        phi = heading + grid.bearings
        ux, uy = np.cos(phi), np.sin(phi)
        out = np.empty((H, W, 3), np.float32)
        depth = gd["depth_init"].copy()
        # sky
        sr = gd["sky_rows"]
        if sr.stop > sr.start:
            k = (np.mod(phi, 2 * np.pi) * (self._sky_n_az / (2 * np.pi))).astype(np.int64) % self._sky_n_az
            out[sr] = gd["sky_panel"][:, k]
        # ground
        gr = gd["gnd_rows"]
        if gr.stop > gr.start:
            d = gd["gnd_d_col"]
            X = x + d * ux
            Y = y + d * uy
            inv = gd["det_inv"]
            iu = np.floor(X * inv).astype(np.int64) & gd["det_mask"]
            iv = np.floor(Y * inv).astype(np.int64) & gd["det_mask"]
            det = self._det_flat[gd["det_off"] + iv * gd["det_n"] + iu]
            n, res, o = self._gmap_n, self._gmap_res, self._gmap_origin
            gi = (np.floor((X - o) / res).astype(np.int64) & (n - 1)) + (
                np.floor((Y - o) / res).astype(np.int64) & (n - 1)) * n
            col = self._lit_ground(light)[gi] * det[..., None]
            fog = gd["gnd_fog"]
            out[gr] = col + fog * (self._horizon_rgb - col)
        # objects
        prims = self._static
        lists = [prims]
        if self.world.dynamic:
            dyn = [dd.primitive_at(time) for dd in self.world.dynamic]
            lists.append(_Prims(dyn, self.pyramids))
        for P in lists:
            self._draw(P, gd, grid, x, y, heading, ux, uy, out, depth, light)
        out *= light.rgb
        return out

    def _draw(self, P: _Prims, gd: dict[str, Any], grid: _Grid, cx: float, cy: float, heading: float,
              ux: np.ndarray, uy: np.ndarray, out: np.ndarray, depth: np.ndarray, light: Lighting) -> None:
        W, h = grid.W, grid.h
        qx, qy = P.x - cx, P.y - cy
        rho = np.hypot(qx, qy)
        ang = np.arctan2(qy, qx)
        half = np.arcsin(np.clip(P.rb / np.maximum(rho, 1e-9), 0, 1))
        inside = rho <= P.rb
        jc = column_of_bearing(ang - heading, W) if W else ang
        hw = half * (W / (2 * np.pi))
        near = np.maximum(rho - P.rb, 0.05)
        far = rho + P.rb
        z0r, z1r = P.z0 - h, P.z1 - h
        e_hi = np.arctan2(z1r, np.where(z1r > 0, near, far))
        e_lo = np.arctan2(z0r, np.where(z0r < 0, near, far))
        i_lo = np.searchsorted(gd["neg_elev"], -e_hi, "left")
        i_hi = np.searchsorted(gd["neg_elev"], -e_lo, "right")
        j_lo = np.floor(jc - hw).astype(int)
        j_hi = np.ceil(jc + hw).astype(int) + 1
        sun = light.sun
        amb, dif = light.ambient, (1 - light.ambient) / np.sin(np.radians(50.0))
        order = np.argsort(near)
        for i in order:
            r0, r1 = int(i_lo[i]), int(i_hi[i])
            if r1 <= r0:
                continue
            if inside[i] or j_hi[i] - j_lo[i] >= W:
                spans = [(0, W)]
            else:
                a, b = int(j_lo[i]), int(j_hi[i])
                if a < 0:
                    spans = [(a + W, W), (0, b)]
                elif b > W:
                    spans = [(a, W), (0, b - W)]
                else:
                    spans = [(a, b)]
            p = P.list[i]
            for c0, c1 in spans:
                if c1 <= c0:
                    continue
                dblk = depth[r0:r1, c0:c1]
                if near[i] > dblk.max():
                    continue  # hidden behind nearer surfaces everywhere in its block
                self._draw_block(p, P.tex[i], P.front[i], qx[i], qy[i], rho[i], cx, cy, h,
                                 ux[c0:c1], uy[c0:c1], grid.tan[r0:r1], dblk, out[r0:r1, c0:c1],
                                 grid.pixel_angle, sun, amb, dif)

    def _draw_block(self, p: Primitive, tex: Pyramid, front: Pyramid | None, qx: float, qy: float, rho: float,
                    cx: float, cy: float, h: float, ux: np.ndarray, uy: np.ndarray, t: np.ndarray,
                    dblk: np.ndarray, oblk: np.ndarray, pixel_angle: float, sun: np.ndarray,
                    amb: float, dif: float) -> None:
        tcol = t[:, None]
        z0r, z1r = p.z0 - h, p.z1 - h
        face = None
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if p.shape == "ellipsoid":
                r, rz = p.radius, 0.5 * (p.z1 - p.z0)
                zc = 0.5 * (p.z0 + p.z1) - h
                a = qx * ux + qy * uy
                A = 1.0 / (r * r) + tcol * tcol / (rz * rz)
                B = -2.0 * a / (r * r) - 2.0 * tcol * zc / (rz * rz)
                C = rho * rho / (r * r) - 1.0 + zc * zc / (rz * rz)
                disc = B * B - 4.0 * A * C
                d = (-B - np.sqrt(disc)) / (2.0 * A)
                d = np.where((disc >= 0) & (d > 0), d, np.inf)
            else:
                if p.shape == "cylinder":
                    a = qx * ux + qy * uy
                    disc = p.radius**2 - (rho * rho - a * a)
                    s = np.sqrt(disc)
                    din, dout = a - s, a + s
                    valid = disc > 0
                else:  # box: slabs in the box frame
                    c, sn = np.cos(p.yaw), np.sin(p.yaw)
                    ox, oy = -(c * qx + sn * qy), -(-sn * qx + c * qy)
                    vx, vy = c * ux + sn * uy, -sn * ux + c * uy
                    L2, W2 = p.length / 2, p.width / 2
                    tx1, tx2 = (-L2 - ox) / vx, (L2 - ox) / vx
                    ty1, ty2 = (-W2 - oy) / vy, (W2 - oy) / vy
                    txn, txf = np.minimum(tx1, tx2), np.maximum(tx1, tx2)
                    tyn, tyf = np.minimum(ty1, ty2), np.maximum(ty1, ty2)
                    din, dout = np.maximum(txn, tyn), np.minimum(txf, tyf)
                    valid = (din < dout) & (dout > 0)
                    face = np.where(txn > tyn, np.where(vx < 0, 0, 1), np.where(vy < 0, 2, 3))
                    # faces: 0 = +x, 1 = -x, 2 = +y, 3 = -y (the "front")
                din = np.maximum(din, 0.0)
                zin = din * tcol
                side = valid & (zin >= z0r) & (zin <= z1r)
                d = np.where(side, din, np.inf)
                cap = None
                if z1r < 0:  # top visible from above
                    dc = z1r / tcol
                    top = valid & (zin > z1r) & (tcol < 0) & (dc <= dout)
                    d = np.where(top, dc, d)
                    cap = top
                if z0r > 0:  # bottom visible from below
                    dc = z0r / tcol
                    bot = valid & (zin < z0r) & (tcol > 0) & (dc <= dout)
                    d = np.where(bot, dc, d)
                    cap = bot if cap is None else cap | bot
            win = d < dblk
            if not win.any():
                return
            ri, ci = np.nonzero(win)
            dw = d[ri, ci]
            hx = dw * ux[ci] - qx  # hit point relative to the primitive's centre
            hy = dw * uy[ci] - qy
            hz = dw * t[ri]  # relative to the camera height
            level = tex.level_for(rho * pixel_angle)
            alpha = None
            if p.shape == "ellipsoid":
                zc = 0.5 * (p.z0 + p.z1) - h
                rz = 0.5 * (p.z1 - p.z0)
                nx, ny, nz = hx / p.radius**2, hy / p.radius**2, (hz - zc) / rz**2
                u = np.arctan2(hy, hx) * p.radius
                rgba = tex.sample(u, hz + h, level)
            elif p.shape == "cylinder":
                nx, ny, nz = hx, hy, np.zeros_like(hx)
                u = np.arctan2(hy, hx) * p.radius
                rgba = tex.sample(u, hz + h, level)
                if cap is not None:
                    cw = cap[ri, ci]
                    if cw.any():
                        nx, ny = np.where(cw, 0.0, nx), np.where(cw, 0.0, ny)
                        nz = np.where(cw, np.sign(-t[ri]), nz)
                        rgba[cw] = tex.sample(hx[cw] + p.x, hy[cw] + p.y, level)
            else:
                c, sn = np.cos(p.yaw), np.sin(p.yaw)
                lx, ly = c * hx + sn * hy, -sn * hx + c * hy
                f = face[ci]
                nlx = np.where(f == 0, 1.0, np.where(f == 1, -1.0, 0.0))
                nly = np.where(f == 2, 1.0, np.where(f == 3, -1.0, 0.0))
                nx, ny = c * nlx - sn * nly, sn * nlx + c * nly
                nz = np.zeros_like(hx)
                u = np.where(f <= 1, ly, lx)
                rgba = tex.sample(u, hz + h, level)
                if front is not None:
                    fw = f == 3
                    if cap is not None:
                        fw &= ~cap[ri, ci]
                    if fw.any():
                        fu = (lx[fw] + p.length / 2) / p.length
                        fv = (hz[fw] + h - p.z0) / (p.z1 - p.z0)
                        rgba[fw] = front.sample(fu, fv, front.level_for(rho * pixel_angle), stretch=True)
                if cap is not None:
                    cw = cap[ri, ci]
                    if cw.any():
                        nx, ny = np.where(cw, 0.0, nx), np.where(cw, 0.0, ny)
                        nz = np.where(cw, np.sign(-t[ri]), nz)
                        rgba[cw] = tex.sample(hx[cw] + p.x, hy[cw] + p.y, level)
            if tex.has_alpha:
                keep = rgba[:, 3] > 0.5
                if not keep.all():
                    ri, ci, dw, rgba = ri[keep], ci[keep], dw[keep], rgba[keep]
                    nx, ny, nz = nx[keep], ny[keep], nz[keep]
            norm = np.sqrt(nx * nx + ny * ny + nz * nz)
            lam = np.maximum((nx * sun[0] + ny * sun[1] + nz * sun[2]) / np.maximum(norm, 1e-12), 0.0)
            shade = (amb + dif * lam).astype(np.float32)
            col = rgba[:, :3] * shade[:, None]
            fog = np.float32(1.0 - np.exp(-rho / FOG_DISTANCE))
            col = col + fog * (self._horizon_rgb - col)
            oblk[ri, ci] = col
            dblk[ri, ci] = dw


def _hit_distance(p: Primitive, ox: np.ndarray, oy: np.ndarray, dx: float, dy: float, rise: float) -> np.ndarray:
    """Horizontal distance at which rays from ground points (ox, oy relative
    to the primitive centre, z = 0) going in horizontal direction (dx, dy)
    with slope ``rise`` (dz per horizontal metre) first meet the primitive;
    inf where they miss. Used for shadow maps."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if p.shape == "ellipsoid":
            r, rz = p.radius, 0.5 * (p.z1 - p.z0)
            zc = 0.5 * (p.z0 + p.z1)
            # (ox + d dx)^2/r^2 + (oy + d dy)^2/r^2 + (d rise - zc)^2/rz^2 = 1
            A = 1.0 / r**2 + rise**2 / rz**2
            B = 2 * (ox * dx + oy * dy) / r**2 - 2 * rise * zc / rz**2
            C = (ox**2 + oy**2) / r**2 + zc**2 / rz**2 - 1
            disc = B * B - 4 * A * C
            d = (-B - np.sqrt(disc)) / (2 * A)
            d2 = (-B + np.sqrt(disc)) / (2 * A)
            return np.where((disc >= 0) & (d2 > 0), np.maximum(d, 0), np.inf)
        if p.shape == "cylinder":
            a = -(ox * dx + oy * dy)
            disc = p.radius**2 - (ox**2 + oy**2 - a * a)
            s = np.sqrt(disc)
            din, dout = a - s, a + s
            valid = (disc > 0) & (dout > 0)
        else:
            c, sn = np.cos(p.yaw), np.sin(p.yaw)
            lx, ly = c * ox + sn * oy, -sn * ox + c * oy
            vx, vy = c * dx + sn * dy, -sn * dx + c * dy
            L2, W2 = p.length / 2, p.width / 2
            tx1, tx2 = (-L2 - lx) / vx, (L2 - lx) / vx
            ty1, ty2 = (-W2 - ly) / vy, (W2 - ly) / vy
            din = np.maximum(np.minimum(tx1, tx2), np.minimum(ty1, ty2))
            dout = np.minimum(np.maximum(tx1, tx2), np.maximum(ty1, ty2))
            valid = (din < dout) & (dout > 0)
        din = np.maximum(din, 0)
        # heights of the ray over [din, dout]: [din*rise, dout*rise]; hit if it overlaps [z0, z1]
        hit = valid & (din * rise <= p.z1) & (dout * rise >= p.z0)
        return np.where(hit, din, np.inf)


def _pose3(pose: Sequence[float]) -> tuple[float, float, float]:
    try:
        x, y, th = (float(v) for v in pose)
    except (TypeError, ValueError):
        raise ValueError(f"pose must be (x, y, heading) in metres and radians, got {pose!r}") from None
    if not all(np.isfinite([x, y, th])):
        raise ValueError(f"pose must be finite, got {pose!r}")
    return x, y, th


def _to_uint8(img: np.ndarray, rgb: bool) -> np.ndarray:
    if not rgb:
        img = img @ _LUMA
    return np.clip(img * 255.0 + 0.5, 0, 255).astype(np.uint8)
