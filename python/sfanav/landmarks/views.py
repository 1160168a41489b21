"""Marker views from omnidirectional images (thesis 5.4.1, Fig. 5.25).

A :class:`ViewExtractor` finds ArUco markers in a donut image of a
catadioptric camera and cuts out each marker's *view*: the marker's polar
angle ``phi = atan2(v, u)`` around the image centre says where it is, the
image is turned about the centre by ``90 deg - phi`` so that every marker
stands upright at the top, and the bounding box of the turned marker plus a
margin on every side is resized to ``size x size`` pixels. A marker's view is
then the same whatever the robot's heading (turning the robot turns the
donut), so the network trained on the views needs no simulated rotation.

Detection runs OpenCV's ``cv2.aruco.ArucoDetector`` on the ring of the donut
unrolled into a panorama strip (columns: azimuth, rows: radius), where a
marker is nearly a perspective quadrilateral; in the donut itself its edges
are arcs, and the detector's homography misreads the bits of markers seen
up close (measured: docs/landmarks.md). The corners found in the strip are
mapped back into the donut.

Pixel coordinates follow OpenCV: ``x`` the column, ``y`` the row, integer
values at pixel centres; angles are radians, counter-clockwise as the image
is displayed, 0 along +x.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_images, as_pair, check_int, check_marker_ids, check_nonneg_float
from .._progress import progress_bar
from ..groundtruth.board import DEFAULT_DICTIONARY, aruco_dictionary
from ..groundtruth.markers import as_gray

VIEW_SIZE = 120
"""Side of a marker view in pixels (thesis 5.4.1)."""
MARGIN = 50.0
"""Pixels added to every side of a marker's bounding box (thesis 5.4.1: 50 px)."""
INNER_FRACTION = 0.5
"""Default inner radius of the searched ring, as a fraction of its outer radius."""
MIN_SIDE_PX = 4.0
"""Smallest marker side (strip pixels) the detector looks for."""
MAX_VIEW_SIZE = 1024
"""Largest view side (px) an extractor accepts (a model file cannot ask for huge views)."""


def polar_angle(points: Any, center: Sequence[float]) -> np.ndarray:
    """Polar angle (rad, counter-clockwise as displayed, 0 along +x, in
    (-pi, pi]) of image points (..., 2) around ``center`` = (cx, cy) px:
    ``atan2(-(y - cy), x - cx)`` (image rows grow downwards).

    Examples
    --------
    >>> float(polar_angle([99.5, 0.0], (99.5, 99.5)))   # straight up
    1.5707963267948966
    """
    p = np.asarray(points, float)
    return np.arctan2(-(p[..., 1] - center[1]), p[..., 0] - center[0])


def upright_transform(corners: Any, center: Sequence[float], margin: float) -> tuple[np.ndarray, tuple[int, int]]:
    """The affine map (2, 3) that turns an image about ``center`` so the
    marker with ``corners`` (4, 2) px stands at the top (polar angle 90 deg)
    and shifts its bounding box plus ``margin`` px on every side to the
    origin, and that box's size (width, height) px."""
    c = np.asarray(corners, float).reshape(4, 2)
    phi = float(polar_angle(c.mean(axis=0), center))
    a = math.pi / 2 - phi  # turn counter-clockwise (as displayed) by this
    cos, sin = math.cos(a), math.sin(a)
    # x' = cx + cos (x - cx) + sin (y - cy); y' = cy - sin (x - cx) + cos (y - cy)  (y down)
    cx, cy = float(center[0]), float(center[1])
    R = np.array([[cos, sin, cx - cos * cx - sin * cy], [-sin, cos, cy + sin * cx - cos * cy]])
    turned = c @ R[:, :2].T + R[:, 2]
    lo = turned.min(axis=0) - margin
    hi = turned.max(axis=0) + margin
    R[:, 2] -= lo
    size = (max(1, int(math.ceil(hi[0] - lo[0]))), max(1, int(math.ceil(hi[1] - lo[1]))))
    return R, size


