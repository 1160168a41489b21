"""Synthetic perspective images of marker boards and chessboards for the
ground-truth tests: each flat quad (a marker, a box face, a chessboard) is
warped by the exact homography of its projected 3-D corners onto a
supersampled canvas, which is then averaged down (area interpolation)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from sfanav.groundtruth import CameraIntrinsics, CameraPose, MarkerBoard

SUPERSAMPLE = 4


def marker_texture(marker_id: int, dictionary: str, *, margin_cells: float = 1.0, cell_px: int = 32) -> np.ndarray:
    """The marker's image with a white quiet zone of ``margin_cells`` cells (uint8)."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    cells = d.markerSize + 2
    img = cv2.aruco.generateImageMarker(d, int(marker_id), cells * cell_px)
    m = int(round(margin_cells * cell_px))
    return cv2.copyMakeBorder(img, m, m, m, m, cv2.BORDER_CONSTANT, value=255)


def background(size: tuple[int, int], seed: int = 0) -> np.ndarray:
    """A grey, textured floor (uint8 (h, w))."""
    w, h = size
    rng = np.random.default_rng(seed)
    noise = rng.normal(0, 1, (h // 8 + 1, w // 8 + 1)).astype(np.float32)
    noise = cv2.resize(cv2.GaussianBlur(noise, (0, 0), 2), (w, h), interpolation=cv2.INTER_CUBIC)
    return np.clip(110 + 25 * noise / (noise.std() + 1e-9), 0, 255).astype(np.uint8)


class Canvas:
    """A supersampled image onto which 3-D quads are drawn."""

    def __init__(self, intrinsics: CameraIntrinsics, camera: CameraPose, base: np.ndarray, ss: int = SUPERSAMPLE):
        self.ss = ss
        self.size = intrinsics.image_size
        K = intrinsics.K.copy()
        K[:2, :2] *= ss
        K[:2, 2] = K[:2, 2] * ss + (ss - 1) / 2
        self.K = K
        self.R, self.t = camera.rotation, camera.tvec
        w, h = self.size
        self.img = cv2.resize(base, (w * ss, h * ss), interpolation=cv2.INTER_NEAREST)

    def project(self, X: np.ndarray) -> np.ndarray | None:
        Xc = X @ self.R.T + self.t
        if (Xc[:, 2] <= 0.05).any():
            return None
        uv = Xc[:, :2] / Xc[:, 2:3]
        return uv @ self.K[:2, :2].T + self.K[:2, 2]

    def facing(self, corners: np.ndarray) -> bool:
        n = np.cross(corners[3] - corners[0], corners[1] - corners[0])  # front normal of a TL, TR, BR, BL quad
        cam = -self.R.T @ self.t
        return float(n @ (cam - corners.mean(axis=0))) > 0

    def quad(self, corners: np.ndarray, texture: np.ndarray) -> None:
        """Draws ``texture`` onto the 3-D quad ``corners`` (4, 3) (TL, TR, BR, BL)."""
        dst = self.project(np.asarray(corners, float))
        if dst is None:
            return
        H_, W_ = self.img.shape
        x0, y0 = np.floor(dst.min(axis=0)).astype(int) - 2
        x1, y1 = np.ceil(dst.max(axis=0)).astype(int) + 2
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, W_), min(y1, H_)
        if x1 <= x0 or y1 <= y0:
            return
        th, tw = texture.shape[:2]
        src = np.array([[-0.5, -0.5], [tw - 0.5, -0.5], [tw - 0.5, th - 0.5], [-0.5, th - 0.5]], np.float32)
        H = cv2.getPerspectiveTransform(src, (dst - [x0, y0]).astype(np.float32))
        roi = self.img[y0:y1, x0:x1]
        cv2.warpPerspective(texture, H, (x1 - x0, y1 - y0), dst=roi, flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_TRANSPARENT)

    def image(self, *, blur: float = 0.5, noise: float = 1.5, seed: int = 0) -> np.ndarray:
        w, h = self.size
        out = cv2.resize(self.img, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32)
        if blur:
            out = cv2.GaussianBlur(out, (0, 0), blur)
        if noise:
            out += np.random.default_rng(seed).normal(0, noise, out.shape).astype(np.float32)
        return np.clip(np.round(out), 0, 255).astype(np.uint8)


def robot_to_ground(x: float, y: float, heading: float) -> tuple[np.ndarray, np.ndarray]:
    c, s = math.cos(heading), math.sin(heading)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), np.array([x, y, 0.0])


