"""The estimated ground-truth track, one row per frame, and its CSV pose log.

The pose log has the columns :meth:`sfanav.data.Dataset.from_recording`
reads (``timestamp, x, y, heading``), then diagnostic columns it ignores.
Frames without a pose are gaps: NaN in memory, left out of the CSV (never
written as zeros); :meth:`PoseTrack.summary` counts them.
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._files import write_text_atomic

COLUMNS = ("timestamp", "x", "y", "heading")
DIAGNOSTICS = ("z", "tilt", "n_markers", "reprojection_error")
_UNITS = {"timestamp": "s", "x": "m", "y": "m", "heading": "rad", "z": "m", "tilt": "rad",
          "n_markers": "", "reprojection_error": "px"}


@dataclass
class PoseTrack:
    """Robot poses in the ground frame, one row per frame (NaN in gaps).

    Attributes
    ----------
    timestamp : (N,) float, s
    x, y : (N,) float, m
        Position of the robot frame's origin (its ground point).
    heading : (N,) float, rad
        Yaw of the robot's x axis in the ground plane, counter-clockwise
        from the ground frame's +x, in [-pi, pi).
    z : (N,) float, m
        Height of the robot's origin above the ground plane in the free
        6-DoF pose: about 0 when the camera pose, the board file and the
        floor are right (a diagnostic; the planar fit holds it at 0).
    tilt : (N,) float, rad
        Angle between the robot's z axis and the ground's in the 6-DoF pose
        (about 0 on a level floor; a diagnostic like ``z``).
    n_markers : (N,) int
        Board markers used (0 in gaps).
    reprojection_error : (N,) float, px
        RMS reprojection error of the used corners.
    n_rejected : int
        Frames with markers whose pose was rejected (reprojection error too
        large); they are gaps too.
    """

    timestamp: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    z: np.ndarray
    tilt: np.ndarray
    n_markers: np.ndarray
    reprojection_error: np.ndarray
    n_rejected: int = 0
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.timestamp)

    @property
    def valid(self) -> np.ndarray:
        """(N,) bool: frames with a pose."""
        return np.isfinite(self.x) & np.isfinite(self.y) & np.isfinite(self.heading)

    @property
    def n_gaps(self) -> int:
        return int(len(self) - self.valid.sum())

    @property
    def poses(self) -> np.ndarray:
        """(N, 3) x, y, heading (NaN rows in gaps)."""
        return np.stack([self.x, self.y, self.heading], axis=1)

    def summary(self) -> str:
        """One line: frames with a pose, gaps, rejections, median reprojection error."""
        ok = self.valid
        text = f"{int(ok.sum())} of {len(self)} frames with a pose, {self.n_gaps} gaps"
        if self.n_rejected:
            text += f" ({self.n_rejected} rejected for their reprojection error)"
        if ok.any():
            text += f"; median reprojection error {float(np.median(self.reprojection_error[ok])):.3f} px"
        return text

    def to_csv(self, path: str | os.PathLike, *, overwrite: bool = False, diagnostics: bool = True) -> int:
        """Writes the frames with a pose as a pose log, atomically (a
        temporary file in the same folder, then renamed); returns the number
        of rows. Gaps are left out (``from_recording`` interpolates across
        them; see ``n_gaps``).

        Raises
        ------
        ValueError
            If no frame has a pose.
        FileExistsError
            If ``path`` exists and ``overwrite`` is false.
        """
        ok = self.valid
        if not ok.any():
            raise ValueError(f"no frame has a pose (of {len(self)} frames); nothing to write")
        cols = list(COLUMNS) + (list(DIAGNOSTICS) if diagnostics else [])
        buf = io.StringIO()
        buf.write(",".join(cols) + "\n")
        for i in np.nonzero(ok)[0]:
            row = []
            for c in cols:
                v = getattr(self, c)[i]
                if c == "n_markers":
                    row.append(str(int(v)))
                else:  # timestamps exactly as given (they are matched to image names), the rest to 1e-6
                    row.append(repr(float(v)) if c == "timestamp" else f"{float(v):.6f}")
            buf.write(",".join(row) + "\n")
        write_text_atomic(path, buf.getvalue(), overwrite=overwrite)
        return int(ok.sum())

    @classmethod
    def from_csv(cls, path: str | os.PathLike) -> "PoseTrack":
        """Reads a pose log written by :meth:`to_csv` (diagnostic columns optional).

        Raises
        ------
        FileNotFoundError, ValueError (missing column, bad number)
        """
        import csv

        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"no pose log at {p}")
        with open(p, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
        if not rows:
            raise ValueError(f"pose log {p} has no rows")
        missing = [c for c in COLUMNS if c not in rows[0]]
        if missing:
            raise ValueError(f"pose log {p} lacks column(s) {', '.join(missing)}")
        data: dict[str, np.ndarray] = {}
        for c in COLUMNS + DIAGNOSTICS:
            if c not in rows[0]:
                data[c] = np.full(len(rows), np.nan)
                continue
            vals = []
            for ln, r in enumerate(rows, start=2):
                try:
                    vals.append(float(r[c]) if r[c] != "" else math.nan)
                except (TypeError, ValueError):
                    raise ValueError(f"pose log {p} line {ln}: column {c!r} has {r[c]!r}, not a number") from None
            data[c] = np.array(vals)
        n = np.nan_to_num(data.pop("n_markers"), nan=0).astype(np.int64)
        return cls(n_markers=n, **data)
