"""Recording conditions of the garden simulator: the light.

A :class:`Lighting` is one condition under which the renderer
(:mod:`sfanav.sim.render`) draws the garden: how bright, what colour, where
the sun stands, how much sky light fills the shade, whether objects cast
shadows. Presets (:mod:`sfanav.sim.presets`) map condition names to
Lightings, and datasets store them in their metadata (:meth:`Lighting.to_dict`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


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
