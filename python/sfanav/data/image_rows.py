"""Image rows and the near field.

A panorama's rows look at different distances: rows above the horizon see
far objects and the sky, rows below it the ground, the lowest ones the
ground right in front of the robot (at -30 degrees and 0.5 m camera height:
0.9 m away). Near-field content (ground patches, the bottom of nearby
objects) changes fast as the robot moves and dominates the slowest features
with blobs and rings instead of smooth functions of position.

* :func:`horizon_band`: keep only the rows of an elevation band (by
  default -10 .. +20 degrees, dropping the near ground) and resample them to
  the original height, so the same network (and its cost) applies.
* :func:`row_normalize`: each row of each image shifted and scaled to zero
  mean and unit variance (over its columns and channels), removing each
  row's overall brightness and contrast (e.g. the ground colour under the
  robot, global light) while keeping the structure along the row, which
  carries the bearings.
* :class:`ImageRows`: both as one serialisable step.

Elevations are those of ``sim.PanoramicCamera`` (equiangular rows, row 0
highest); for a real camera pass its elevation range.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .._checks import as_image_batch


def band_rows(height: int, camera_elevation: Sequence[float] = (-30.0, 20.0),
              band: Sequence[float] = (-10.0, 20.0)) -> tuple[int, int]:
    """The rows ``[r0, r1)`` of a ``height``-row equiangular panorama spanning
    ``camera_elevation`` (degrees, low, high) whose centres lie in ``band``."""
    lo, hi = (float(v) for v in camera_elevation)
    b0, b1 = (float(v) for v in band)
    if not (hi > lo and b1 > b0):
        raise ValueError(f"elevation ranges must be (low, high), got {camera_elevation!r} and {band!r}")
    centres = hi - (np.arange(height) + 0.5) * (hi - lo) / height  # row 0 highest
    inside = np.nonzero((centres >= b0) & (centres <= b1))[0]
    if len(inside) < 2:
        raise ValueError(f"the band {band!r} holds fewer than 2 of the {height} rows")
    return int(inside[0]), int(inside[-1]) + 1


def horizon_band(images: Any, *, camera_elevation: Sequence[float] = (-30.0, 20.0),
                 band: Sequence[float] = (-10.0, 20.0), height: int | None = None) -> np.ndarray:
    """Crops images (N, H, W[, C]) to the rows of an elevation ``band`` and
    resamples them (linear interpolation along the rows) to ``height`` rows
    (default: H, so a network built for the full panorama takes them).
    Returns float32."""
    a = as_image_batch(images)
    H = a.shape[1]
    r0, r1 = band_rows(H, camera_elevation, band)
    out_h = int(height or H)
    crop = a[:, r0:r1].astype(np.float32)
    n = r1 - r0
    # sample the cropped rows at out_h equally spaced positions (pixel centres)
    pos = (np.arange(out_h) + 0.5) * n / out_h - 0.5
    pos = np.clip(pos, 0, n - 1)
    i0 = np.floor(pos).astype(int)
    i1 = np.minimum(i0 + 1, n - 1)
    t = (pos - i0).astype(np.float32)
    shape = (1, out_h) + (1,) * (a.ndim - 2)
    t = t.reshape(shape)
    return np.ascontiguousarray(crop[:, i0] * (1 - t) + crop[:, i1] * t, dtype=np.float32)


def row_normalize(images: Any, eps: float = 1e-3) -> np.ndarray:
    """Each row of each image (N, H, W[, C]) to zero mean and unit variance
    over its columns and channels (float32). Flat rows (std below ``eps``
    times the image's range, or 0) are only centred."""
    a = as_image_batch(images).astype(np.float32, copy=False)
    axes = (2,) if a.ndim == 3 else (2, 3)
    mean = a.mean(axis=axes, keepdims=True, dtype=np.float64)
    std = a.std(axis=axes, keepdims=True, dtype=np.float64)
    scale = float(np.ptp(a)) if a.size else 1.0
    std = np.where(std > eps * max(scale, 1e-12), std, 1.0)
    return ((a - mean) / std).astype(np.float32)


@dataclass(frozen=True)
class ImageRows:
    """Row handling before the network: ``band`` (elevation degrees, or None
    for all rows) then ``normalize`` (per-row normalisation).
    ``camera_elevation`` is the panorama's elevation range."""

    band: tuple[float, float] | None = None
    normalize: bool = False
    camera_elevation: tuple[float, float] = (-30.0, 20.0)

    def __call__(self, images: Any) -> np.ndarray:
        a = np.asarray(images)
        if self.band is not None:
            a = horizon_band(a, camera_elevation=self.camera_elevation, band=self.band)
        if self.normalize:
            a = row_normalize(a)
        return a

    @property
    def identity(self) -> bool:
        return self.band is None and not self.normalize

    def describe(self) -> str:
        parts = []
        if self.band is not None:
            parts.append(f"horizon band {self.band[0]:g}..{self.band[1]:g} deg")
        if self.normalize:
            parts.append("per-row normalization")
        return ", ".join(parts) or "all rows"

    def to_dict(self) -> dict[str, Any]:
        return {"band": list(self.band) if self.band is not None else None, "normalize": self.normalize,
                "camera_elevation": list(self.camera_elevation)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "ImageRows":
        b = d.get("band")
        return cls(tuple(b) if b is not None else None, bool(d.get("normalize", False)),  # type: ignore[arg-type]
                   tuple(d.get("camera_elevation", (-30.0, 20.0))))  # type: ignore[arg-type]
