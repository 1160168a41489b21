"""The renderer's per-world tables: every texture's mip levels in one flat
array (:class:`TextureAtlas`) and the primitives' parameters as arrays
grouped by shape (:class:`PrimitiveArrays`), for vectorised ray casting in
:mod:`sfanav.sim.render`."""

from __future__ import annotations

import numpy as np

from .primitives import Primitive
from .textures import Pyramid

#: the shape groups of :class:`PrimitiveArrays`, in their order
SHAPE_CODE = {"ellipsoid": 0, "box": 1, "cylinder": 2}


class TextureAtlas:
    """Every texture's mip levels in one flat RGBA array (T, 4), with per
    (texture, level) entries: offset, height, width and texels per metre."""

    def __init__(self, pyramids: dict[str, Pyramid]):
        self.index: dict[str, int] = {}
        chunks, off, hs, ws, su, sv = [], [], [], [], [], []
        base, nlev, texel, alpha = [], [], [], []
        pos = 0
        for tid, (name, pyr) in enumerate(pyramids.items()):
            self.index[name] = tid
            base.append(len(off))
            nlev.append(len(pyr.levels))
            texel.append(pyr.texel)
            alpha.append(pyr.has_alpha)
            for lv, (h, w) in zip(pyr.levels, pyr.shapes):
                if lv.shape[1] == 3:
                    lv = np.concatenate([lv, np.ones((len(lv), 1), np.float32)], axis=1)
                chunks.append(lv[:, :4])
                off.append(pos)
                pos += h * w
                hs.append(h)
                ws.append(w)
                su.append(w / pyr.tile[0])
                sv.append(h / pyr.tile[1])
        self.flat = np.concatenate(chunks).astype(np.float32) if chunks else np.zeros((1, 4), np.float32)
        self._vflat = self.flat.view("V16").ravel()  # one 16-byte texel per element: fast gathers
        self.off = np.array(off, np.int64)
        self.h = np.array(hs, np.int64)
        self.w = np.array(ws, np.int64)
        self.su = np.array(su, np.float64)
        self.sv = np.array(sv, np.float64)
        self.base = np.array(base, np.int64)
        self.nlev = np.array(nlev, np.int64)
        self.texel = np.array(texel, np.float64)
        self.alpha = np.array(alpha, bool)
        self.pow2 = bool(np.all((self.w & (self.w - 1)) == 0) and np.all((self.h & (self.h - 1)) == 0))

    def sample(self, entry: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Wrapped nearest-texel lookup at surface coordinates in metres
        (u along, v up). Returns (n, 4)."""
        w, h = self.w[entry], self.h[entry]
        if self.pow2:
            iu = np.floor(u * self.su[entry]).astype(np.int64) & (w - 1)
            iv = (-1 - np.floor(v * self.sv[entry]).astype(np.int64)) & (h - 1)
        else:
            iu = np.floor(u * self.su[entry]).astype(np.int64) % w
            iv = (-1 - np.floor(v * self.sv[entry]).astype(np.int64)) % h
        return self._vflat[self.off[entry] + iv * w + iu].view(np.float32).reshape(-1, 4)

    def sample_stretched(self, entry: np.ndarray, fu: np.ndarray, fv: np.ndarray) -> np.ndarray:
        """Lookup at tile fractions fu, fv in [0, 1] (v up), clamped."""
        w, h = self.w[entry], self.h[entry]
        iu = np.clip((fu * w).astype(np.int64), 0, w - 1)
        iv = np.clip(((1.0 - fv) * h).astype(np.int64), 0, h - 1)
        return self._vflat[self.off[entry] + iv * w + iu].view(np.float32).reshape(-1, 4)


class PrimitiveArrays:
    """Primitive parameters as arrays, grouped by shape (ellipsoids, boxes,
    cylinders), for the per-frame vector work."""

    FIELDS = ("code", "x", "y", "z0", "z1", "r", "L2", "W2", "cos", "sin", "tex", "front", "rb")

    def __init__(self, prims: list[Primitive], atlas: TextureAtlas):
        order = sorted(range(len(prims)), key=lambda i: SHAPE_CODE[prims[i].shape])
        self.list = [prims[i] for i in order]
        L = self.list
        self.code = np.array([SHAPE_CODE[p.shape] for p in L], np.int64)
        self.x = np.array([p.x for p in L], float)
        self.y = np.array([p.y for p in L], float)
        self.z0 = np.array([p.z0 for p in L], float)
        self.z1 = np.array([p.z1 for p in L], float)
        self.r = np.array([p.radius for p in L], float)
        self.L2 = np.array([p.length / 2 for p in L], float)
        self.W2 = np.array([p.width / 2 for p in L], float)
        self.cos = np.array([np.cos(p.yaw) for p in L], float)
        self.sin = np.array([np.sin(p.yaw) for p in L], float)
        self.tex = np.array([atlas.index[p.texture] for p in L], np.int64)
        self.front = np.array([atlas.index[p.front] if p.front else -1 for p in L], np.int64)
        self.rb = np.array([p.bound_radius for p in L], float)

    def plus(self, extra: "PrimitiveArrays") -> "PrimitiveArrays":
        """These primitives followed by ``extra`` (cylinders only, so the
        shape groups stay contiguous)."""
        assert not len(extra.code) or (extra.code == SHAPE_CODE["cylinder"]).all()
        out = object.__new__(PrimitiveArrays)
        out.list = self.list + extra.list
        for f in self.FIELDS:
            setattr(out, f, np.concatenate([getattr(self, f), getattr(extra, f)]))
        return out
