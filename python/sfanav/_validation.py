"""Input checks shared by the public API: clear errors before data reaches Rust."""

from __future__ import annotations

from typing import Any

import numpy as np

FLOAT_TYPES = (np.float32, np.float64)


def as_float_2d(X: Any, name: str = "X", *, min_samples: int = 1) -> np.ndarray:
    """Returns ``X`` as a 2-D float32/float64 array without copying when it
    already is one (any strides); other real dtypes are converted to float64.

    Raises TypeError for non-numeric data and ValueError for a wrong shape.
    NaN and infinity are detected in the Rust core (ValueError naming the row
    and column).
    """
    if isinstance(X, np.ndarray):
        arr = X
    else:
        try:
            arr = np.asarray(X)
        except Exception as exc:  # ragged lists and the like
            raise TypeError(f"{name} must be array-like of numbers: {exc}") from None
    if arr.dtype.type not in FLOAT_TYPES:
        if arr.dtype.kind in "biuf":
            arr = arr.astype(np.float64)
        else:
            raise TypeError(
                f"{name} must hold real numbers (float32 or float64), got dtype {arr.dtype}"
            )
    if arr.ndim != 2:
        raise ValueError(
            f"{name} must be 2-D with shape (n_samples, n_features), got shape {arr.shape}"
        )
    if arr.shape[1] == 0:
        raise ValueError(f"{name} has no features (shape {arr.shape})")
    if arr.shape[0] < min_samples:
        raise ValueError(
            f"{name} needs at least {min_samples} sample{'s' if min_samples != 1 else ''}, "
            f"got {arr.shape[0]}"
        )
    if not arr.dtype.isnative:
        arr = arr.astype(arr.dtype.newbyteorder("="))
    return arr


def check_positive_int(value: Any, name: str, *, allow_none: bool = False) -> int | None:
    """Validates an integer hyper-parameter >= 1."""
    if value is None and allow_none:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if value < 1:
        raise ValueError(f"{name} must be at least 1, got {value}")
    return int(value)
