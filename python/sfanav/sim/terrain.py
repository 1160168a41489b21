"""Uneven ground: how a robot standing on bumpy terrain tilts and bobs.

* :class:`Attitude`: the camera's roll, pitch and height change for one
  frame; :meth:`sfanav.sim.Renderer.render` takes it and renders the view of
  the tilted camera (the world's horizon then runs off-centre through the
  image: in an omnidirectional image the horizon ring's centre moves).
* :class:`UnevenGround`: the recipe of a random ground-height field, smooth
  bumps (the wheels' scale) plus a gentle swell (metres); a scene preset
  carries one, and :meth:`UnevenGround.field` draws a :class:`HeightField`
  from a seed.
* :class:`HeightField`: the drawn field; :meth:`HeightField.attitudes`
  gives the robot's attitude along a trajectory from the heights under its
  four wheels.

Simplifications: the renderer still draws the ground flat (the terrain moves
the camera, it does not bend the ground in the image), and the camera turns
about its own viewpoint (a mast's sideways sway is left out).

Angles of attitudes are degrees (their names say ``_deg``), headings
radians, lengths metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_real_array, check_finite, check_nonneg_float, check_positive_float

MAX_TILT_DEG = 20.0
"""Largest roll or pitch (degrees) the renderer takes."""


def _finite_float(value: Any, name: str) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    v = float(value)
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    return v


@dataclass(frozen=True)
class Attitude:
    """The camera's attitude on uneven ground, for one frame.

    Attributes
    ----------
    roll_deg : float
        Rotation about the robot's forward axis, degrees, positive when its
        left side is higher than its right; at most :data:`MAX_TILT_DEG` in
        magnitude.
    pitch_deg : float
        Rotation about its left axis, degrees, positive when the nose is up;
        at most :data:`MAX_TILT_DEG` in magnitude.
    height_m : float
        Change of the camera's height above the (flat-drawn) ground, metres;
        the camera must stay above it.

    Examples
    --------
    >>> Attitude(roll_deg=2.0, pitch_deg=-1.0).level
    False
    >>> Attitude().rotation().tolist() == np.eye(3).tolist()
    True
    """

    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    height_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("roll_deg", "pitch_deg", "height_m"):
            object.__setattr__(self, name, _finite_float(getattr(self, name), name))
        for name in ("roll_deg", "pitch_deg"):
            if abs(getattr(self, name)) > MAX_TILT_DEG:
                raise ValueError(f"{name} must be within +-{MAX_TILT_DEG:g} degrees, got {getattr(self, name)}")

    @property
    def level(self) -> bool:
        """Whether the camera is not tilted (it may still be higher or lower)."""
        return self.roll_deg == 0.0 and self.pitch_deg == 0.0

    @property
    def identity(self) -> bool:
        """Whether this attitude changes nothing."""
        return self.level and self.height_m == 0.0

    @property
    def tilt_deg(self) -> float:
        """Angle (degrees) between the camera's up axis and the vertical."""
        r, p = np.radians(self.roll_deg), np.radians(self.pitch_deg)
        return float(np.degrees(np.arccos(np.clip(np.cos(r) * np.cos(p), -1.0, 1.0))))

    def rotation(self) -> np.ndarray:
        """(3, 3) matrix taking a direction in the camera's frame (forward,
        left, up) to the level frame of the same heading (x ahead, y left, z
        up): the roll about the forward axis, then the pitch about the left
        axis."""
        r, p = np.radians(self.roll_deg), np.radians(self.pitch_deg)
        cr, sr, cp, sp = np.cos(r), np.sin(r), np.cos(p), np.sin(p)
        roll = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
        pitch = np.array([[cp, 0.0, -sp], [0.0, 1.0, 0.0], [sp, 0.0, cp]])
        return pitch @ roll

    def to_dict(self) -> dict[str, float]:
        return {"roll_deg": self.roll_deg, "pitch_deg": self.pitch_deg, "height_m": self.height_m}


