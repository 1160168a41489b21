"""A marker board: ArUco markers at known 3-D positions on a rigid body.

The board carried by the robot is usually a box with one marker on each
visible face (:func:`box_board`); a board lying on the floor (:func:`flat_board`)
can fix the external camera's pose in the ground frame. Both are a
:class:`MarkerBoard`: marker ids and the 3-D coordinates of each marker's four
corners, saved as JSON.

Frames
------
robot frame
    x forward, y left, z up, origin on the ground below the robot's reference
    point (the point whose track is the ground truth), metres.
ground (world) frame
    x, y on the floor, z up, metres.

Corner order is OpenCV's: as seen from the front of the printed marker,
top-left, top-right, bottom-right, bottom-left.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import check_positive_float
from .._files import write_text_atomic

FORMAT = "sfanav-marker-board"
VERSION = 1
DEFAULT_DICTIONARY = "DICT_ARUCO_ORIGINAL"
FACES = ("front", "left", "back", "right", "top")

# outward normal and the marker's "up" direction of each face of an axis-aligned box
_FACE_AXES = {
    "front": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "back": ((-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "left": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "right": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "top": ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0)),
}


def aruco_dictionary(name: str) -> Any:
    """The ``cv2.aruco`` dictionary called ``name`` (e.g. ``"DICT_4X4_50"``).

    Raises
    ------
    ValueError
        If OpenCV has no such dictionary.
    """
    import cv2

    if not isinstance(name, str) or not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        known = ", ".join(n for n in ("DICT_ARUCO_ORIGINAL", "DICT_4X4_50", "DICT_5X5_100", "DICT_6X6_250",
                                      "DICT_APRILTAG_36h11"))
        raise ValueError(f"unknown ArUco dictionary {name!r} (cv2.aruco names such as {known})")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


def square_corners(center: Sequence[float], normal: Sequence[float], up: Sequence[float], size: float) -> np.ndarray:
    """The four corners (4, 3) of a square marker of side ``size`` (m)
    centred at ``center`` facing ``normal``, its top edge towards ``up``, in
    OpenCV's order (top-left, top-right, bottom-right, bottom-left as seen
    from the front).

    Raises
    ------
    ValueError
        If ``normal`` and ``up`` are zero or parallel.
    """
    c, n, u = (np.asarray(v, float).reshape(3) for v in (center, normal, up))
    if np.linalg.norm(n) == 0:
        raise ValueError("normal must not be zero")
    n = n / np.linalg.norm(n)
    u = u - n * (u @ n)
    if np.linalg.norm(u) < 1e-9:
        raise ValueError("up must not be zero or parallel to normal")
    u = u / np.linalg.norm(u)
    r = np.cross(-n, u)  # the viewer faces -n; right = facing x up
    h = size / 2
    return np.array([c - r * h + u * h, c + r * h + u * h, c + r * h - u * h, c - r * h - u * h])


@dataclass(frozen=True)
class MarkerBoard:
    """ArUco markers at known 3-D positions on one rigid body.

    Parameters
    ----------
    ids : (M,) int
        Marker ids of ``dictionary``, distinct.
    corners : (M, 4, 3) float
        Each marker's corners in the board's frame (metres), OpenCV's order.
    dictionary : str
        ``cv2.aruco`` dictionary name; the simulator's markers use
        ``DICT_ARUCO_ORIGINAL``.
    description : str
        Free text saved with the board.

    Raises
    ------
    ValueError
        On duplicate or out-of-range ids, corners of the wrong shape, not
        finite, or not a flat square-ish quadrilateral.

    Examples
    --------
    >>> board = box_board(marker_size=0.12, box_size=(0.2, 0.2, 0.2), height=0.3, ids=[1, 2, 3, 4, 5])
    >>> board.to_json("board.json")                                    # doctest: +SKIP
    >>> MarkerBoard.from_json("board.json").ids                        # doctest: +SKIP
    array([1, 2, 3, 4, 5])
    """

    ids: np.ndarray
    corners: np.ndarray
    dictionary: str = DEFAULT_DICTIONARY
    description: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        ids = np.asarray(self.ids)
        if ids.ndim != 1 or len(ids) == 0:
            raise ValueError(f"markers: a board needs at least one marker id, got ids of shape {ids.shape}")
        if ids.dtype.kind not in "iu":
            if ids.dtype.kind == "f" and np.all(np.isfinite(ids)) and np.all(ids == np.round(ids)):
                ids = ids.astype(np.int64)
            else:
                raise ValueError(f"markers: ids must be integers, got {ids.tolist()!r}")
        corners = np.asarray(self.corners, float)
        if corners.shape != (len(ids), 4, 3):
            raise ValueError(f"markers: corners must have shape ({len(ids)}, 4, 3) (4 corners x, y, z per marker), "
                             f"got {corners.shape}")
        d = aruco_dictionary(self.dictionary)
        n_ids = int(d.bytesList.shape[0])
        for i, (mid, c) in enumerate(zip(ids.tolist(), corners)):
            if not 0 <= mid < n_ids:
                raise ValueError(f"markers[{i}].id: {mid} is outside {self.dictionary} (ids 0..{n_ids - 1})")
            _check_quad(c, f"markers[{i}].corners")
        dup = sorted({m for m in ids.tolist() if ids.tolist().count(m) > 1})
        if dup:
            raise ValueError(f"markers: ids must be distinct, {dup} appear more than once")
        ids = ids.astype(np.int64)
        ids.setflags(write=False)
        corners = corners.copy()
        corners.setflags(write=False)
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "corners", corners)

    def __len__(self) -> int:
        return len(self.ids)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, MarkerBoard):
            return NotImplemented
        return (self.dictionary == other.dictionary and np.array_equal(self.ids, other.ids)
                and np.array_equal(self.corners, other.corners))

    __hash__ = None  # type: ignore[assignment]

    @property
    def marker_sizes(self) -> np.ndarray:
        """(M,) each marker's mean side length, metres."""
        sides = np.linalg.norm(self.corners - np.roll(self.corners, -1, axis=1), axis=2)
        return sides.mean(axis=1)

    def marker_corners(self, marker_id: int) -> np.ndarray:
        """The (4, 3) corners of marker ``marker_id``; KeyError if not on the board."""
        hit = np.nonzero(self.ids == int(marker_id))[0]
        if not len(hit):
            raise KeyError(f"marker {marker_id} is not on this board (ids {self.ids.tolist()})")
        return self.corners[int(hit[0])]

    def with_marker_size(self, size: float) -> "MarkerBoard":
        """The same board with every marker scaled about its own centre to
        side ``size`` (m): for prints that came out at a different size than
        the board file says. Marker centres and orientations are kept."""
        size = check_positive_float(size, "marker size")
        centers = self.corners.mean(axis=1, keepdims=True)
        scale = size / self.marker_sizes[:, None, None]
        return MarkerBoard(self.ids, centers + (self.corners - centers) * scale, self.dictionary, self.description)

    # ---------------------------------------------------------------- JSON

    def to_dict(self) -> dict[str, Any]:
        """The JSON document (a dict of plain Python values)."""
        return {
            "format": FORMAT,
            "version": VERSION,
            "dictionary": self.dictionary,
            "units": "m",
            "description": self.description,
            "markers": [{"id": int(i), "corners": [[round(float(v), 9) for v in p] for p in c]}
                        for i, c in zip(self.ids, self.corners)],
        }

    @classmethod
    def from_dict(cls, doc: Any, source: str = "board") -> "MarkerBoard":
        """A board from the JSON document ``doc``; ValueError naming the
        bad field (prefixed with ``source``)."""
        if not isinstance(doc, dict):
            raise ValueError(f"{source}: expected a JSON object, got {type(doc).__name__}")
        if doc.get("format", FORMAT) != FORMAT:
            raise ValueError(f"{source}: field 'format' is {doc.get('format')!r}, expected {FORMAT!r}")
        if "version" not in doc:
            raise ValueError(f"{source}: field 'version' is missing (expected {VERSION})")
        version = doc["version"]
        if isinstance(version, bool) or not isinstance(version, int):
            raise ValueError(f"{source}: field 'version' must be an integer, got {version!r}")
        if version != VERSION:
            raise ValueError(f"{source}: field 'version' is {version}, this sfanav reads version {VERSION}")
        units = doc.get("units", "m")
        if units != "m":
            raise ValueError(f"{source}: field 'units' must be 'm' (metres), got {units!r}")
        dictionary = doc.get("dictionary", DEFAULT_DICTIONARY)
        try:
            aruco_dictionary(dictionary)
        except ValueError as exc:
            raise ValueError(f"{source}: field 'dictionary': {exc}") from None
        markers = doc.get("markers")
        if not isinstance(markers, list) or not markers:
            raise ValueError(f"{source}: field 'markers' must be a non-empty list of {{'id', 'corners'}} objects")
        ids, corners = [], []
        for i, m in enumerate(markers):
            if not isinstance(m, dict):
                raise ValueError(f"{source}: field 'markers[{i}]' must be an object with 'id' and 'corners'")
            mid = m.get("id")
            if isinstance(mid, bool) or not isinstance(mid, int):
                raise ValueError(f"{source}: field 'markers[{i}].id' must be an integer, got {mid!r}")
            c = m.get("corners")
            try:
                arr = np.array(c, dtype=float)
            except (TypeError, ValueError):
                arr = np.zeros(0)
            if arr.shape != (4, 3):
                raise ValueError(f"{source}: field 'markers[{i}].corners' must be 4 points [x, y, z] in metres, "
                                 f"got {c!r}")
            ids.append(mid)
            corners.append(arr)
        description = doc.get("description", "")
        try:
            return cls(np.array(ids), np.array(corners), dictionary, str(description))
        except ValueError as exc:
            raise ValueError(f"{source}: field {exc}") from None

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> "MarkerBoard":
        """Reads a board file (see :meth:`to_dict` for the fields).

        Raises
        ------
        FileNotFoundError
            If ``path`` does not exist.
        ValueError
            If it is not JSON, or a field is missing or wrong (the message names it).
        """
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"no marker board file at {p}")
        try:
            doc = json.loads(p.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"marker board {p} is not JSON ({exc})") from None
        return cls.from_dict(doc, f"marker board {p}")

    def to_json(self, path: str | os.PathLike, *, overwrite: bool = True) -> None:
        """Writes the board as JSON, atomically (temporary file + rename)."""
        write_text_atomic(path, json.dumps(self.to_dict(), indent=1) + "\n", overwrite=overwrite)