def marker_view(image: np.ndarray, corners: Any, center: Sequence[float], *, size: int = VIEW_SIZE,
                margin: float = MARGIN) -> np.ndarray:
    """One marker's view: ``image`` (H, W[, C]) turned about ``center`` by
    the marker's polar angle so the marker is upright at the top, cut to
    the marker's bounding box plus ``margin`` px on every side and resized
    to ``size`` x ``size`` px (area interpolation when shrinking, linear
    when enlarging). Same dtype and channels as ``image``; pixels beyond the
    image are black.

    Examples
    --------
    >>> img = np.zeros((200, 200), np.uint8)
    >>> corners = np.array([[150, 90], [170, 90], [170, 110], [150, 110]], float)
    >>> marker_view(img, corners, (99.5, 99.5), size=32, margin=10).shape
    (32, 32)
    """
    import cv2

    A, (w, h) = upright_transform(corners, center, float(margin))
    crop = cv2.warpAffine(np.ascontiguousarray(image), A, (w, h), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    interp = cv2.INTER_AREA if w >= size and h >= size else cv2.INTER_LINEAR
    return cv2.resize(crop, (size, size), interpolation=interp)


@dataclass
class MarkerViews:
    """The marker views of a sequence of images.

    Attributes
    ----------
    ids : tuple of int
        The markers, in the order of the second axis below.
    views : ndarray (N, k, size, size[, C]) uint8
        View of marker ``ids[j]`` in image ``i``; zeros where it was not found.
    found : ndarray (N, k) bool
        Whether marker ``ids[j]`` was detected in image ``i``.
    angles : ndarray (N, k) float
        The marker's polar angle in the image (rad; NaN where not found).
    corners : ndarray (N, k, 4, 2) float
        Its corners in the image (px; NaN where not found).

    Examples
    --------
    >>> mv = ViewExtractor([136, 144]).transform(omni_images)       # doctest: +SKIP
    >>> views_136, frames = mv.of(136)        # (n, 120, 120, 3), (n,)    # doctest: +SKIP
    >>> mv.hide(144, xy[:, 0] > 0).found.mean(axis=0)              # doctest: +SKIP
    """

    ids: tuple[int, ...]
    views: np.ndarray
    found: np.ndarray
    angles: np.ndarray
    corners: np.ndarray

    def __len__(self) -> int:
        return len(self.found)

    def index(self, marker_id: int) -> int:
        """Position of ``marker_id`` in :attr:`ids`; ValueError if it is not one of them."""
        try:
            return self.ids.index(int(marker_id))
        except ValueError:
            raise ValueError(f"marker {marker_id} is not one of these views' markers {list(self.ids)}") from None

    def detection_rate(self) -> np.ndarray:
        """Fraction of the images each marker was found in, (k,)."""
        return self.found.mean(axis=0) if len(self) else np.zeros(len(self.ids))

    def of(self, marker_id: int) -> tuple[np.ndarray, np.ndarray]:
        """The views of one marker where it was found, (n, size, size[, C]),
        and the indices of those images (n,)."""
        j = self.index(marker_id)
        idx = np.flatnonzero(self.found[:, j])
        return self.views[idx, j], idx

    def subset(self, index: Any) -> "MarkerViews":
        """The views of some images (an index or boolean mask over the images)."""
        return MarkerViews(self.ids, self.views[index], self.found[index], self.angles[index], self.corners[index])

    @classmethod
    def concatenate(cls, parts: Sequence["MarkerViews"]) -> "MarkerViews":
        """The views of several image sequences one after the other (same
        markers); ValueError for an empty list or different markers."""
        parts = list(parts)
        if not parts:
            raise ValueError("no views to concatenate")
        if any(p.ids != parts[0].ids for p in parts):
            raise ValueError(f"views of different markers: {sorted({p.ids for p in parts})}")
        return cls(parts[0].ids, *(np.concatenate([getattr(p, f) for p in parts])
                                   for f in ("views", "found", "angles", "corners")))

    def hide(self, marker_id: int, mask: Any) -> "MarkerViews":
        """A copy with ``marker_id`` treated as not found in the images of
        ``mask`` (N,) bool (zeros, NaN angles and corners there)."""
        j = self.index(marker_id)
        m = np.asarray(mask, bool)
        if m.shape != (len(self),):
            raise ValueError(f"mask must have shape ({len(self)},), got {m.shape}")
        out = MarkerViews(self.ids, self.views.copy(), self.found.copy(), self.angles.copy(), self.corners.copy())
        out.views[m, j] = 0
        out.found[m, j] = False
        out.angles[m, j] = np.nan
        out.corners[m, j] = np.nan
        return out


class ViewExtractor:
    """Finds markers in omnidirectional (donut) images and extracts their
    aligned views (thesis 5.4.1).

    Parameters
    ----------
    ids : sequence of int
        The markers to extract (ArUco ids, distinct, non-negative).
    size : int, default 120
        Side of a view in pixels (thesis: 120).
    margin : float, default 50
        Pixels added to every side of the turned marker's bounding box
        before resizing (thesis: "an additional space of 50 pixels in each
        dimension"); the background around the marker tells from which side
        it is seen.
    dictionary : str, default ``"DICT_ARUCO_ORIGINAL"``
        ``cv2.aruco`` dictionary of the markers.
    center : (cx, cy) or None
        Mirror axis in the image, px; None: the image centre
        ``((W - 1) / 2, (H - 1) / 2)``.
    ring : (inner, outer) or None
        Radii (px) of the ring searched for markers; None: from
        ``0.5 * outer`` to ``outer = min(H, W) / 2 - 1`` (the outer half of a
        donut filling the image, where a camera looking up into a convex
        mirror sees the horizon and above).
    gray : bool, default False
        Views as one channel (ITU-R 601 luma) instead of RGB.

    Examples
    --------
    >>> ex = ViewExtractor([136, 144])
    >>> mv = ex.transform(omni_images)        # (N, 1000, 1000, 3) uint8   # doctest: +SKIP
    >>> mv.views.shape, mv.detection_rate()                                # doctest: +SKIP
    ((N, 2, 120, 120, 3), array([0.97, 0.95]))
    """

    def __init__(self, ids: Sequence[int], *, size: int = VIEW_SIZE, margin: float = MARGIN,
                 dictionary: str = DEFAULT_DICTIONARY, center: Sequence[float] | None = None,
                 ring: Sequence[float] | None = None, gray: bool = False) -> None:
        self.ids = check_marker_ids(ids)
        self.size = check_int(size, "size", minimum=8)
        if self.size > MAX_VIEW_SIZE:
            raise ValueError(f"size must be at most {MAX_VIEW_SIZE} px, got {self.size}")
        self.margin = check_nonneg_float(margin, "margin")
        aruco_dictionary(dictionary)  # ValueError for an unknown name
        self.dictionary = dictionary
        self.center = None if center is None else as_pair(center, "center")
        self.ring = None if ring is None else as_pair(ring, "ring")
        if self.ring is not None and not 0 <= self.ring[0] < self.ring[1]:
            raise ValueError(f"ring must be (inner, outer) radii with 0 <= inner < outer (px), got {ring!r}")
        if not isinstance(gray, (bool, np.bool_)):
            raise TypeError(f"gray must be a bool, got {gray!r}")
        self.gray = bool(gray)
        self._strips: dict[tuple[int, int], _Strip] = {}

    def __repr__(self) -> str:
        return (f"ViewExtractor(ids={list(self.ids)}, size={self.size}, margin={self.margin:g}, "
                f"dictionary={self.dictionary!r}, center={self.center}, ring={self.ring}, gray={self.gray})")

    @property
    def channels(self) -> int:
        """Channels of a view: 1 if :attr:`gray`, else 3."""
        return 1 if self.gray else 3

    def geometry(self, shape: Sequence[int]) -> tuple[tuple[float, float], tuple[float, float]]:
        """The centre (cx, cy) and ring (inner, outer) px used for images of
        ``shape`` (H, W[, C])."""
        h, w = int(shape[0]), int(shape[1])
        center = self.center or ((w - 1) / 2, (h - 1) / 2)
        if self.ring is not None:
            return center, self.ring
        outer = min(h, w) / 2 - 1
        return center, (INNER_FRACTION * outer, outer)

    # ------------------------------------------------------------ detection
    def detect(self, image: Any) -> dict[int, np.ndarray]:
        """All markers of the dictionary in one donut image (uint8 (H, W) or
        (H, W, 3) RGB): id -> corners (4, 2) px in the image, in the
        marker's corner order (top-left, top-right, bottom-right,
        bottom-left of the marker). A marker seen twice keeps its larger
        detection."""
        gray = as_gray(image)
        strip = self._strip(gray.shape)
        found = strip.detect(gray)
        return found

    def _strip(self, shape: tuple[int, int]) -> "_Strip":
        if shape not in self._strips:
            center, ring = self.geometry(shape)
            self._strips[shape] = _Strip(center, ring, self.dictionary)
        return self._strips[shape]

    # ------------------------------------------------------------ views
    def view(self, image: Any, corners: Any) -> np.ndarray:
        """The view (size, size[, 3]) of the marker with ``corners`` (4, 2)
        px in ``image`` (uint8 (H, W) or (H, W, 3))."""
        img = np.asarray(image)
        center, _ = self.geometry(img.shape)
        if self.gray and img.ndim == 3:
            img = as_gray(img)
        return marker_view(img, corners, center, size=self.size, margin=self.margin)

    def transform(self, images: Any, *, progress: bool = False) -> MarkerViews:
        """Detects the markers in every image and extracts their views.

        Parameters
        ----------
        images : array (N, H, W[, 3]) uint8, or an iterable of such batches
            Donut images in temporal order (RGB or gray).
        progress : bool
            A progress bar.

        Returns
        -------
        MarkerViews
            Views (N, k, size, size[, 3]) with zeros where a marker was not
            found; k = len(ids).

        Raises
        ------
        ValueError
            For images that are not uint8 (H, W) / (H, W, 3) or that change size.
        """
        batches = [images] if isinstance(images, np.ndarray) else images
        if not isinstance(batches, Iterable):
            raise TypeError(f"images must be an array (N, H, W[, 3]) or an iterable of batches, "
                            f"got {type(images).__name__}")
        k, s = len(self.ids), self.size
        views, found, angles, corners = [], [], [], []
        total = len(images) if isinstance(images, np.ndarray) else None
        bar = progress_bar(progress, total, "marker views")
        shape = None
        for batch in batches:
            a = as_images(batch, "images")
            if a.dtype != np.uint8 or (a.ndim == 4 and a.shape[3] not in (1, 3)):
                raise ValueError(f"images must be uint8 (N, H, W) or (N, H, W, 3), got {a.dtype} {a.shape}")
            if shape is None:
                shape = a.shape[1:3]
            elif a.shape[1:3] != shape:
                raise ValueError(f"all images must have one size: {shape[1]}x{shape[0]} first, then "
                                 f"{a.shape[2]}x{a.shape[1]}")
            for img in a:
                v = np.zeros((k, s, s) + (() if self.gray else (3,)), np.uint8)
                f = np.zeros(k, bool)
                ang = np.full(k, np.nan)
                cor = np.full((k, 4, 2), np.nan)
                rgb = img if img.ndim == 3 and img.shape[2] == 3 else np.repeat(as_gray(img)[..., None], 3, axis=2)
                det = self.detect(rgb)
                center, _ = self.geometry(img.shape)
                for j, mid in enumerate(self.ids):
                    if mid in det:
                        f[j] = True
                        cor[j] = det[mid]
                        ang[j] = float(polar_angle(det[mid].mean(axis=0), center))
                        v[j] = self.view(rgb, det[mid])
                views.append(v)
                found.append(f)
                angles.append(ang)
                corners.append(cor)
                if bar is not None:
                    bar.update(1)
        if bar is not None:
            bar.close()
        if not views:
            raise ValueError("no images given")
        return MarkerViews(self.ids, np.stack(views), np.stack(found), np.stack(angles), np.stack(corners))

    # ------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        return {"ids": list(self.ids), "size": self.size, "margin": self.margin, "dictionary": self.dictionary,
                "center": None if self.center is None else list(self.center),
                "ring": None if self.ring is None else list(self.ring), "gray": self.gray}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "ViewExtractor":
        """An extractor from :meth:`to_dict` output; ValueError for a bad record."""
        if not isinstance(d, dict):
            raise ValueError(f"a view extractor record is a table, got {type(d).__name__}")
        unknown = set(d) - {"ids", "size", "margin", "dictionary", "center", "ring", "gray"}
        if unknown:
            raise ValueError(f"unknown view extractor keys {sorted(map(str, unknown))}")
        try:
            return cls(d["ids"], size=d["size"], margin=d["margin"], dictionary=d["dictionary"],
                       center=d.get("center"), ring=d.get("ring"), gray=d.get("gray", False))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"invalid view extractor record: {exc}") from None


