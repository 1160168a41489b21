"""The sfanav dataset format: its name and version, the columns of
``frames.csv`` and their units, the insect-database file names, and the
small value checks the reader and the writer share."""

from __future__ import annotations

import math
from typing import Any

FORMAT = "sfanav-dataset"


VERSION = 1


COLUMNS = ("frame", "run", "timestamp", "x", "y", "heading", "odom_x", "odom_y", "odom_heading",
           "camera", "condition", "image")


FLOAT_COLUMNS = ("timestamp", "x", "y", "heading", "odom_x", "odom_y", "odom_heading")


STR_COLUMNS = ("run", "camera", "condition", "image")


UNITS = {"timestamp": "s", "x": "m", "y": "m", "heading": "rad", "odom_x": "m", "odom_y": "m",
         "odom_heading": "rad"}


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