def _check_quad(c: np.ndarray, name: str) -> None:
    if not np.isfinite(c).all():
        raise ValueError(f"{name}: contains NaN or infinity")
    sides = np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)
    if sides.min() <= 1e-6:
        raise ValueError(f"{name}: two corners coincide")
    if sides.max() > 1.5 * sides.min():
        raise ValueError(f"{name}: not a square marker (sides {np.round(sides, 4).tolist()} m)")
    n = np.cross(c[1] - c[0], c[3] - c[0])
    n = n / np.linalg.norm(n)
    off = np.abs((c - c.mean(axis=0)) @ n).max()
    if off > 0.02 * sides.mean():
        raise ValueError(f"{name}: the four corners are not in one plane (off by {off:.4g} m)")


def box_board(marker_size: float, box_size: float | Sequence[float], ids: Sequence[int], *,
              height: float = 0.0, center: Sequence[float] = (0.0, 0.0), faces: Sequence[str] = FACES,
              dictionary: str = DEFAULT_DICTIONARY, description: str = "") -> MarkerBoard:
    """A box with one marker in the middle of each of ``faces``, in the robot frame.

    Parameters
    ----------
    marker_size : float
        Side of each printed marker's black square, m.
    box_size : float or (length x, width y, height z)
        Outer size of the box, m.
    ids : sequence of int
        One marker id per face, in the order of ``faces``.
    height : float
        Height of the box's bottom above the ground, m.
    center : (x, y)
        Position of the box's centre in the robot frame, m (default: above the origin).
    faces : sequence of ``"front"``, ``"left"``, ``"back"``, ``"right"``, ``"top"``
        Side faces carry the marker upright (its top edge up); the top face
        carries it with its top edge pointing forward (+x).

    Raises
    ------
    ValueError
        If a marker does not fit on its face, a face name is unknown, or
        ``ids`` and ``faces`` differ in length.

    Examples
    --------
    >>> b = box_board(0.12, (0.2, 0.2, 0.15), ids=[10, 11, 12, 13, 14], height=0.25)
    >>> b.marker_corners(14)[:, 2]        # the top marker lies at z = 0.40 m
    array([0.4, 0.4, 0.4, 0.4])
    """
    s = check_positive_float(marker_size, "marker_size")
    size = np.broadcast_to(np.asarray(box_size, float), (3,)).copy()
    for v, name in zip(size, ("box length", "box width", "box height")):
        check_positive_float(float(v), name)
    if not math.isfinite(height) or height < 0:
        raise ValueError(f"height must be a finite number >= 0, got {height}")
    faces = list(faces)
    ids = [int(i) for i in ids]
    if len(ids) != len(faces):
        raise ValueError(f"need one id per face: {len(ids)} ids for faces {faces}")
    cx, cy = (float(v) for v in center)
    mid = np.array([cx, cy, height + size[2] / 2])
    corners = []
    for face in faces:
        if face not in _FACE_AXES:
            raise ValueError(f"unknown face {face!r}; faces are {', '.join(FACES)}")
        n, up = (np.array(v) for v in _FACE_AXES[face])
        axis = int(np.argmax(np.abs(n)))
        extent = [size[k] for k in range(3) if k != axis]
        if s > min(extent) + 1e-12:
            raise ValueError(f"a {s} m marker does not fit on the {face} face ({extent[0]} x {extent[1]} m)")
        corners.append(square_corners(mid + n * size[axis] / 2, n, up, s))
    return MarkerBoard(np.array(ids), np.array(corners), dictionary, description)


