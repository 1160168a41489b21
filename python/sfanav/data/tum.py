"""Trajectories as TUM files (the format of the TUM RGB-D benchmark, read by
evo, rpg_trajectory_evaluation and most SLAM tools): :func:`write_tum`
writes one pose per line, ``timestamp x y z qx qy qz qw``, atomically;
:func:`read_tum` reads such a file back with its stamps exact to the
nanosecond.

sfanav's poses are planar: ``z`` is 0 and the quaternion is a rotation about
the vertical axis by the heading (counter-clockwise from +x), ``qx = qy = 0,
qz = sin(heading / 2), qw = cos(heading / 2)``. A position without a heading
(a single-image estimate) is written with the identity rotation ``0 0 0 1``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import as_matrix
from .._files import write_text_atomic

TUM_HEADER = "# timestamp x y z qx qy qz qw"
"""The comment line :func:`write_tum` starts a file with (TUM readers skip ``#`` lines)."""

_NS = 1_000_000_000


def stamp_text(ns: int) -> str:
    """An int64 stamp in nanoseconds as seconds with nine decimals, exactly
    (``1700000000123456789`` -> ``"1700000000.123456789"``, ``-1`` ->
    ``"-0.000000001"``); no float rounding on the way."""
    ns = int(ns)
    sign = "-" if ns < 0 else ""
    s, frac = divmod(abs(ns), _NS)
    return f"{sign}{s}.{frac:09d}"


def _stamps_text(stamps: Any, n: int, unit: str) -> list[str]:
    if unit not in ("ns", "s"):
        raise ValueError(f"unit must be 'ns' (int64 nanoseconds) or 's' (float seconds), got {unit!r}")
    a = np.asarray(stamps)
    if a.shape != (n,):
        raise ValueError(f"stamps must have shape ({n},) (one per pose), got {a.shape}")
    if unit == "ns":
        if a.dtype.kind not in "iu":
            raise TypeError(f"stamps in unit 'ns' must be integers (int64 nanoseconds), got dtype {a.dtype}")
        a = a.astype(np.int64)
        text = [stamp_text(v) for v in a.tolist()]
    else:
        a = np.asarray(a, dtype=np.float64)
        if not np.isfinite(a).all():
            raise ValueError(f"stamps must be finite; row {int(np.flatnonzero(~np.isfinite(a))[0])} is {a[~np.isfinite(a)][0]}")
        text = [f"{v:.9f}" for v in a.tolist()]
    bad = np.flatnonzero(np.diff(a) <= 0)
    if len(bad):
        i = int(bad[0])
        raise ValueError(f"stamps must increase strictly (a trajectory in time order); pose {i + 1} "
                         f"({text[i + 1]} s) does not come after pose {i} ({text[i]} s)")
    return text


def tum_text(stamps: Any, xy: Any, heading: Any = None, *, unit: str = "ns") -> str:
    """The TUM file :func:`write_tum` writes, as a string (header line, then
    one line per pose)."""
    p = as_matrix(xy, "xy", n_cols=2)  # finite, (N, 2)
    n = len(p)
    if heading is None:
        q = np.zeros((n, 2))
        q[:, 1] = 1.0
    else:
        h = np.asarray(heading, dtype=np.float64)
        if h.shape != (n,):
            raise ValueError(f"heading must have shape ({n},) (one per pose, radians), got {h.shape}")
        if not np.isfinite(h).all():
            raise ValueError(f"heading must be finite; row {int(np.flatnonzero(~np.isfinite(h))[0])} is not")
        q = np.column_stack([np.sin(h / 2), np.cos(h / 2)])
    ts = _stamps_text(stamps, n, unit)
    lines = [TUM_HEADER]
    lines += [f"{t} {x!r} {y!r} 0 0 0 {qz!r} {qw!r}" for t, (x, y), (qz, qw) in
              zip(ts, p.tolist(), q.tolist())]
    return "\n".join(lines) + "\n"


def write_tum(path: str | os.PathLike, stamps: Any, xy: Any, heading: Any = None, *, unit: str = "ns",
              overwrite: bool = True) -> Path:
    """Writes a planar trajectory as a TUM file, atomically (a failed write
    leaves what was there), and returns its path.

    Parameters
    ----------
    path : str or Path
        The file to write (any name; sfanav's command line uses ``NAME.tum``).
    stamps : array of shape (N,)
        The poses' times, strictly increasing: int64 nanoseconds
        (``unit="ns"``, written exactly, e.g. ``1700000000.123456789``) or
        float seconds (``unit="s"``, written with nine decimals).
    xy : array of shape (N, 2)
        Positions, metres; written with full float precision, ``z = 0``.
    heading : array of shape (N,), optional
        Radians, counter-clockwise from +x: the quaternion of a rotation
        about z by the heading. Without it every pose has the identity
        rotation (``qx qy qz qw = 0 0 0 1``).
    unit : ``"ns"`` or ``"s"``
    overwrite : bool
        Replace an existing file (default True).

    Raises
    ------
    ValueError
        Shapes that do not match, non-finite values, stamps that do not
        increase.
    TypeError
        Float stamps with ``unit="ns"``.
    FileExistsError
        ``path`` exists and ``overwrite`` is false.

    Example
    -------
    >>> write_tum("est.tum", np.array([0, 500_000_000]), [[0.0, 0.0], [1.0, 0.5]])  # doctest: +SKIP
    """
    return write_text_atomic(path, tum_text(stamps, xy, heading, unit=unit), overwrite=overwrite)


def read_tum(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reads a TUM file: ``(stamps_ns, xyz, quat)``, int64 nanoseconds (N,)
    parsed from the text exactly (decimals beyond the ninth are rounded
    down), positions (N, 3) in metres and quaternions (N, 4) as
    ``qx qy qz qw``. Lines starting with ``#`` and blank lines are skipped.
    Raises ValueError naming the line of a malformed row."""
    stamps, rows = [], []
    for k, line in enumerate(Path(path).read_text().splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        cells = s.split()
        if len(cells) != 8:
            raise ValueError(f"{path}, line {k}: a TUM row has 8 numbers (timestamp x y z qx qy qz qw), got {len(cells)}")
        try:
            stamps.append(_parse_stamp(cells[0]))
            rows.append([float(c) for c in cells[1:]])
        except ValueError:
            raise ValueError(f"{path}, line {k}: not a number in {s!r}") from None
    a = np.array(rows, dtype=np.float64).reshape(-1, 7)
    return np.array(stamps, dtype=np.int64), a[:, :3], a[:, 3:]


def _parse_stamp(text: str) -> int:
    sign = -1 if text.startswith("-") else 1
    body = text.lstrip("+-")
    whole, _, frac = body.partition(".")
    if not (whole or frac) or not (whole + frac).isdigit():
        raise ValueError(text)
    return sign * (int(whole or "0") * _NS + int((frac + "000000000")[:9]))
