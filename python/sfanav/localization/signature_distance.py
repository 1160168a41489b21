"""L1 distances between appearance signatures, the cost that dominates the
signature readouts' fits and queries (:class:`SignatureGPReadout`,
:class:`SignatureKNNReadout`)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from .._resources import get_num_threads

try:  # loaded before any threadpool limit (see readouts.py)
    from scipy.spatial.distance import cdist
except ImportError:  # pragma: no cover - scipy is a dependency
    cdist = None


def l1_distances(A: np.ndarray, B: np.ndarray, chunk: int = 128, dtype: Any = np.float64) -> np.ndarray:
    """L1 (city-block) distances between the rows of ``A`` (n, q) and ``B``
    (m, q): an (n, m) array of ``dtype``.

    Blocks of ``chunk`` rows of ``A`` run on the Rust core's worker threads
    (:func:`sfanav.get_num_threads`; SciPy's ``cdist`` releases the GIL);
    memory beyond the result is one block's.

    Example
    -------
    >>> l1_distances(np.array([[0.0, 0.0]]), np.array([[1.0, 2.0], [0.0, -1.0]])).tolist()
    [[3.0, 1.0]]
    """
    out = np.empty((len(A), len(B)), dtype)

    def block(s: int) -> None:
        out[s : s + chunk] = cdist(A[s : s + chunk], B, "cityblock")

    starts = range(0, len(A), chunk)
    workers = min(get_num_threads(), len(starts))
    if workers <= 1:
        for s in starts:
            block(s)
    else:
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(block, starts))
    return out
