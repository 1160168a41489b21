"""Reading and writing single images (OpenCV), RGB in memory, optionally
converted to gray or resized on read."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .schema import as_size


def _cv2() -> Any:
    try:
        import cv2
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ImportError("reading and writing images needs OpenCV (pip install opencv-python-headless)") from exc
    return cv2


_QUIET = threading.Lock()
_quiet_state = {"depth": 0, "saved": -1}


@contextlib.contextmanager
def quiet_codecs() -> Iterator[None]:
    """Silences what OpenCV's image codecs print straight to the process's
    stderr while decoding (libjpeg's "Corrupt JPEG data: ...", libpng's
    "libpng error: ...", OpenCV's own "[ WARN ]" and "[ERROR]" lines): the
    caller reports a failed decode in one line of its own. File descriptor 2
    points at /dev/null while any thread is inside (Python's pending stderr
    output is flushed first; what another thread writes to the process's
    stderr meanwhile is lost, a decode's few milliseconds); nested and
    concurrent uses share one redirection, undone when the last one leaves."""
    with _QUIET:
        if _quiet_state["depth"] == 0:
            try:
                sys.stderr.flush()
                saved = os.dup(2)
            except (OSError, ValueError, AttributeError):  # no usable stderr: nothing to silence
                saved = -1
            if saved >= 0:
                null = os.open(os.devnull, os.O_WRONLY)
                try:
                    os.dup2(null, 2)
                finally:
                    os.close(null)
            _quiet_state["saved"] = saved
        _quiet_state["depth"] += 1
    try:
        yield
    finally:
        with _QUIET:
            _quiet_state["depth"] -= 1
            if _quiet_state["depth"] == 0 and _quiet_state["saved"] >= 0:
                os.dup2(_quiet_state["saved"], 2)
                os.close(_quiet_state["saved"])
                _quiet_state["saved"] = -1


def read_image(path: str | os.PathLike, gray: bool = False, size: tuple[int, int] | None = None) -> np.ndarray:
    """Reads an image as uint8 RGB (H, W, 3) or gray (H, W).

    Parameters
    ----------
    gray : bool
        Convert to gray (ITU-R 601 luma).
    size : (width, height), optional
        Resize (area interpolation).
    """
    cv2 = _cv2()
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"image file {path} does not exist")
    with quiet_codecs():
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"cannot read image {path} (not an image OpenCV can decode)")
    if img.dtype != np.uint8:
        img = (img / (256 if img.dtype == np.uint16 else 1)).clip(0, 255).astype(np.uint8)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB if img.shape[2] == 4 else cv2.COLOR_BGR2RGB)
        if gray:
            img = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    if size is not None:
        w, h = as_size(size)
        img = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
    return img


def write_image(path: str | os.PathLike, image: np.ndarray) -> None:
    """Writes a uint8 RGB (H, W, 3) or gray (H, W) image (PNG by extension)."""
    cv2 = _cv2()
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise TypeError(f"images must be uint8, got {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    elif img.ndim != 2:
        raise ValueError(f"an image must be (H, W) gray or (H, W, 3) RGB, got shape {img.shape}")
    if not cv2.imwrite(str(path), img, [cv2.IMWRITE_PNG_COMPRESSION, 1]):
        raise OSError(f"could not write image {path}")


def encode_png(image: np.ndarray) -> bytes:
    """A uint8 RGB (H, W, 3) or gray (H, W) image as PNG file bytes (the
    fast compression :func:`write_image` uses)."""
    cv2 = _cv2()
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise TypeError(f"images must be uint8, got {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    elif img.ndim != 2:
        raise ValueError(f"an image must be (H, W) gray or (H, W, 3) RGB, got shape {img.shape}")
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise ValueError(f"could not encode a {img.shape} image as PNG")
    return buf.tobytes()


def truncation(data: bytes) -> str | None:
    """Why the PNG or JPEG file ``data`` is cut short, or None if it is
    complete or neither format (checked on its structure, without decoding:
    OpenCV's decoders either fail on a cut file with a message of their own
    on stderr, or, in some versions, return the decoded part as if whole).

    A JPEG is complete when an end-of-image marker follows its last
    start-of-scan marker (the coded data cannot hold one), a PNG when its
    chunks run to an ``IEND`` chunk; bytes after either are allowed.
    """
    if data.startswith(b"\xff\xd8\xff"):
        sos = data.rfind(b"\xff\xda")
        if sos < 0:
            return "the JPEG data ends before its image data (truncated?)"
        if data.rfind(b"\xff\xd9") < sos:
            return "the JPEG data ends without its end-of-image marker (truncated)"
        return None
    if data.startswith(b"\x89PNG\r\n\x1a\n"):
        pos, n = 8, len(data)
        while pos + 8 <= n:
            end = pos + 12 + int.from_bytes(data[pos : pos + 4], "big")
            kind = data[pos + 4 : pos + 8]
            if end > n:
                return f"the PNG data ends inside its {kind.decode('latin-1')!r} chunk (truncated)"
            if kind == b"IEND":
                return None
            pos = end
        return "the PNG data ends before its IEND chunk (truncated)"
    return None


def damage(data: bytes) -> str | None:
    """Why the PNG or JPEG file ``data`` cannot be whole: cut short
    (:func:`truncation`), or, for a PNG, a chunk whose CRC-32 does not match
    its bytes (a bit flipped in storage or transfer); None otherwise.
    Checked before OpenCV sees the data, whose PNG decoder prints libpng's
    complaints on stderr. A JPEG has no checksum: bits flipped inside its
    coded data decode to a wrong picture, unnoticed."""
    cut = truncation(data)
    if cut is not None or not data.startswith(b"\x89PNG\r\n\x1a\n"):
        return cut
    pos = 8
    while True:  # truncation() found the chunks to run whole up to IEND
        length = int.from_bytes(data[pos : pos + 4], "big")
        end = pos + 12 + length
        kind = data[pos + 4 : pos + 8]
        if zlib.crc32(data[pos + 4 : end - 4]) != int.from_bytes(data[end - 4 : end], "big"):
            return f"the PNG's {kind.decode('latin-1')!r} chunk at byte {pos} fails its CRC-32 (damaged data)"
        if kind == b"IEND":
            return None
        pos = end