def box_faces(board: MarkerBoard, margin: float = 0.02) -> list[np.ndarray]:
    """White squares behind each marker, ``margin`` m wider on each side (the quiet zone)."""
    out = []
    for c in board.corners:
        m = c.mean(axis=0)
        s = np.linalg.norm(c[1] - c[0])
        out.append(m + (c - m) * (s + 2 * margin) / s)
    return out


def render(intrinsics: CameraIntrinsics, camera: CameraPose, board: MarkerBoard | None, pose=(0.0, 0.0, 0.0), *,
           ground: MarkerBoard | None = None, seed: int = 0, noise: float = 1.5, blur: float = 0.5) -> np.ndarray:
    """A gray image of ``board`` (robot frame) at robot ``pose`` (x, y, heading) and
    of ``ground`` (ground frame), as seen by ``camera``; ``board=None`` hides the robot."""
    canvas = Canvas(intrinsics, camera, background(intrinsics.image_size, seed))
    white = np.full((8, 8), 235, np.uint8)
    for b, (R, t) in ((ground, (np.eye(3), np.zeros(3))), (board, robot_to_ground(*pose))):
        if b is None:
            continue
        for mid, c, face in zip(b.ids, b.corners, box_faces(b, 0.25 * b.marker_sizes.mean())):
            cw, fw = c @ R.T + t, face @ R.T + t
            if not canvas.facing(cw):
                continue
            canvas.quad(fw, white)
            canvas.quad(cw, marker_texture(int(mid), b.dictionary, margin_cells=0))
    return canvas.image(blur=blur, noise=noise, seed=seed + 1)


def chessboard_texture(cols: int, rows: int, square_px: int = 40) -> np.ndarray:
    """A chessboard of ``cols`` x ``rows`` squares with a white border of one square."""
    sq = (np.indices((rows, cols)).sum(axis=0) % 2 == 0).astype(np.uint8) * 255
    img = np.kron(255 - sq, np.ones((square_px, square_px), np.uint8))
    return cv2.copyMakeBorder(img, square_px, square_px, square_px, square_px, cv2.BORDER_CONSTANT, value=255)


def render_chessboard(intrinsics: CameraIntrinsics, inner: tuple[int, int], square: float, rvec, tvec, *,
                      seed: int = 0) -> np.ndarray:
    """A chessboard with ``inner`` = (cols, rows) inner corners and squares
    of ``square`` m, at board pose (rvec, tvec) in the camera frame; its
    first inner corner at the board origin, x along the columns."""
    cols, rows = inner[0] + 1, inner[1] + 1
    tex = chessboard_texture(cols, rows)
    # the textured quad spans one extra square of white border on each side
    x0, y0, x1, y1 = -2 * square, -2 * square, (cols) * square, (rows) * square
    corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], float)
    cam = CameraPose(rvec, tvec)
    canvas = Canvas(intrinsics, cam, background(intrinsics.image_size, seed))
    canvas.quad(corners, tex)
    return canvas.image(seed=seed + 1)


def render_charuco(intrinsics: CameraIntrinsics, board, rvec, tvec, *, seed: int = 0, px: int = 60) -> np.ndarray:
    """A ChArUco board (``cv2.aruco.CharucoBoard``) at board pose (rvec, tvec)
    in the camera frame; board coordinates as OpenCV's (origin at the
    image's top-left corner, x right, y down, z = 0)."""
    cols, rows = board.getChessboardSize()
    sq = board.getSquareLength()
    tex = board.generateImage((cols * px, rows * px), marginSize=0, borderBits=1)
    x1, y1 = cols * sq, rows * sq
    corners = np.array([[0, 0, 0], [x1, 0, 0], [x1, y1, 0], [0, y1, 0]], float)
    canvas = Canvas(intrinsics, CameraPose(rvec, tvec), background(intrinsics.image_size, seed))
    # a white margin of one square around the board
    canvas.quad(np.array([[-sq, -sq, 0], [x1 + sq, -sq, 0], [x1 + sq, y1 + sq, 0], [-sq, y1 + sq, 0]]),
                np.full((8, 8), 255, np.uint8))
    canvas.quad(corners, tex)
    return canvas.image(seed=seed + 1)
