"""Sub-pixel marker corners from the marker's four edges.

OpenCV's corner refinements look at the corner's neighbourhood; for the
L-shaped corner of a marker on a blurred image they are biased towards the
inside. :func:`refine_corners` instead locates the marker's outer edge at
many points along each side (the centroid of the intensity gradient across
the edge, dark inside to bright outside), fits a straight line to each side
(in undistorted pixel coordinates when the lens distortion is known) and
intersects neighbouring lines. Markers whose edges cannot be measured keep
their detected corners.
"""

from __future__ import annotations

import numpy as np

from .intrinsics import CameraIntrinsics


def _undistort(pts: np.ndarray, cam: CameraIntrinsics | None) -> np.ndarray:
    if cam is None or not np.any(cam.dist):
        return pts
    import cv2

    return cv2.undistortPoints(pts.reshape(-1, 1, 2).astype(np.float64), cam.K, cam.dist, P=cam.K).reshape(-1, 2)


def _distort(pts: np.ndarray, cam: CameraIntrinsics | None) -> np.ndarray:
    if cam is None or not np.any(cam.dist):
        return pts
    import cv2

    rays = np.linalg.solve(cam.K, np.c_[pts, np.ones(len(pts))].T).T
    return cv2.projectPoints(rays, np.zeros(3), np.zeros(3), cam.K, cam.dist)[0].reshape(-1, 2)


def _side_line(img: np.ndarray, a: np.ndarray, b: np.ndarray, centre: np.ndarray, cells: int,
               cam: CameraIntrinsics | None) -> tuple[np.ndarray, np.ndarray] | None:
    """(point, unit direction) of the line through the edge from corner a to b, or None."""
    import cv2

    length = float(np.linalg.norm(b - a))
    if length < 4:
        return None
    d = (b - a) / length
    normal = np.array([d[1], -d[0]])
    if normal @ ((a + b) / 2 - centre) < 0:
        normal = -normal  # outwards
    # stay within the black border cell inside, and sample away from the corners
    half = max(1.0, min(3.0, 0.45 * length / cells))
    offsets = np.arange(-half, half + 1e-9, 0.25)
    ts = np.linspace(0.12, 0.88, int(np.clip(length / 1.5, 6, 60)))
    pts = a[None, :] + ts[:, None] * (b - a)[None, :]
    grid = pts[:, None, :] + offsets[None, :, None] * normal[None, None, :]
    prof = cv2.remap(img, grid[..., 0].astype(np.float32), grid[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    grad = np.clip(np.diff(prof, axis=1), 0, None)
    mid = (offsets[:-1] + offsets[1:]) / 2
    weight = grad.sum(axis=1)
    contrast = prof.max(axis=1) - prof.min(axis=1)
    good = (weight > 0) & (contrast > 10)
    if good.sum() < 4:
        return None
    shift = (grad[good] * mid).sum(axis=1) / weight[good]
    edge = _undistort(pts[good] + shift[:, None] * normal, cam)
    mu = edge.mean(axis=0)
    _, sv, vt = np.linalg.svd(edge - mu, full_matrices=False)
    if sv[0] <= 0:
        return None
    return mu, vt[0]


def _intersect(l1: tuple[np.ndarray, np.ndarray], l2: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
    (p1, d1), (p2, d2) = l1, l2
    A = np.array([d1, -d2]).T
    if abs(np.linalg.det(A)) < 1e-6:
        return None
    s = np.linalg.solve(A, p2 - p1)
    return p1 + s[0] * d1


def refine_corners(image: np.ndarray, corners: np.ndarray, *, cells: int = 7,
                   intrinsics: CameraIntrinsics | None = None, iterations: int = 2) -> np.ndarray:
    """Refines marker corners by fitting lines to the markers' outer edges.

    Parameters
    ----------
    image : uint8 (H, W)
        Gray image.
    corners : (n, 4, 2) float
        Detected corners (pixels), OpenCV's order.
    cells : int
        Cells across a marker including its black border (ArUco original: 7).
    intrinsics : CameraIntrinsics, optional
        With lens distortion, lines are fitted to undistorted edge points.
    iterations : int
        Refinement rounds (each re-samples the edges at the new corners).

    Returns
    -------
    (n, 4, 2) float
        Refined corners; a marker whose edges cannot be measured, or whose
        corners would move by more than half a cell, keeps its input.
    """
    img = np.asarray(image, np.float32)
    out = np.array(corners, float, copy=True)
    for m, start in enumerate(out):
        c = start.copy()
        ok = True
        for _ in range(iterations):
            centre = c.mean(axis=0)
            lines = [_side_line(img, c[i], c[(i + 1) % 4], centre, cells, intrinsics) for i in range(4)]
            if any(line is None for line in lines):
                ok = False
                break
            new = [_intersect(lines[(i - 1) % 4], lines[i]) for i in range(4)]  # corner i joins sides i-1 and i
            if any(p is None for p in new):
                ok = False
                break
            c = _distort(np.array(new), intrinsics)
        side = np.linalg.norm(start - np.roll(start, -1, axis=0), axis=1).mean()
        if ok and np.isfinite(c).all() and np.abs(c - start).max() <= max(1.5, 0.5 * side / cells):
            out[m] = c
    return out
