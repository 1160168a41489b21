"""Ray casting of garden worlds for the panoramic and omnidirectional cameras
(:mod:`sfanav.sim.cameras`).

One ray caster serves both cameras. It renders a separable ray grid, a
vector of azimuths (one per column, relative to the camera's heading) times a
vector of elevations (one per row), from a camera at ``mount_height`` metres
above the ground:

* sky and distant tree line above the horizon (at infinity: no parallax);
* the ground below it, hit at horizontal distance ``h / tan(-elevation)``,
  textured by a photographic lawn detail times a large-scale colour map,
  mip-mapped by distance, with the shadows of the objects (both maps from
  :mod:`sfanav.sim.ground`);
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

from typing import Any, Sequence

import numpy as np

from .cameras import Camera, LevelGrid, OmniCamera, PanoramicCamera, RayGrid, column_of_bearing
from .conditions import DECIDUOUS_KINDS, Lighting, Season
from .ground import lawn_map, shadow_map
from .terrain import MAX_TILT_DEG, Attitude
from .atlas import PrimitiveArrays, TextureAtlas
from .textures import Pyramid, fractal_noise, make_texture, photo
from .world import World

_LUMA = np.array([0.299, 0.587, 0.114], np.float32)


FOG_DISTANCE = 250.0  # m; aerial perspective: far surfaces fade to the horizon colour


LEVEL_MARGINS_DEG = (4.0, 8.0, 16.0, 2 * MAX_TILT_DEG)  # elevation margins of the level grids of tilted views


class Renderer:
    """Renders a :class:`~sfanav.sim.world.World` for any camera.

    Building a renderer synthesises the textures and the ground and sky maps
    (about a second for a garden); each lighting condition's sun direction
    adds a shadow map (cached), each season its recoloured lawn and sky
    (cached). Rendering is then pure NumPy.

    A lighting's :class:`~sfanav.sim.conditions.Season` multiplies the
    lawn's colour map (not the painted patches), the sky and the horizon
    colour, and the colour of deciduous foliage (leaf-textured parts of
    ``DECIDUOUS_KINDS`` objects, and the distant tree line); crowns of
    trees and bushes are thinned by its ``leaf_cover`` (see
    :meth:`Season.leafy`), and so are their shadows. Transient objects
    (``WorldObject.seasons``) and their shadows are drawn only in their
    seasons (a lighting without a season counts as summer). A season's
    ``texture_seed`` shifts the leaf texture of deciduous foliage and the
    grass detail of the lawn (:meth:`Season.texture_offset`).

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
        self._atlas = TextureAtlas(self.pyramids)
        self._static = PrimitiveArrays([p for o in world.objects for p in o.parts], self._atlas)
        owner = {id(p): o for o in world.objects for p in o.parts}
        self._owners = [owner[id(p)] for p in self._static.list]  # the object of each static primitive
        self._marker_of = np.array([-1 if o.marker_id is None else o.marker_id for o in self._owners], np.int64)
        self._covered: dict[frozenset[int], PrimitiveArrays] = {}
        self._foliage, self._crowns = self._vegetation()
        self._presence: dict[str | None, np.ndarray | None] = {}
        self._build_ground()
        self._build_sky()
        self._ground_cache: dict[tuple, np.ndarray] = {}
        self._sky_cache: dict[Season, np.ndarray] = {}
        self._grid_cache: dict[int, dict[str, Any]] = {}
        self._level_cache: dict[tuple[int, float], LevelGrid] = {}

    def _vegetation(self) -> tuple[np.ndarray, np.ndarray]:
        """Per static primitive (in ``self._static`` order): deciduous foliage
        (seasonal colour), and of those the crowns (ellipsoids of trees and
        bushes: seasonal leaf cover)."""
        tex = self.world.textures
        foliage = np.array([o.kind in DECIDUOUS_KINDS and tex[p.texture].kind == "leaves"
                            for o, p in zip(self._owners, self._static.list)], bool)
        crowns = foliage & np.array([p.shape == "ellipsoid" for p in self._static.list], bool)
        return foliage, crowns

    def _present(self, season: Season | None) -> np.ndarray | None:
        """Per static primitive (in ``self._static`` order): whether its
        object is there in ``season`` (bool array), or None when every
        primitive is (a world without transient objects, or all there)."""
        name = None if season is None else season.name
        if name not in self._presence:
            mask = np.array([o.present(name) for o in self._owners], bool)
            self._presence[name] = None if mask.all() else mask
        return self._presence[name]

    # ------------------------------------------------------------ ground

    def _build_ground(self) -> None:
        g = self.world.ground
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
        lawn = lawn_map(g, self.world.outer_radius)
        self._gmap_n = lawn.n
        self._gmap_res = lawn.resolution
        self._gmap_origin = lawn.origin
        self._gmap = lawn.colour  # (n, n, 3), row = y index, col = x index
        self._lawn = lawn.lawn[..., None]  # (n, n, 1): share of lawn, the part a season recolours
        share = lawn.lawn.reshape(-1).astype(np.float32)
        self._lawn_flat = np.concatenate([share, share])  # indexed like the lit ground (near and far copies)

    def ground_colour_map(self) -> tuple[np.ndarray, float, float]:
        """The lawn's colour map before light and texture: ``(map, resolution,
        origin)``, map (n, n, 3) float32 RGB in [0, 1] (row = y index, column
        = x index), cells of ``resolution`` metres starting at ``origin``
        metres on both axes (periodic beyond)."""
        return self._gmap, float(self._gmap_res), float(self._gmap_origin)

    def _shadow_map(self, light: Lighting) -> np.ndarray:
        """Fraction of direct sun blocked, (n, n) in [0, 1], on the ground map grid."""
        n = self._gmap_n
        if not light.shadows:
            return np.zeros((n, n), np.float32)
        weights = None
        if light.season is not None and light.season.leaf_cover < 1:
            weights = np.where(self._crowns, light.season.leaf_cover, 1.0)
        present = self._present(light.season)
        if present is not None:  # absent transient objects cast no shadow
            weights = present * (1.0 if weights is None else weights)
        return shadow_map(self._static.list, light.sun, n, self._gmap_res, self._gmap_origin, weights)

    def _lit_ground(self, light: Lighting) -> np.ndarray:
        season = light.season
        present = self._present(season)
        key = (light.sun_azimuth_deg, light.sun_elevation_deg, light.ambient, light.sun_intensity, light.shadows,
               None if season is None else (season.ground, season.leaf_cover),
               None if present is None else present.tobytes())
        lit = self._ground_cache.get(key)
        if lit is None:
            gmap = self._gmap
            if season is not None:
                gmap = gmap * (1 + self._lawn * (np.asarray(season.ground, np.float32) - 1))
            s = light.sun
            direct = _direct_light(light) * max(s[2], 0.0)
            shade = light.ambient + direct * (1.0 - self._shadow_map(light))
            # two copies: with shadows, and without for ground so far away that the
            # periodic map would repeat the shadows of the objects
            nn = self._gmap_n * self._gmap_n
            lit = np.ones((2 * nn, 4), np.float32)
            lit[:nn, :3] = (gmap * shade[..., None]).reshape(-1, 3)
            lit[nn:, :3] = (gmap * (light.ambient + direct)).reshape(-1, 3)
            lit = lit.view("V16").ravel()
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
        clouds = fractal_noise((n_el * 2, n_az), rng, beta=3.4, fmin=3.0, aspect=2.0)[:n_el]
        thr = np.quantile(clouds, 1 - sk.cloud_cover) if sk.cloud_cover > 0 else np.inf
        cover = np.clip((clouds - thr) / 0.6, 0, 1) ** 0.7
        cover *= np.clip(el / np.radians(3.0), 0, 1)[:, None]  # thin out at the horizon
        # brighter tops, grey bellies
        shade = 0.97 - 0.2 * np.clip(clouds - thr - 0.6, 0, 1.5) / 1.5
        cloud_col = shade[..., None] * np.ones(3, np.float32)
        sky = base * (1 - cover[..., None]) + cloud_col * cover[..., None]
        # distant tree line / hills at infinity
        prof = fractal_noise((1, n_az), rng, beta=1.8, fmin=1.0)[0]
        lo, hi = np.radians(sk.treeline_deg)
        prof = lo + (hi - lo) * (prof - prof.min()) / max(prof.max() - prof.min(), 1e-9)
        tex = 1.0 + 0.25 * fractal_noise((n_el, n_az), rng, beta=1.2)
        tree = (np.asarray(sk.treeline, np.float32)[None, None, :] * tex[..., None]).astype(np.float32)
        below = el[:, None] < prof[None, :]
        self._sky_open, self._treeline, self._below_treeline = sky, tree, below[..., None]
        sky = np.where(below[..., None], tree, sky)
        self._sky = sky.astype(np.float32)
        self._sky_el = el
        self._horizon_rgb = np.asarray(sk.horizon, np.float32)
        self._horizon_rgba = np.append(self._horizon_rgb, np.float32(1.0))

    def _seasonal_sky(self, season: Season | None) -> np.ndarray:
        """The sky map (n_el, n_az, 3) in a season: open sky times the sky
        multiplier; the tree line times the foliage multiplier, letting
        ``(1 - leaf_cover) / 2`` of the sky through."""
        if season is None:
            return self._sky
        sky = self._sky_cache.get(season)
        if sky is None:
            open_sky = self._sky_open * np.asarray(season.sky, np.float32)
            keep = np.float32(0.5 + 0.5 * season.leaf_cover)
            tree = keep * (self._treeline * np.asarray(season.foliage, np.float32)) + (1 - keep) * open_sky
            sky = np.where(self._below_treeline, tree, open_sky).astype(np.float32)
            if len(self._sky_cache) > 8:
                self._sky_cache.clear()
            self._sky_cache[season] = sky
        return sky

    def _horizon(self, season: Season | None) -> np.ndarray:
        """The RGBA colour far surfaces fade to."""
        if season is None:
            return self._horizon_rgba
        return np.append(self._horizon_rgb * np.asarray(season.sky, np.float32), np.float32(1.0))

    # ------------------------------------------------------------ per-grid data

    def _grid_data(self, grid: RayGrid, height: float | None = None) -> dict[str, Any]:
        """Per-grid constants (cached per grid), for a camera ``height``
        metres above the ground (default the grid's mount height; another
        height recomputes the ground rows, uncached)."""
        key = id(grid)
        gd = self._grid_cache.get(key)
        if gd is None or gd["grid"] is not grid:
            gd = {"grid": grid, "h": grid.h}
            sky_rows = np.nonzero(grid.elev >= 0)[0]
            gnd_rows = np.nonzero(grid.elev < 0)[0]
            gd["sky_rows"] = slice(int(sky_rows[0]), int(sky_rows[-1]) + 1) if len(sky_rows) else slice(0, 0)
            gd["gnd_rows"] = slice(int(gnd_rows[0]), int(gnd_rows[-1]) + 1) if len(gnd_rows) else slice(0, 0)
            if len(sky_rows):
                gd["sky_k"] = np.clip(np.searchsorted(self._sky_el, grid.elev[sky_rows]), 0, len(self._sky_el) - 1)
                gd["sky_panels"] = {}
            gd.update(self._ground_data(grid, grid.h, gd["gnd_rows"], gd["sky_rows"]))
            gd["neg_elev"] = -grid.elev
            if len(self._grid_cache) > 16:
                self._grid_cache.clear()
            self._grid_cache[key] = gd
        if height is None or height == grid.h:
            return gd
        out = dict(gd)
        out["h"] = float(height)
        out.update(self._ground_data(grid, float(height), gd["gnd_rows"], gd["sky_rows"]))
        return out

    def _ground_data(self, grid: RayGrid, h: float, gr: slice, sr: slice) -> dict[str, Any]:
        """The ground rows' distances, texture levels and fog, and the
        initial depth buffer, for a camera ``h`` metres above the ground."""
        gd: dict[str, Any] = {}
        n_gnd, n_sky = gr.stop - gr.start, sr.stop - sr.start
        if n_gnd:
            gnd_rows = np.arange(gr.start, gr.stop)
            t = grid.tan[gnd_rows]
            d = h / -t  # horizontal distance of the ground hit, per row
            # texel footprint: the larger of the radial and tangential pixel extents
            de = np.abs(np.gradient(grid.elev))[gnd_rows] if grid.H > 1 else np.full(n_gnd, 0.01)
            foot = np.maximum(d * d / h * de, d * grid.pixel_angle)
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
            half_period = self._gmap_n * self._gmap_res / 2
            far = d > half_period - self.world.outer_radius - 1.0
            gd["gnd_map_off"] = np.where(far, self._gmap_n * self._gmap_n, 0)[:, None].astype(np.int64)
            gd["depth_init"] = np.concatenate(
                [np.full(n_sky, np.inf), d]
            )[:, None] * np.ones((1, grid.W))
        else:
            gd["depth_init"] = np.full((grid.H, grid.W), np.inf)
        return gd

    def _sky_panel(self, gd: dict[str, Any], season: Season | None) -> np.ndarray:
        """The sky rows of a grid in a season: (Hs, n_az) of 16-byte RGBA texels."""
        panels = gd["sky_panels"]
        panel = panels.get(season)
        if panel is None:
            k = gd["sky_k"]
            rgba = np.ones((len(k), self._sky_n_az, 4), np.float32)
            rgba[..., :3] = self._seasonal_sky(season)[k]
            panel = rgba.view("V16")[..., 0]
            if len(panels) > 8:
                panels.clear()
            panels[season] = panel
        return panel

    # ------------------------------------------------------------ rendering

    def render(self, camera: Camera, pose: Sequence[float], time: float = 0.0,
               lighting: Lighting | None = None, attitude: Attitude | None = None) -> np.ndarray:
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
        attitude : Attitude, optional
            The camera's roll, pitch and height change on uneven ground
            (:mod:`sfanav.sim.terrain`); default level at its mount height.
            A tilted camera's view is resampled from a level view of the same
            viewpoint (:class:`~sfanav.sim.cameras.LevelGrid`), so the
            world's horizon runs off-centre through the image.

        Returns
        -------
        ndarray uint8, ``camera.shape``.

        Raises
        ------
        TypeError
            ``camera`` or ``attitude`` of the wrong type.
        ValueError
            A pose that is not three finite numbers, or an attitude that
            puts the camera at or below the ground.
        """
        if not isinstance(camera, (PanoramicCamera, OmniCamera)):
            raise TypeError(f"camera must be a PanoramicCamera or OmniCamera, got {type(camera).__name__}")
        if attitude is not None and not isinstance(attitude, Attitude):
            raise TypeError(f"attitude must be an Attitude (sfanav.sim.terrain), got {type(attitude).__name__}")
        x, y, heading = _pose3(pose)
        light = lighting or self.lighting
        if attitude is None or attitude.identity:
            img = self._render_grid(camera.grid, x, y, heading, time, light)
        else:
            h = camera.grid.h + attitude.height_m
            if not h > 0.01:
                raise ValueError(f"attitude height_m {attitude.height_m} puts the camera ({camera.grid.h} m up) "
                                 "at or below the ground")
            if attitude.level:
                img = self._render_grid(camera.grid, x, y, heading, time, light, height=h)
            else:
                level = self._level_grid(camera.grid, attitude.tilt_deg)
                img = self._render_grid(level.grid, x, y, heading, time, light, height=h)
                img = level.resample(img, attitude.rotation())
        if isinstance(camera, OmniCamera):
            img = camera.finish(img)
        return _to_uint8(img, camera.rgb, light.rgb)

    def _level_grid(self, grid: RayGrid, tilt_deg: float) -> LevelGrid:
        """The (cached) level grid with the smallest of a few margins that
        covers a tilt of ``tilt_deg``."""
        margin = next(m for m in LEVEL_MARGINS_DEG if m >= tilt_deg + 0.5)
        key = (id(grid), margin)
        level = self._level_cache.get(key)
        if level is None or level.camera_grid is not grid:
            if len(self._level_cache) > 8:
                self._level_cache.clear()
            level = self._level_cache[key] = LevelGrid(grid, margin)
        return level

    def _render_grid(self, grid: RayGrid, x: float, y: float, heading: float, time: float,
                     light: Lighting, height: float | None = None) -> np.ndarray:
        """Float32 image (H, W, 4) of a ray grid, before the light's intensity
        and tint; channel 3 is padding (see :meth:`render`). ``height``: the
        camera's height above the ground (default the grid's)."""
        gd = self._grid_data(grid, height)
        H, W = grid.H, grid.W
        phi = heading + grid.bearings
        ux, uy = np.cos(phi), np.sin(phi)
        out = np.empty((H, W, 4), np.float32)
        depth = gd["depth_init"].copy()
        # sky
        sr = gd["sky_rows"]
        if sr.stop > sr.start:
            k = (np.mod(phi, 2 * np.pi) * (self._sky_n_az / (2 * np.pi))).astype(np.int64) % self._sky_n_az
            out[sr] = np.take(self._sky_panel(gd, light.season), k, axis=1).view(np.float32).reshape(
                sr.stop - sr.start, W, 4)
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
                np.floor((Y - o) / res).astype(np.int64) & (n - 1)) * n + gd["gnd_map_off"]
            if light.season is not None and light.season.texture_seed is not None:
                # the season's grass: the detail shifted on the lawn share, patio, paths and beds unchanged
                du, dv = light.season.texture_offset("lawn")
                iu = np.floor((X + du) * inv).astype(np.int64) & gd["det_mask"]
                iv = np.floor((Y + dv) * inv).astype(np.int64) & gd["det_mask"]
                grass = self._det_flat[gd["det_off"] + iv * gd["det_n"] + iu]
                det = det + self._lawn_flat[gi] * (grass - det)
            col = self._lit_ground(light)[gi].view(np.float32).reshape(gi.shape + (4,)) * det[..., None]
            fog = gd["gnd_fog"]
            col += fog * (self._horizon(light.season) - col)
            out[gr] = col
        # objects
        P = self._static
        hidden = self.world.hidden_markers(x, y) if self.world.occlusions else frozenset()
        if hidden:
            P = self._with_covered_markers(hidden)
        if self.world.dynamic:
            P = P.plus(PrimitiveArrays([dd.primitive_at(time) for dd in self.world.dynamic], self._atlas))
        self._draw(P, gd, grid, x, y, heading, ux, uy, out, depth, light)
        return out

    def _with_covered_markers(self, hidden: frozenset[int]) -> PrimitiveArrays:
        """The static primitives with the faces of the ``hidden`` markers
        covered (drawn with the board's side texture), cached per set."""
        if hidden not in self._covered:
            P = object.__new__(PrimitiveArrays)
            for f in PrimitiveArrays.FIELDS:
                setattr(P, f, getattr(self._static, f))
            P.list = self._static.list
            P.front = np.where(np.isin(self._marker_of, list(hidden)), -1, self._static.front)
            self._covered[hidden] = P
        return self._covered[hidden]

    def _draw(self, P: PrimitiveArrays, gd: dict[str, Any], grid: RayGrid, cx: float, cy: float, heading: float,
              ux: np.ndarray, uy: np.ndarray, out: np.ndarray, depth: np.ndarray, light: Lighting) -> None:
        """Draws every primitive at once: candidate pixels are the union of
        the primitives' screen bounding blocks, intersected exactly in one
        vector pass per shape; the nearest hit per pixel wins."""
        n = len(P.code)
        if n == 0:
            return
        W, h = grid.W, gd["h"]
        atlas = self._atlas
        season = light.season
        if season is not None:  # the dynamic primitives (after the static ones) are no plants
            pad = np.zeros(n - len(self._foliage), bool)
            foliage, crowns = np.concatenate([self._foliage, pad]), np.concatenate([self._crowns, pad])
        present = self._present(season)  # None: every static primitive is there
        shift = None  # the season's leaf pattern: (deciduous foliage mask, du, dv)
        if season is not None and season.texture_seed is not None:
            shift = (foliage, *season.texture_offset("foliage"))
        # --- per primitive: screen block
        qx, qy = P.x - cx, P.y - cy
        rho2 = qx * qx + qy * qy
        rho = np.sqrt(rho2)
        half = np.arcsin(np.clip(P.rb / np.maximum(rho, 1e-9), 0.0, 1.0))
        jc = column_of_bearing(np.arctan2(qy, qx) - heading, W)
        hw = half * (W / (2 * np.pi))
        near = np.maximum(rho - P.rb, 0.05)
        far = rho + P.rb
        z0r, z1r = P.z0 - h, P.z1 - h
        e_hi = np.arctan2(z1r, np.where(z1r > 0, near, far))
        e_lo = np.arctan2(z0r, np.where(z0r < 0, near, far))
        r0 = np.searchsorted(gd["neg_elev"], -e_hi, "left")
        r1 = np.searchsorted(gd["neg_elev"], -e_lo, "right")
        c0 = np.floor(jc - hw).astype(np.int64)
        c1 = np.ceil(jc + hw).astype(np.int64) + 1
        full = (rho <= P.rb) | (c1 - c0 >= W)
        c0 = np.where(full, 0, c0)
        c1 = np.where(full, W, c1)
        nc = c1 - c0
        cnt = np.maximum(r1 - r0, 0) * nc
        if present is not None:  # transient objects out of season: no candidate pixels
            cnt[: len(present)] *= present
        total = int(cnt.sum())
        if total == 0:
            return
        # --- candidate pixels
        pid = np.repeat(np.arange(n), cnt)
        local = np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ncp = nc[pid]
        row = r0[pid] + local // ncp
        col = (c0[pid] + local % ncp) % W
        pix = row * W + col
        base = depth.reshape(-1)
        keep = near[pid] < base[pix]  # cannot beat a nearer ground hit
        pid, row, col, pix = pid[keep], row[keep], col[keep], pix[keep]
        t = grid.tan[row]
        vx, vy = ux[col], uy[col]
        d = np.full(len(pid), np.inf)
        face = np.zeros(len(pid), np.int8)
        bounds = np.searchsorted(pid, np.searchsorted(P.code, [0, 1, 2, 3]))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            # ellipsoids
            s, e = bounds[0], bounds[1]
            if e > s:
                p, tt = pid[s:e], t[s:e]
                r2 = P.r * P.r
                rz = 0.5 * (P.z1 - P.z0)
                zc = 0.5 * (P.z0 + P.z1) - h
                ir2, irz2 = (1.0 / np.where(r2 > 0, r2, 1.0))[p], (1.0 / (rz * rz))[p]
                zcp = zc[p]
                a = qx[p] * vx[s:e] + qy[p] * vy[s:e]
                A = ir2 + tt * tt * irz2
                B = -2.0 * (a * ir2 + tt * zcp * irz2)
                C = (rho2 / np.where(r2 > 0, r2, 1.0) - 1.0 + zc * zc / (rz * rz))[p]
                disc = B * B - 4.0 * A * C
                dd = (-B - np.sqrt(disc)) / (2.0 * A)
                d[s:e] = np.where((disc >= 0) & (dd > 0), dd, np.inf)
            # boxes and cylinders: an interval [din, dout] in the horizontal plane, then heights
            for code in (1, 2):
                s, e = bounds[code], bounds[code + 1]
                if e <= s:
                    continue
                p, tt = pid[s:e], t[s:e]
                if code == 2:
                    a = qx[p] * vx[s:e] + qy[p] * vy[s:e]
                    disc = (P.r * P.r - rho2)[p] + a * a
                    sq = np.sqrt(disc)
                    din, dout = a - sq, a + sq
                    valid = disc > 0
                    fc = np.zeros(e - s, np.int8)
                else:
                    cs, sn = P.cos, P.sin
                    ox, oy = (-(cs * qx + sn * qy))[p], (-(-sn * qx + cs * qy))[p]
                    wx = cs[p] * vx[s:e] + sn[p] * vy[s:e]
                    wy = -sn[p] * vx[s:e] + cs[p] * vy[s:e]
                    L2, W2 = P.L2[p], P.W2[p]
                    tx1, tx2 = (-L2 - ox) / wx, (L2 - ox) / wx
                    ty1, ty2 = (-W2 - oy) / wy, (W2 - oy) / wy
                    txn, tyn = np.minimum(tx1, tx2), np.minimum(ty1, ty2)
                    din = np.maximum(txn, tyn)
                    dout = np.minimum(np.maximum(tx1, tx2), np.maximum(ty1, ty2))
                    valid = (din < dout) & (dout > 0)
                    # faces: 0 = +x, 1 = -x, 2 = +y, 3 = -y (the "front")
                    fc = np.where(txn > tyn, np.where(wx < 0, 0, 1), np.where(wy < 0, 2, 3)).astype(np.int8)
                din = np.maximum(din, 0.0)
                zin = din * tt
                lo, hi = z0r[p], z1r[p]
                side = valid & (zin >= lo) & (zin <= hi)
                dc = np.where(tt < 0, hi, lo) / tt
                cap = (valid & ~side & (dc >= din) & (dc <= dout)
                       & (((tt < 0) & (zin > hi)) | ((tt > 0) & (zin < lo))))
                d[s:e] = np.where(side, din, np.where(cap, dc, np.inf))
                face[s:e] = np.where(cap, 4, fc)
            foot = rho * grid.pixel_angle  # metres per pixel at the primitive
            level = np.floor(np.log2(np.maximum(foot / atlas.texel[P.tex], 1.0))).astype(np.int64)
            ftex = np.maximum(P.front, 0)
            flevel = np.floor(np.log2(np.maximum(foot / atlas.texel[ftex], 1.0))).astype(np.int64)
            level = np.stack([np.minimum(level, atlas.nlev[P.tex] - 1), np.minimum(flevel, atlas.nlev[ftex] - 1)])
            # transparent texels (fence gaps) let the ray through
            if atlas.alpha[P.tex].any():
                m = np.nonzero(atlas.alpha[P.tex][pid] & np.isfinite(d))[0]
                if len(m):
                    rgba, _ = self._surface(P, m, pid, d, face, t, vx, vy, qx, qy, h, level, bounds, shift)
                    d[m[rgba[:, 3] < 0.5]] = np.inf
            # thinned crowns let the ray through where the season has no leaf
            if season is not None and season.leaf_cover < 1:
                m = np.nonzero(crowns[pid] & np.isfinite(d))[0]
                if len(m):
                    dm = d[m]
                    d[m[~season.leafy(cx + dm * vx[m], cy + dm * vy[m], h + dm * t[m])]] = np.inf
            # depth test: nearest hit per pixel
            cand = np.nonzero(d < base[pix])[0]
            if not len(cand):
                return
            buf = base.copy()
            np.minimum.at(buf, pix[cand], d[cand])
            win = cand[d[cand] <= buf[pix[cand]]]
            rgba, nrm = self._surface(P, win, pid, d, face, t, vx, vy, qx, qy, h, level, bounds, shift)
            if season is not None:
                rgba[foliage[pid[win]], :3] *= np.asarray(season.foliage, np.float32)
            sun = light.sun
            norm = np.sqrt((nrm * nrm).sum(axis=1))
            lam = np.maximum((nrm @ sun) / np.maximum(norm, 1e-12), 0.0)
            shade = (light.ambient + _direct_light(light) * lam).astype(np.float32)
            rgba *= shade[:, None]
            fog = (1.0 - np.exp(-rho[pid[win]] / FOG_DISTANCE)).astype(np.float32)[:, None]
            rgba += fog * (self._horizon(season) - rgba)
        out.reshape(-1, 4)[pix[win]] = rgba
        base[pix[win]] = d[win]

    def _surface(self, P: PrimitiveArrays, idx: np.ndarray, pid: np.ndarray, d: np.ndarray, face: np.ndarray,
                 t: np.ndarray, vx: np.ndarray, vy: np.ndarray, qx: np.ndarray, qy: np.ndarray, h: float,
                 level: np.ndarray, bounds: np.ndarray,
                 shift: tuple[np.ndarray, float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Texture colour (n, 4) and surface normal (n, 3) at the hits of
        candidates ``idx`` (sorted). ``shift``: (mask per primitive, du, dv
        metres) moves the texture coordinates of the masked primitives (a
        season's ``texture_seed``)."""
        atlas = self._atlas
        p = pid[idx]
        dw = d[idx]
        tt = t[idx]
        hx = dw * vx[idx] - qx[p]  # hit point relative to the primitive's centre
        hy = dw * vy[idx] - qy[p]
        hz = dw * tt  # height above the camera
        z = hz + h
        nrm = np.zeros((len(idx), 3))
        u = np.empty(len(idx))
        v = z.copy()
        fc = face[idx]
        entry = atlas.base[P.tex[p]] + level[0, p]
        g = np.searchsorted(idx, bounds)
        # ellipsoids
        s, e = g[0], g[1]
        if e > s:
            pp = p[s:e]
            r = P.r[pp]
            rz = 0.5 * (P.z1 - P.z0)[pp]
            zc = 0.5 * (P.z0 + P.z1)[pp] - h
            nrm[s:e, 0] = hx[s:e] / (r * r)
            nrm[s:e, 1] = hy[s:e] / (r * r)
            nrm[s:e, 2] = (hz[s:e] - zc) / (rz * rz)
            u[s:e] = np.arctan2(hy[s:e], hx[s:e]) * r
        # boxes
        s, e = g[1], g[2]
        if e > s:
            pp = p[s:e]
            cs, sn = P.cos[pp], P.sin[pp]
            lx = cs * hx[s:e] + sn * hy[s:e]
            ly = -sn * hx[s:e] + cs * hy[s:e]
            f = fc[s:e]
            nlx = np.where(f == 0, 1.0, np.where(f == 1, -1.0, 0.0))
            nly = np.where(f == 2, 1.0, np.where(f == 3, -1.0, 0.0))
            nrm[s:e, 0] = cs * nlx - sn * nly
            nrm[s:e, 1] = sn * nlx + cs * nly
            u[s:e] = np.where(f <= 1, ly, lx)
        # cylinders
        s, e = g[2], g[3]
        if e > s:
            pp = p[s:e]
            nrm[s:e, 0] = hx[s:e]
            nrm[s:e, 1] = hy[s:e]
            u[s:e] = np.arctan2(hy[s:e], hx[s:e]) * P.r[pp]
        # caps (tops and bottoms of boxes and cylinders): ground-plane texture coordinates
        cap = fc == 4
        if cap.any():
            nrm[cap] = 0.0
            nrm[cap, 2] = -np.sign(tt[cap])
            u[cap] = hx[cap] + P.x[p[cap]]
            v[cap] = hy[cap] + P.y[p[cap]]
        if shift is not None:
            moved = shift[0][p]
            u[moved] += shift[1]
            v[moved] += shift[2]
        rgba = atlas.sample(entry, u, v)
        fr = (fc == 3) & (P.front[p] >= 0)
        if fr.any():
            pf = p[fr]
            cs, sn = P.cos[pf], P.sin[pf]
            lx = cs * hx[fr] + sn * hy[fr]
            fu = (lx + P.L2[pf]) / (2 * P.L2[pf])
            fv = (z[fr] - P.z0[pf]) / (P.z1[pf] - P.z0[pf])
            fe = atlas.base[P.front[pf]] + level[1, pf]
            rgba[fr] = atlas.sample_stretched(fe, fu, fv)
        return rgba, nrm


def _direct_light(light: Lighting) -> float:
    """The direct sunlight on a surface facing the sun (Lambert factor 1):
    the non-ambient share scaled by ``sun_intensity``, normalised so that
    level ground under a 50 deg sun gets the full share."""
    return light.sun_intensity * (1 - light.ambient) / float(np.sin(np.radians(50.0)))


def _pose3(pose: Sequence[float]) -> tuple[float, float, float]:
    try:
        x, y, th = (float(v) for v in pose)
    except (TypeError, ValueError):
        raise ValueError(f"pose must be (x, y, heading) in metres and radians, got {pose!r}") from None
    if not all(np.isfinite([x, y, th])):
        raise ValueError(f"pose must be finite, got {pose!r}")
    return x, y, th


def _to_uint8(img: np.ndarray, rgb: bool, light: np.ndarray) -> np.ndarray:
    """(H, W, 4) float32 before the light -> uint8 (H, W, 3) or gray (H, W)."""
    gain = (255.0 * light).astype(np.float32)
    if rgb:
        out = img[..., :3] * gain
    else:
        out = img[..., :3] @ (_LUMA * gain)
    out += 0.5
    return np.clip(out, 0, 255, out=out).astype(np.uint8)
