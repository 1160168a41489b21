"""Evenly spaced subsets: how sfanav thins a run it cannot keep whole
(readout samples, peer queries, memories, CV subsets)."""

from __future__ import annotations

import numpy as np


def evenly_spaced(n: int, m: int) -> np.ndarray:
    """Indices of at most ``m`` evenly spaced items of ``n``, sorted, the
    first and the last included (all ``n`` if ``n <= m``).

    Example
    -------
    >>> evenly_spaced(10, 4).tolist()
    [0, 3, 6, 9]
    >>> evenly_spaced(3, 5).tolist()
    [0, 1, 2]
    """
    n, m = int(n), int(m)
    if n <= m:
        return np.arange(n)
    if m < 1:
        raise ValueError(f"at least one item must be kept, got m={m}")
    return np.unique(np.linspace(0, n - 1, m).round().astype(int))