class _Strip:
    """The ring of a donut unrolled into a strip for detection: column
    ``c`` looks at azimuth ``2 pi c / W`` clockwise as displayed from +x (so
    the strip reads as the scene does, not mirrored), row ``r`` at radius
    ``outer - r (outer - inner) / (H - 1)``; the first eighth of the strip is
    repeated at its end so markers on the seam are whole."""

    def __init__(self, center: tuple[float, float], ring: tuple[float, float], dictionary: str) -> None:
        import cv2

        self.center, (self.inner, self.outer) = center, ring
        self.width = max(16, int(math.ceil(2 * math.pi * self.outer)))
        self.height = max(2, int(math.ceil(self.outer - self.inner)) + 1)
        cols = np.arange(self.width + self.width // 8)
        theta = 2 * math.pi * cols / self.width
        rho = self.outer - np.arange(self.height) * (self.outer - self.inner) / (self.height - 1)
        self.map_x = (center[0] + rho[:, None] * np.cos(theta)[None]).astype(np.float32)
        self.map_y = (center[1] + rho[:, None] * np.sin(theta)[None]).astype(np.float32)
        params = cv2.aruco.DetectorParameters()
        params.minMarkerPerimeterRate = 4 * MIN_SIDE_PX / max(self.map_x.shape)
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self.detector = cv2.aruco.ArucoDetector(aruco_dictionary(dictionary), params)

    def to_image(self, pts: np.ndarray) -> np.ndarray:
        """Strip coordinates (..., 2) -> donut image coordinates (..., 2)."""
        theta = 2 * math.pi * pts[..., 0] / self.width
        rho = self.outer - pts[..., 1] * (self.outer - self.inner) / (self.height - 1)
        return np.stack([self.center[0] + rho * np.cos(theta), self.center[1] + rho * np.sin(theta)], axis=-1)

    def detect(self, gray: np.ndarray) -> dict[int, np.ndarray]:
        import cv2

        strip = cv2.remap(gray, self.map_x, self.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                          borderValue=0)
        corners, ids, _ = self.detector.detectMarkers(strip)
        out: dict[int, tuple[float, np.ndarray]] = {}
        if ids is None:
            return {}
        for c, mid in zip(corners, ids.ravel()):
            c = np.asarray(c, float).reshape(4, 2)
            d1, d2 = c[2] - c[0], c[3] - c[1]
            area = 0.5 * abs(float(d1[0] * d2[1] - d1[1] * d2[0]))
            mid = int(mid)
            if mid not in out or area > out[mid][0]:
                out[mid] = (area, c)
        return {mid: self.to_image(c) for mid, (area, c) in out.items()}
