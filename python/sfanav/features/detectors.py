"""Local visual features on panoramas: detection, description, matching.

Detectors (OpenCV's free build; SURF is patented and BRIEF lives in
opencv-contrib, neither is available, so stand-ins are named here):

* ``"fast-brief"``: FAST corners (threshold 5, non-maximum suppression),
  described by ORB's rBRIEF (256 bits, learned test pattern) at a fixed
  upright orientation, i.e. BRIEF without orientation as in the thesis;
  stands in for OpenCV-contrib's ``BriefDescriptorExtractor``.
* ``"orb"``: ORB (oriented FAST + rotated BRIEF), multi-scale.
* ``"sift"``: SIFT, oriented; stands in for SURF (a scale-space blob
  detector with a gradient-histogram descriptor, like SURF).
* ``"sift-upright"``: SIFT keypoints described at orientation 0; stands in
  for upright SURF.

A panorama wraps around horizontally: images are padded (wrapped left and
right, mirrored top and bottom) before detection and description, so
features near the seam or the top and bottom rows are kept, and distances
between keypoints wrap around the width (:func:`pixel_distance`).

>>> import numpy as np
>>> img = (np.random.default_rng(0).random((60, 300)) * 255).astype(np.uint8)
>>> f = detect(img, "fast-brief", 100)
>>> len(f) <= 100, f.descriptors.shape[1]
(True, 32)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: detector names, see the module docstring
DETECTORS = ("fast-brief", "orb", "sift", "sift-upright")
#: pixels added on every side before detection and description
PAD = 40


@dataclass
class Features:
    """Keypoints of one image with their descriptors.

    Attributes
    ----------
    xy : ndarray (n, 2) float
        Keypoint positions (x = column, y = row, pixels) in the image.
    response : ndarray (n,) float
        Detector response (larger: stronger).
    size : ndarray (n,) float
        Keypoint diameter (pixels).
    descriptors : ndarray (n, d)
        uint8 bytes of a binary descriptor or float32 of a real one.
    binary : bool
        Hamming (True) or Euclidean (False) descriptor distance.
    width : int
        Image width (pixels), for distances that wrap around a panorama.
    """

    xy: np.ndarray
    response: np.ndarray
    size: np.ndarray
    descriptors: np.ndarray
    binary: bool
    width: int

    def __len__(self) -> int:
        return len(self.xy)

    def subset(self, idx: Any) -> "Features":
        """The features at indices ``idx`` (in that order)."""
        idx = np.asarray(idx, dtype=np.intp)
        return Features(self.xy[idx], self.response[idx], self.size[idx], self.descriptors[idx], self.binary,
                        self.width)

    def strongest(self, k: int) -> "Features":
        """The ``k`` features of largest detector response (all if fewer)."""
        return self.subset(np.argsort(-self.response, kind="stable")[: max(int(k), 0)])


def as_gray(image: Any) -> np.ndarray:
    """A uint8 gray image (H, W) from a gray (H, W) or RGB (H, W, 3) image.

    Raises
    ------
    TypeError
        Not an array of numbers.
    ValueError
        Another shape, or smaller than 8x8 pixels.
    """
    import cv2

    a = np.asarray(image)
    if a.dtype.kind not in "uif" or a.dtype == bool:
        raise TypeError(f"image must be an array of numbers, got dtype {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 3:
        a = cv2.cvtColor(as_uint8(a), cv2.COLOR_RGB2GRAY)
    elif a.ndim != 2:
        raise ValueError(f"image must be gray (H, W) or RGB (H, W, 3), got shape {a.shape}")
    if min(a.shape) < 8:
        raise ValueError(f"image must be at least 8x8 pixels, got {a.shape[1]}x{a.shape[0]}")
    return as_uint8(a)


def as_uint8(a: np.ndarray) -> np.ndarray:
    """``a`` as uint8 pixels: floats with a maximum <= 1 scaled by 255,
    rounded and clipped to 0..255; ValueError for non-finite pixels."""
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    if a.dtype.kind == "f":
        if not np.all(np.isfinite(a)):
            raise ValueError("image has non-finite pixels")
        if a.max(initial=0) <= 1.0:
            a = a * 255.0
    return np.clip(np.rint(a), 0, 255).astype(np.uint8)


def pad_panorama(image: np.ndarray, pad: int = PAD) -> np.ndarray:
    """``image`` wrapped left and right and mirrored top and bottom by ``pad`` pixels."""
    import cv2

    wrapped = np.concatenate([image[:, -pad:], image, image[:, :pad]], axis=1)
    return cv2.copyMakeBorder(wrapped, pad, pad, 0, 0, cv2.BORDER_REFLECT_101)


def _engine(detector: str, n: int) -> tuple[Any, Any, bool]:
    import cv2

    if detector == "fast-brief":
        return cv2.FastFeatureDetector_create(5, True), cv2.ORB_create(edgeThreshold=31, patchSize=31), True
    if detector == "orb":
        orb = cv2.ORB_create(nfeatures=int(n * 1.3) + 10, edgeThreshold=31, patchSize=31, fastThreshold=5)
        return orb, orb, True
    if detector in ("sift", "sift-upright"):
        sift = cv2.SIFT_create(contrastThreshold=0.015)
        return sift, sift, False
    raise ValueError(f"unknown detector {detector!r}; known: {', '.join(DETECTORS)}")


def detect(image: Any, detector: str = "fast-brief", n: int = 1000) -> Features:
    """Detects and describes up to ``n`` keypoints of largest response.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, 3)
        Gray or RGB panorama (uint8, or floats in [0, 1] or [0, 255]).
    detector : str
        One of :data:`DETECTORS`.
    n : int
        Most keypoints to keep (>= 1).

    Returns
    -------
    Features
        Sorted by decreasing response.

    Raises
    ------
    ValueError
        An unknown detector, ``n`` < 1, a bad image shape.
    TypeError
        A non-numeric image.
    """
    from .._checks import check_int

    n = check_int(n, "n", minimum=1)
    gray = as_gray(image)
    det, desc, binary = _engine(detector, n)
    h, w = gray.shape
    padded = pad_panorama(gray)
    kps = det.detect(padded, None)
    inside = [k for k in kps if PAD <= k.pt[0] < PAD + w and PAD <= k.pt[1] < PAD + h]
    if detector in ("fast-brief", "sift-upright"):
        uniq: dict[tuple[float, float, float], Any] = {}
        for k in inside:
            key = (round(k.pt[0], 2), round(k.pt[1], 2), round(k.size, 2))
            if key not in uniq or k.response > uniq[key].response:
                uniq[key] = k
        inside = list(uniq.values())
        for k in inside:
            k.angle = 0.0
    inside.sort(key=lambda k: -k.response)
    inside = inside[:n]
    for i, k in enumerate(inside):
        k.class_id = i
    d = 32 if binary else 128
    if not inside:
        return Features(np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                        np.zeros((0, d), np.uint8 if binary else np.float32), binary, w)
    kept, des = desc.compute(padded, inside)
    kept = list(kept) if kept is not None else []
    if des is None or not kept:
        des = np.zeros((0, d), np.uint8 if binary else np.float32)
        kept = []
    xy = np.array([[k.pt[0] - PAD, k.pt[1] - PAD] for k in kept], float).reshape(-1, 2)
    resp = np.array([k.response for k in kept], float)
    size = np.array([k.size for k in kept], float)
    order = np.argsort(-resp, kind="stable")
    return Features(xy[order], resp[order], size[order], np.asarray(des)[order], binary, w)


def pixel_distance(a: np.ndarray, b: np.ndarray, width: int | None = None) -> np.ndarray:
    """Euclidean distance (pixels) between points ``a`` and ``b`` (n, 2),
    the x difference wrapped around a panorama of ``width`` pixels."""
    d = np.abs(np.asarray(a, float) - np.asarray(b, float))
    if width:
        d[..., 0] = np.minimum(d[..., 0], width - d[..., 0])
    return np.hypot(d[..., 0], d[..., 1])


def descriptor_distances(a: Features, b: Features) -> np.ndarray:
    """Descriptor distances (len(a), len(b)) float32: Hamming for binary
    descriptors, Euclidean for real ones. Raises ValueError for features of
    different detectors."""
    if a.binary != b.binary or a.descriptors.shape[1:] != b.descriptors.shape[1:]:
        raise ValueError("features to match must come from the same detector")
    if a.binary:
        x = np.unpackbits(a.descriptors.astype(np.uint8), axis=1).astype(np.float32)
        y = np.unpackbits(b.descriptors.astype(np.uint8), axis=1).astype(np.float32)
        return x @ (1 - y).T + (1 - x) @ y.T
    x = a.descriptors.astype(np.float32)
    y = b.descriptors.astype(np.float32)
    d2 = (x * x).sum(1)[:, None] + (y * y).sum(1)[None, :] - 2 * x @ y.T
    return np.sqrt(np.maximum(d2, 0))


def match(reference: Features, query: Features, *, cross_check: bool = True,
          ratio: float | None = None) -> np.ndarray:
    """Nearest-neighbour matches from ``reference`` to ``query`` in
    descriptor space (Hamming or Euclidean distance).

    Parameters
    ----------
    cross_check : bool
        Keep a match only if each feature is the other's nearest neighbour
        (mutual consistency check).
    ratio : float in (0, 1], optional
        Distance ratio test: keep a match only if the nearest distance is
        below ``ratio`` times the second nearest.

    Returns
    -------
    ndarray (m, 2) int
        Index pairs (reference, query).
    """
    if len(reference) == 0 or len(query) == 0:
        return np.zeros((0, 2), np.intp)
    return match_distances(descriptor_distances(reference, query), cross_check=cross_check, ratio=ratio)


def match_distances(D: np.ndarray, *, cross_check: bool = True, ratio: float | None = None) -> np.ndarray:
    """:func:`match` on a precomputed distance matrix ``D`` (n_reference,
    n_query), e.g. a block of one :func:`descriptor_distances` matrix
    shared by several subsets of the same features. Returns (m, 2) index
    pairs into ``D``'s rows and columns."""
    D = np.asarray(D)
    if D.ndim != 2:
        raise ValueError(f"D must be a 2-D distance matrix, got shape {D.shape}")
    if D.shape[0] == 0 or D.shape[1] == 0:
        return np.zeros((0, 2), np.intp)
    j = np.argmin(D, axis=1)
    i = np.arange(D.shape[0])
    keep = np.ones(D.shape[0], bool)
    if cross_check:
        keep &= np.argmin(D, axis=0)[j] == i
    if ratio is not None:
        if D.shape[1] < 2:
            keep[:] = False
        else:
            two = np.partition(D, 1, axis=1)[:, :2]
            keep &= two[:, 0] < ratio * two[:, 1]
    return np.stack([i[keep], j[keep]], axis=1)


def true_match(reference: Features, query: Features, pairs: np.ndarray, threshold: float) -> np.ndarray:
    """Whether each match of ``pairs`` (m, 2) joins keypoints at most
    ``threshold`` pixels apart (same viewpoint: a true correspondence)."""
    pairs = np.asarray(pairs, np.intp).reshape(-1, 2)
    if len(pairs) == 0:
        return np.zeros(0, bool)
    return pixel_distance(reference.xy[pairs[:, 0]], query.xy[pairs[:, 1]], reference.width) <= threshold
