"""The sfanav dataset format: its name and version, the columns of
``frames.csv`` and their units, the insect-database file names, and the
small value checks the reader and the writer share.

Times: ``timestamp`` is float seconds (every dataset has it); the optional
``stamp_ns`` column holds the same time exactly, as an integer count of
nanoseconds (int64, >= 0, written as a plain decimal integer), where the
source had exact times: ``sfanav import`` writes each image's ROS header
stamp (``sec * 10**9 + nanosec``; the record time with ``--time bag``).
A Unix time in ns does not fit float64 seconds exactly (a few hundred ns
off), so what must match the source exactly (the stamps of the estimates
``sfanav localize`` writes into a bag) uses ``stamp_ns``. The two agree to
within :data:`STAMP_TOLERANCE_S`. Datasets without the column (all before
it existed, simulated ones) still load; readers that predate it read it as
an extra integer column, so the format's version stays 1.

Gyro: the optional column ``gyro_heading`` (rad) is the robot's heading
integrated from a yaw gyro (an IMU), continuous (not wrapped) and, like the
odometry, cumulative from the run's start: the gyro's turn between two
frames of a run is the difference of their values, whichever frames are
kept (a per-frame rate or increment would change meaning when frames are
selected or dropped). Every value must be finite. The cameras of one robot
pose share it. Older readers read it as an extra column."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

FORMAT = "sfanav-dataset"


VERSION = 1


COLUMNS = ("frame", "run", "timestamp", "x", "y", "heading", "odom_x", "odom_y", "odom_heading",
           "camera", "condition", "image")


FLOAT_COLUMNS = ("timestamp", "x", "y", "heading", "odom_x", "odom_y", "odom_heading")


STR_COLUMNS = ("run", "camera", "condition", "image")


STAMP_COLUMN = "stamp_ns"
"""The optional column of exact times: int64 nanoseconds, written right after ``timestamp``."""


GYRO_COLUMN = "gyro_heading"
"""The optional column of the gyro-integrated heading: float rad, continuous."""


GYRO_UNITS = {GYRO_COLUMN: "rad"}
"""Added to ``UNITS`` in the metadata of a dataset with a gyro column."""


OPTIONAL_COLUMNS = (STAMP_COLUMN,)


UNITS = {"timestamp": "s", "x": "m", "y": "m", "heading": "rad", "odom_x": "m", "odom_y": "m",
         "odom_heading": "rad"}


STAMP_UNITS = {STAMP_COLUMN: "ns"}
"""Added to ``UNITS`` in the metadata of a dataset with exact stamps."""


STAMP_TOLERANCE_S = 1e-6
"""How far ``timestamp`` (s) may be from ``stamp_ns`` / 1e9 (plus two ulps of the timestamp)."""


INT64_MAX = 2**63 - 1


INSECT_ENTRIES = "database_entries.csv"


INSECT_METADATA = "database_metadata.yaml"


def as_size(size: Any) -> tuple[int, int]:
    try:
        w, h = (int(s) for s in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height) in pixels, got {size!r}") from None
    if w < 1 or h < 1:
        raise ValueError(f"size must be positive, got {size!r}")
    return w, h


def check_name(v: Any, what: str) -> str:
    s = str(v)
    if not s or any(c in s for c in ",\n\r\""):
        raise ValueError(f"{what} must be a non-empty name without commas, quotes or newlines, got {v!r}")
    return s


def format_float(v: float) -> str:
    return "" if not math.isfinite(v) else repr(float(v))


def format_stamp_ns(ns: Any) -> str:
    """A time in integer ns as exact seconds for a message: every digit
    kept, trailing zeros dropped (``1733000000.190123455``, ``1000.5``,
    ``1000.0``), so that two stamps 1 ns apart print apart."""
    v = int(ns)
    s, f = divmod(abs(v), 1_000_000_000)
    return f"{'-' if v < 0 else ''}{s}.{f'{f:09d}'.rstrip('0') or '0'}"


def columns_of(exact_stamps: bool) -> tuple[str, ...]:
    """The standard columns of ``frames.csv`` in order, with ``stamp_ns``
    after ``timestamp`` if there are exact stamps."""
    if not exact_stamps:
        return COLUMNS
    i = COLUMNS.index("timestamp") + 1
    return COLUMNS[:i] + (STAMP_COLUMN,) + COLUMNS[i:]


def stamps_disagree(timestamp: Any, stamp_ns: Any) -> Any:
    """Whether float seconds ``timestamp`` and integer nanoseconds ``stamp_ns``
    are not the same time (elementwise for arrays)."""
    t = np.asarray(timestamp, float)
    return np.abs(t - np.asarray(stamp_ns, np.int64) / 1e9) > STAMP_TOLERANCE_S + 2 * np.spacing(np.abs(t))

