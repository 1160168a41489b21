"""The ground of the garden simulator: the lawn's colour map and the
objects' shadows on it.

The lawn is a colour map of square cells (``GroundSpec.resolution`` metres)
centred on the origin and large enough for the whole world, periodic beyond:
two greens mixed by fractal noise, drier patches, and the ground patches
(patio, gravel path, flower beds) painted over it. :func:`lawn_map` builds
it together with the share of lawn in every cell (a season recolours the
lawn, not the patches). :func:`shadow_map` gives the fraction of direct sun
the objects block on the same grid. The renderer (:mod:`sfanav.sim.render`)
multiplies the map by a photographic grass detail and the light.

Map convention: ``map[j, i]`` is the cell whose centre is at
``x = origin + (i + 0.5) * resolution``, ``y = origin + (j + 0.5) *
resolution`` (metres).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .textures import fractal_noise
from .primitives import Primitive
from .world import GroundSpec


@dataclass
class LawnMap:
    """The ground's colour map before light and texture.

    Attributes
    ----------
    colour : ndarray (n, n, 3) float32
        RGB in [0, 1]; row = y index, column = x index; n a power of two.
    lawn : ndarray (n, n) float32
        Share of each cell that is lawn (1) rather than a painted patch (0).
    resolution : float
        Cell size (m).
    origin : float
        Coordinate of the map's first cell edge on both axes (m).
    """

    colour: np.ndarray
    lawn: np.ndarray
    resolution: float
    origin: float

    @property
    def n(self) -> int:
        return int(self.colour.shape[0])


def lawn_map(ground: GroundSpec, outer_radius: float) -> LawnMap:
    """The lawn's colour map of a world's ``ground``, covering a square of
    side ``2 * (outer_radius + 4)`` metres or more (deterministic from
    ``ground.seed``).

    >>> m = lawn_map(GroundSpec(seed=1), 10.0)          # doctest: +SKIP
    >>> m.colour.shape, m.resolution                     # doctest: +SKIP
    ((512, 512, 3), 0.1)
    """
    g = ground
    rng = np.random.default_rng(g.seed)
    extent = 2 * (outer_radius + 4.0)
    n = int(2 ** np.ceil(np.log2(extent / g.resolution)))
    origin = -n * g.resolution / 2
    big = fractal_noise((n, n), rng, beta=3.0, fmin=2.0)
    mid = fractal_noise((n, n), rng, beta=2.2, fmin=8.0)
    mix = np.clip(0.5 + 0.35 * big + 0.15 * mid, 0, 1)[..., None]
    col = mix * np.asarray(g.green, np.float32) + (1 - mix) * np.asarray(g.green2, np.float32)
    patches = fractal_noise((n, n), rng, beta=3.0, fmin=3.0)
    thr = np.quantile(patches, 1 - g.dry_fraction) if g.dry_fraction > 0 else np.inf
    dry = np.clip((patches - thr) / 0.3, 0, 1)[..., None]
    col = (1 - dry) * col + dry * np.asarray(g.dry, np.float32)
    lawn = np.ones((n, n), np.float32)
    if g.patches:
        paint_patches(col, g.patches, origin, g.resolution, lawn)
    return LawnMap(col.astype(np.float32), lawn, float(g.resolution), float(origin))


def shadow_map(prims: Sequence[Primitive], sun: np.ndarray, n: int, res: float, origin: float,
               weights: Sequence[float] | None = None) -> np.ndarray:
    """Fraction of direct sun the primitives block, (n, n) float32 in
    [0, 1], on a map grid of ``n`` cells of ``res`` metres from ``origin``
    (see the module docstring), softened over about 0.25 m.

    ``sun`` is the unit vector towards the sun (x, y, z), z > 0.
    ``weights`` (one per primitive, in [0, 1], default 1) scale each
    primitive's shadow: a thinned crown lets part of the sun through.
    """
    import cv2

    o = origin
    shadow = np.zeros((n, n), np.float32)
    s = sun
    horiz = np.hypot(s[0], s[1])
    cot = horiz / s[2]
    sx, sy = (s[0] / horiz, s[1] / horiz) if horiz > 1e-9 else (1.0, 0.0)
    for i, p in enumerate(prims):
        wt = 1.0 if weights is None else float(weights[i])
        if wt <= 0:
            continue
        rb = p.bound_radius
        top = max(p.z1, 0.0)
        reach = top * cot
        # bounding box of the shadow: footprint swept away from the sun
        xs = [p.x - rb, p.x + rb, p.x - rb - sx * reach, p.x + rb - sx * reach]
        ys = [p.y - rb, p.y + rb, p.y - rb - sy * reach, p.y + rb - sy * reach]
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
        d = hit_distance(p, X - p.x, Y - p.y, sx, sy, s[2] / horiz if horiz > 1e-9 else 1e9)
        hit = np.isfinite(d).astype(np.float32)
        if wt != 1.0:
            hit *= np.float32(wt)
        shadow[j0:j1, i0:i1] = np.maximum(shadow[j0:j1, i0:i1], hit)
    k = max(3, int(0.25 / res) | 1)
    return cv2.GaussianBlur(shadow, (k, k), 0)


def hit_distance(p: Primitive, ox: np.ndarray, oy: np.ndarray, dx: float, dy: float, rise: float) -> np.ndarray:
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


def paint_patches(col: np.ndarray, patches: Sequence[dict[str, Any]], origin: float, res: float,
                  lawn: np.ndarray | None = None) -> None:
    """Paints ground patches (patio, gravel path, flower bed; see
    :class:`~sfanav.sim.world.GroundSpec`) into the lawn's colour map
    ``col`` (n, n, 3; row = y, column = x) in place; ``lawn`` (n, n), if
    given, is multiplied by the share of each cell the patches leave to
    the lawn. Raises ValueError for an unknown patch kind."""
    n = col.shape[0]
    for pt in patches:
        kind = pt["kind"]
        rng = np.random.default_rng(int(pt.get("seed", 0)))
        if kind == "path":
            P = np.asarray(pt["points"], float)
            half = float(pt["width"]) / 2
            lo, hi = P.min(axis=0) - half - 0.5, P.max(axis=0) + half + 0.5
        elif kind == "patio":
            r = 0.5 * float(np.hypot(pt["length"], pt["width"]))
            lo, hi = np.array([pt["x"] - r, pt["y"] - r]), np.array([pt["x"] + r, pt["y"] + r])
        elif kind == "bed":
            r = max(float(pt["rx"]), float(pt["ry"])) + 0.2
            lo, hi = np.array([pt["x"] - r, pt["y"] - r]), np.array([pt["x"] + r, pt["y"] + r])
        else:
            raise ValueError(f"unknown ground patch kind {kind!r}")
        i0, j0 = (np.floor((lo - origin) / res).astype(int)).clip(0, n)
        i1, j1 = (np.ceil((hi - origin) / res).astype(int) + 1).clip(0, n)
        if i1 <= i0 or j1 <= j0:
            continue
        gx = origin + (np.arange(i0, i1) + 0.5) * res
        gy = origin + (np.arange(j0, j1) + 0.5) * res
        X, Y = np.meshgrid(gx, gy)
        block = col[j0:j1, i0:i1]
        shape = X.shape
        if kind == "patio":
            c, s_ = np.cos(pt["yaw"]), np.sin(pt["yaw"])
            lx, ly = c * (X - pt["x"]) + s_ * (Y - pt["y"]), -s_ * (X - pt["x"]) + c * (Y - pt["y"])
            inside = (np.abs(lx) <= pt["length"] / 2) & (np.abs(ly) <= pt["width"] / 2)
            tile = float(pt["tile"])
            tu, tv = np.floor((lx + pt["length"] / 2) / tile), np.floor((ly + pt["width"] / 2) / tile)
            base = np.asarray(rng.choice([(0.62, 0.60, 0.56), (0.70, 0.64, 0.55), (0.55, 0.55, 0.57)]), np.float32)
            # per-slab brightness, joints one map cell wide
            shade = 0.85 + 0.3 * ((np.sin(tu * 12.9898 + tv * 78.233 + rng.uniform(0, 100)) * 43758.5453) % 1.0)
            fu, fv = (lx + pt["length"] / 2) % tile, (ly + pt["width"] / 2) % tile
            joint = (fu < res) | (fv < res)
            paint = base[None, None, :] * shade[..., None] * np.where(joint, 0.45, 1.0)[..., None]
            alpha = inside.astype(np.float32)
        elif kind == "path":
            # distance to the polyline
            d = np.full(shape, np.inf)
            for a, b in zip(P[:-1], P[1:]):
                ab = b - a
                t = np.clip(((X - a[0]) * ab[0] + (Y - a[1]) * ab[1]) / max(ab @ ab, 1e-12), 0, 1)
                d = np.minimum(d, np.hypot(X - a[0] - t * ab[0], Y - a[1] - t * ab[1]))
            half = float(pt["width"]) / 2
            alpha = np.clip((half - d) / (1.5 * res) + 0.5, 0, 1).astype(np.float32)
            base = np.asarray((0.66, 0.62, 0.54), np.float32)
            grain = 0.8 + 0.4 * rng.random(shape)
            paint = base[None, None, :] * grain[..., None]
        else:  # bed
            c, s_ = np.cos(pt["yaw"]), np.sin(pt["yaw"])
            lx, ly = c * (X - pt["x"]) + s_ * (Y - pt["y"]), -s_ * (X - pt["x"]) + c * (Y - pt["y"])
            q = (lx / pt["rx"]) ** 2 + (ly / pt["ry"]) ** 2
            alpha = (q <= 1.0).astype(np.float32)
            soil = np.asarray((0.28, 0.20, 0.13), np.float32)
            paint = np.broadcast_to(soil, shape + (3,)) * (0.8 + 0.4 * rng.random(shape))[..., None]
            u = rng.random(shape)
            leaf = u < 0.35
            paint = np.where(leaf[..., None], np.asarray((0.16, 0.34, 0.10), np.float32), paint)
            palette = np.asarray([(0.85, 0.15, 0.15), (0.95, 0.85, 0.20), (0.60, 0.30, 0.75), (0.95, 0.95, 0.92),
                                  (0.95, 0.50, 0.15)], np.float32)
            flowers = palette[rng.integers(0, len(palette), shape)]
            paint = np.where((u > 0.72)[..., None], flowers, paint)
        block[:] = block * (1 - alpha[..., None]) + paint.astype(np.float32) * alpha[..., None]
        if lawn is not None:
            lawn[j0:j1, i0:i1] *= 1 - alpha