def flat_board(marker_size: float, centers: Sequence[Sequence[float]], ids: Sequence[int], *,
               yaw: float = 0.0, dictionary: str = DEFAULT_DICTIONARY, description: str = "") -> MarkerBoard:
    """Markers lying flat on the floor (z = 0), e.g. to fix the camera's pose.

    Parameters
    ----------
    marker_size : float
        Side of each marker, m.
    centers : (M, 2)
        Each marker's centre (x, y) in the ground frame, m.
    ids : (M,) int
    yaw : float
        Direction the markers' top edges point to, rad counter-clockwise
        from +x (the same for all).

    Examples
    --------
    >>> g = flat_board(0.2, [(0, 0), (1, 0), (0, 1)], ids=[40, 41, 42])
    >>> g.corners.shape
    (3, 4, 3)
    """
    s = check_positive_float(marker_size, "marker_size")
    c = np.asarray(centers, float)
    if c.ndim != 2 or c.shape[1] != 2:
        raise ValueError(f"centers must have shape (M, 2), got {c.shape}")
    if len(ids) != len(c):
        raise ValueError(f"need one id per centre: {len(ids)} ids for {len(c)} centres")
    up = (math.cos(yaw), math.sin(yaw), 0.0)
    corners = [square_corners((x, y, 0.0), (0, 0, 1), up, s) for x, y in c]
    return MarkerBoard(np.array([int(i) for i in ids]), np.array(corners), dictionary, description)