@dataclass(frozen=True)
class UnevenGround:
    """The recipe of a random uneven ground and of the robot that drives on it.

    The height field is the sum of two smooth Gaussian random fields: bumps
    (standard deviation ``roughness_m``, correlation length
    ``bump_length_m``) and a swell (``swell_m``, ``swell_length_m``). The
    robot stands on four wheels ``wheelbase_m`` apart front to back and
    ``track_m`` apart side to side; its pitch and roll follow the heights
    under them, the camera's height change their mean.

    Attributes
    ----------
    roughness_m, bump_length_m : float
        Bumps: height standard deviation and correlation length (m).
    swell_m, swell_length_m : float
        Swell: height standard deviation and correlation length (m).
    wheelbase_m, track_m : float
        Wheel distances (m); the defaults are those of a Pioneer 3-AT.

    Examples
    --------
    >>> field = UnevenGround().field(seed=0)
    >>> att = field.attitudes([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])
    >>> len(att), type(att[0]).__name__
    (2, 'Attitude')
    """

    roughness_m: float = 0.01
    bump_length_m: float = 0.15
    swell_m: float = 0.02
    swell_length_m: float = 1.5
    wheelbase_m: float = 0.27
    track_m: float = 0.4

    def __post_init__(self) -> None:
        for name in ("roughness_m", "swell_m"):
            object.__setattr__(self, name, check_nonneg_float(getattr(self, name), name))
        for name in ("bump_length_m", "swell_length_m", "wheelbase_m", "track_m"):
            object.__setattr__(self, name, check_positive_float(getattr(self, name), name))

    def field(self, seed: int | np.random.Generator = 0, extent: float = 20.0) -> "HeightField":
        """A random :class:`HeightField` of this recipe.

        Parameters
        ----------
        seed : int or numpy Generator
            Same seed, same field.
        extent : float
            Period of the field (m) in x and y; it repeats beyond (make it
            larger than the area the robot drives in).
        """
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        extent = check_positive_float(extent, "extent")
        res = min(self.bump_length_m, self.swell_length_m) / 3.0
        n = int(2 ** np.ceil(np.log2(max(extent / res, 8.0))))
        res = extent / n
        k = 2 * np.pi * np.fft.fftfreq(n, d=res)
        k2 = k[:, None] ** 2 + k[None, :] ** 2
        z = np.zeros((n, n))
        for std, length in ((self.roughness_m, self.bump_length_m), (self.swell_m, self.swell_length_m)):
            noise = rng.standard_normal((n, n))
            if std == 0:
                continue
            part = np.real(np.fft.ifft2(np.fft.fft2(noise) * np.exp(-0.5 * k2 * length**2)))
            z += std * (part - part.mean()) / max(float(part.std()), 1e-12)
        return HeightField(z, res, self)

    def to_dict(self) -> dict[str, float]:
        return {"roughness_m": self.roughness_m, "bump_length_m": self.bump_length_m, "swell_m": self.swell_m,
                "swell_length_m": self.swell_length_m, "wheelbase_m": self.wheelbase_m, "track_m": self.track_m}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "UnevenGround":
        if not isinstance(d, dict):
            raise TypeError(f"an uneven-ground record must be a dict, got {type(d).__name__}")
        unknown = set(d) - set(cls().to_dict())
        if unknown:
            raise ValueError(f"unknown uneven-ground fields {sorted(unknown)}")
        return cls(**d)


class HeightField:
    """A periodic ground-height grid (m) with bilinear interpolation, and the
    robot attitudes it causes (:meth:`attitudes`).

    Parameters
    ----------
    heights : ndarray (n, n)
        Heights in metres; row = y index, column = x index, cell ``(i, j)``
        at ``(j * resolution, i * resolution)``, periodic.
    resolution : float
        Cell size (m).
    ground : UnevenGround
        The recipe (wheel geometry).
    """

    def __init__(self, heights: np.ndarray, resolution: float, ground: UnevenGround):
        z = as_real_array(heights, "heights").astype(np.float64)
        if z.ndim != 2 or z.shape[0] != z.shape[1] or z.shape[0] < 2:
            raise ValueError(f"heights must be a square (n, n) grid with n >= 2, got shape {z.shape}")
        check_finite(z, "heights")
        self.heights = z
        self.resolution = check_positive_float(resolution, "resolution")
        self.ground = ground

    def height(self, x: Any, y: Any) -> np.ndarray:
        """Ground height (m) at points ``x``, ``y`` (m; any matching shapes)."""
        n = self.heights.shape[0]
        fx = np.asarray(x, float) / self.resolution
        fy = np.asarray(y, float) / self.resolution
        x0, y0 = np.floor(fx), np.floor(fy)
        tx, ty = fx - x0, fy - y0
        i0, j0 = y0.astype(np.int64) % n, x0.astype(np.int64) % n
        i1, j1 = (i0 + 1) % n, (j0 + 1) % n
        z = self.heights
        return ((z[i0, j0] * (1 - tx) + z[i0, j1] * tx) * (1 - ty)
                + (z[i1, j0] * (1 - tx) + z[i1, j1] * tx) * ty)

    def attitude_array(self, poses: Any) -> np.ndarray:
        """(N, 3) roll (deg), pitch (deg) and height change (m) of a robot at
        ``poses`` (N, 3) ``(x, y, heading)``: pitch from the mean heights of
        the front and the rear wheel pairs over the wheelbase, roll from the
        left and the right pairs over the track, height the mean of the
        four; tilts are clipped to :data:`MAX_TILT_DEG`."""
        P = as_real_array(poses, "poses").astype(np.float64)
        if P.ndim != 2 or P.shape[1] != 3:
            raise ValueError(f"poses must have shape (N, 3) (x, y, heading), got {P.shape}")
        check_finite(P, "poses")
        c, s = np.cos(P[:, 2]), np.sin(P[:, 2])
        a, b = self.ground.wheelbase_m / 2, self.ground.track_m / 2
        z = {}
        for f, l_ in ((a, b), (a, -b), (-a, b), (-a, -b)):
            z[(f > 0, l_ > 0)] = self.height(P[:, 0] + c * f - s * l_, P[:, 1] + s * f + c * l_)
        front = (z[(True, True)] + z[(True, False)]) / 2
        rear = (z[(False, True)] + z[(False, False)]) / 2
        left = (z[(True, True)] + z[(False, True)]) / 2
        right = (z[(True, False)] + z[(False, False)]) / 2
        pitch = np.degrees(np.arctan2(front - rear, self.ground.wheelbase_m))
        roll = np.degrees(np.arctan2(left - right, self.ground.track_m))
        lim = MAX_TILT_DEG
        return np.stack([np.clip(roll, -lim, lim), np.clip(pitch, -lim, lim), (front + rear) / 2], axis=1)

    def attitudes(self, poses: Any) -> list[Attitude]:
        """One :class:`Attitude` per pose (see :meth:`attitude_array`)."""
        return [Attitude(float(r), float(p), float(h)) for r, p, h in self.attitude_array(poses)]
