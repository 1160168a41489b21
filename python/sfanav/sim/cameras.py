"""The simulator's cameras: what rays they cast and how a rendered ray grid
becomes their image.

* :class:`PanoramicCamera`: a 360 degree cylindrical panorama (equiangular
  rows); its image *is* its ray grid.
* :class:`OmniCamera`: a camera looking into a curved mirror; renders its
  grid on the mirror's polar samples and resamples it into the donut image
  (:meth:`OmniCamera.finish`); :meth:`OmniCamera.unwarp` makes a panorama of
  such an image.
* :class:`RayGrid`, :func:`bearings`, :func:`column_of_bearing`,
  :func:`camera_from_dict`.

The ray casting itself is :class:`sfanav.sim.render.Renderer`.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np


class RayGrid:
    """A separable ray grid: bearings (W,) relative to the heading (rad,
    counter-clockwise), elevations (H,) strictly decreasing (rad), from a
    camera ``mount_height`` metres above the ground. The renderer casts one
    ray per grid cell; a camera's ``grid`` is what it asks for."""

    def __init__(self, bearings: np.ndarray, elevations: np.ndarray, mount_height: float):
        self.bearings = np.asarray(bearings, np.float64)
        self.elev = np.asarray(elevations, np.float64)
        if np.any(np.diff(self.elev) >= 0):
            raise ValueError("ray grid elevations must decrease from the top row down")
        self.h = float(mount_height)
        self.tan = np.tan(self.elev)
        self.W, self.H = len(self.bearings), len(self.elev)
        self.pixel_angle = 2 * np.pi / self.W


class LevelGrid:
    """The level ray grid a tilted camera's view is resampled from.

    A camera tilted on uneven ground casts its grid's rays in tilted
    directions. Every ray still leaves the same viewpoint, so the tilted
    view is a resampling of a level one: this grid has the camera grid's
    bearings and equiangular rows at the camera grid's finest elevation step
    (leaving out steps under a quarter of the median, such as an omni
    grid's clipped edge rows),
    ``margin_deg`` beyond its elevation range on both sides (within +-89
    degrees). :meth:`maps` gives, for an attitude, where each cell of the
    camera grid looks in this grid.

    Parameters
    ----------
    grid : RayGrid
        The camera's ray grid.
    margin_deg : float
        Extra elevation (degrees) above and below; at least the largest tilt
        to render.
    """

    def __init__(self, grid: RayGrid, margin_deg: float):
        self.camera_grid = grid
        self.margin_deg = float(margin_deg)
        steps = np.abs(np.diff(grid.elev))
        steps = steps[steps > 0.25 * np.median(steps)] if len(steps) else steps  # not the clipped edge rows
        step = float(steps.min()) if len(steps) else np.radians(0.5)
        m = np.radians(self.margin_deg)
        top = min(float(grid.elev[0]) + m, np.radians(89.0))
        bottom = max(float(grid.elev[-1]) - m, np.radians(-89.0))
        n = max(2, int(np.ceil((top - bottom) / step)))
        self.top, self.step = top, (top - bottom) / n
        self.grid = RayGrid(grid.bearings, top - (np.arange(n) + 0.5) * self.step, grid.h)
        b, e = np.meshgrid(grid.bearings, grid.elev)
        self._rays = np.stack([np.cos(e) * np.cos(b), np.cos(e) * np.sin(b), np.sin(e)], axis=-1)

    def maps(self, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(map_x, map_y)`` float32 (H, W) of the camera grid: the column
        and row of this grid (padded by one wrapped column, as
        :meth:`resample` pads it) that each camera ray looks at when the
        camera is turned by ``rotation`` (3, 3), camera frame to level frame
        (:meth:`sfanav.sim.terrain.Attitude.rotation`)."""
        d = self._rays @ np.asarray(rotation, float).T
        b = np.arctan2(d[..., 1], d[..., 0])
        e = np.arcsin(np.clip(d[..., 2], -1.0, 1.0))
        W = self.grid.W
        col = column_of_bearing(b, W)
        col = np.where(col < 0, col + W, col)
        row = (self.top - e) / self.step - 0.5
        return col.astype(np.float32), row.astype(np.float32)

    def resample(self, level_img: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """The camera grid's image (H, W, C) float32 from this grid's
        rendered image (rows beyond the margin repeat the edge rows)."""
        import cv2

        mx, my = self.maps(rotation)
        padded = np.concatenate([level_img, level_img[:, :1]], axis=1)
        return cv2.remap(padded, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


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
        self.grid = RayGrid(self.bearings, self.elevations, self.mount_height)

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
        n_az = int(np.ceil(2 * np.pi * self.outer_radius / 8) * 8)
        el = self.elevation_of_radius(radii)
        el = el - np.arange(n_rad) * 1e-9  # strictly decreasing after clipping
        self.grid = RayGrid(bearings(n_az), el, self.mount_height)
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
        W = self.grid.W
        col = column_of_bearing(b, W)
        col = np.where(col < 0, col + W, col)  # [0, W): the grid is padded by one wrapped column
        row = self.outer_radius + 0.5 - r
        outside = (r > self.outer_radius + 0.5) | (r < self.inner_radius)
        col[outside] = -10
        row[outside] = -10
        return col.astype(np.float32), row.astype(np.float32)

    def finish(self, grid_img: np.ndarray) -> np.ndarray:
        """The donut image from a rendered ray grid (resampled through the mirror)."""
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
