"""Marks experiment rows whose figure is suspect: a readout that extrapolated
far outside its training positions, or an error so large that it is no
position error at all.

A flagged row keeps its keys and gains ``"flag"`` (why); an absurd figure
(e.g. a mean error of 4.5e13 m) moves from ``"sfanav"`` to ``"withheld"`` and
``"sfanav"`` becomes None, so tables print ``-`` with the flag as a footnote
(:func:`sfanav.experiments.format_rows`, ``scripts/render_docs.py``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

#: an error above this many area diagonals is not printed as a figure
ABSURD_DIAGONALS = 10.0


def area_diagonal(xy: Any) -> float:
    """The diagonal (m) of the bounding box of positions (N, 2)."""
    a = np.asarray(xy, dtype=np.float64)
    if a.ndim != 2 or len(a) == 0:
        raise ValueError(f"xy must be a non-empty (N, d) array, got shape {a.shape}")
    return float(np.linalg.norm(a.max(axis=0) - a.min(axis=0)))


def flag_row(row: Mapping[str, Any], *, extrapolated: int = 0, estimates: int | None = None,
             diagonal: float | None = None, factor: float = ABSURD_DIAGONALS) -> dict[str, Any]:
    """A copy of ``row`` with a ``"flag"`` when its readout extrapolated
    (``extrapolated`` estimates of ``estimates`` far outside the training
    positions) or its figure exceeds ``factor`` times the area's ``diagonal``
    (m); an absurd figure is withheld (``"sfanav"`` None, the value under
    ``"withheld"``). Rows without reason to flag come back unchanged.

    >>> flag_row({"metric": "MED (m)", "sfanav": 4.5e13}, diagonal=12.0)["sfanav"] is None
    True
    """
    out = dict(row)
    reasons = []
    if extrapolated:
        of = f" of {estimates}" if estimates else ""
        reasons.append(f"the regression readout extrapolated ({extrapolated}{of} estimates far outside the training "
                       "positions)")
    v = out.get("sfanav")
    if diagonal is not None and isinstance(v, (int, float, np.number)) and not isinstance(v, bool) \
            and not abs(float(v)) <= factor * diagonal:
        out["withheld"] = float(v)
        out["sfanav"] = None
        reasons.append(f"{float(v):.3g} exceeds {factor:g}x the area's diagonal ({diagonal:.3g} m): not a figure")
    if reasons:
        out["flag"] = "; ".join(([str(out["flag"])] if out.get("flag") else []) + reasons)
    return out
