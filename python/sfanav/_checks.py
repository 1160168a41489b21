"""Input validation for the whole public API, in one place: clear
ValueError/TypeError messages that name the argument and the problem before
any arithmetic runs or any data reaches Rust."""

from __future__ import annotations

from typing import Any

import numpy as np


class NotFittedError(ValueError, AttributeError):
    """Raised when a model is used before it is fitted (as scikit-learn's)."""


def check_is_fitted(estimator: Any, attribute: str, what: str | None = None) -> None:
    """Raises :class:`NotFittedError` unless ``estimator`` has ``attribute``
    (a trailing-underscore fitted attribute)."""
    if getattr(estimator, attribute, None) is None:
        name = what or type(estimator).__name__
        raise NotFittedError(f"this {name} is not fitted yet; call fit first")


def as_real_array(a: Any, name: str) -> np.ndarray:
    """``a`` as a NumPy array of real numbers (bool and complex refused)."""
    try:
        arr = np.asarray(a)
    except Exception as exc:  # ragged lists and the like
        raise TypeError(f"{name} must be array-like of numbers: {exc}") from None
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    return arr


def check_finite(arr: np.ndarray, name: str) -> None:
    """ValueError naming the first non-finite entry of ``arr``."""
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        where = bad[0] if len(bad) == 1 else bad
        raise ValueError(f"{name} contains NaN or infinity (at index {where})")


def as_matrix(
    a: Any,
    name: str,
    *,
    n_cols: int | None = None,
    min_rows: int = 1,
    allow_3d: bool = False,
) -> np.ndarray:
    """A finite float64 array of shape (N, d) (or (N, K, d) with ``allow_3d``)."""
    arr = as_real_array(a, name).astype(np.float64, copy=False)
    ndims = (2, 3) if allow_3d else (2,)
    if arr.ndim not in ndims:
        want = "(N, d) or (N, K, d)" if allow_3d else "(N, d)"
        raise ValueError(f"{name} must have shape {want}, got shape {arr.shape}")
    if n_cols is not None and arr.shape[-1] != n_cols:
        raise ValueError(f"{name} must have {n_cols} columns, got shape {arr.shape}")
    if arr.shape[-1] == 0:
        raise ValueError(f"{name} has no columns (shape {arr.shape})")
    if arr.shape[0] < min_rows:
        raise ValueError(f"{name} needs at least {min_rows} rows, got {arr.shape[0]}")
    check_finite(arr, name)
    return arr


def check_same_length(a: np.ndarray, b: np.ndarray, name_a: str, name_b: str) -> None:
    if len(a) != len(b):
        raise ValueError(f"{name_a} has {len(a)} rows but {name_b} has {len(b)}; they must match")


def as_images(a: Any, name: str = "images") -> np.ndarray:
    """A finite batch of images (N, H, W) or (N, H, W, C) of a real dtype
    (uint8 and float kept; other integers become float64)."""
    arr = as_real_array(a, name)
    if arr.ndim not in (3, 4):
        raise ValueError(f"{name} must have shape (N, H, W) or (N, H, W, C), got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape})")
    if min(arr.shape[1:3]) == 0 or (arr.ndim == 4 and arr.shape[3] == 0):
        raise ValueError(f"{name} has an empty image dimension (shape {arr.shape})")
    if arr.dtype != np.uint8 and arr.dtype.kind != "f":
        arr = arr.astype(np.float64)
    if arr.dtype.kind == "f":
        bad = ~np.isfinite(arr.reshape(len(arr), -1)).all(axis=1)
        if bad.any():
            raise ValueError(f"{name}: image {int(np.argmax(bad))} contains NaN or infinity")
    return arr


def check_nonneg_float(value: Any, name: str) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value) or value < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value}")
    return value


def check_positive_float(value: Any, name: str) -> float:
    value = check_nonneg_float(value, name)
    if value <= 0:
        raise ValueError(f"{name} must be > 0, got {value}")
    return value


def check_int(value: Any, name: str, *, minimum: int = 1) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if value < minimum:
        raise ValueError(f"{name} must be at least {minimum}, got {value}")
    return int(value)


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


def check_n_outputs(n: Any, available: int | None, *, what: str = "the network has", unit: str = "outputs",
                    name: str = "n_outputs") -> int | None:
    """``n`` (slow features to use) as a positive int, or None; ValueError
    when ``available`` is known and smaller (``what``: "the network has",
    "the features have")."""
    if n is None:
        return None
    n = check_int(n, name)
    if available is not None and n > available:
        raise ValueError(f"{name}={n}, but {what} only {available} {unit}")
    return n


def is_single_image(a: np.ndarray, channels: int) -> bool:
    """Whether ``a`` is one image, not a batch, for a model of ``channels``
    channels: (H, W) when gray, (H, W, C) when colour."""
    if channels == 1:
        return a.ndim == 2
    return a.ndim == 3 and a.shape[-1] == channels  # (N, H, W) is a batch of gray images


def as_image_batch(a: Any, name: str = "images") -> np.ndarray:
    """A C-contiguous batch of images (N, H, W) or (N, H, W, C) as uint8,
    float32 or float64 (other real dtypes become float64; no copy when it
    already is one of them and contiguous). TypeError for non-numeric data,
    ValueError for another number of dimensions."""
    arr = np.asarray(a)
    if arr.dtype not in (np.float32, np.float64, np.uint8):
        if arr.dtype.kind in "biuf":
            arr = arr.astype(np.float64)
        else:
            raise TypeError(f"{name} must be numeric, got dtype {arr.dtype}")
    if arr.ndim not in (3, 4):
        raise ValueError(f"{name} must have shape (N, H, W) or (N, H, W, C), got {arr.shape}")
    return np.ascontiguousarray(arr)


def check_marker_ids(ids: Any, name: str = "ids") -> tuple[int, ...]:
    """Marker ids (ArUco): a non-empty sequence of distinct integers >= 0,
    as a tuple. A comma-separated string (``"136,144"``) is read too.
    TypeError for non-integers, ValueError for an empty list, negative or
    repeated ids."""
    if isinstance(ids, str):
        parts = [p.strip() for p in ids.split(",") if p.strip()]
        try:
            ids = [int(p) for p in parts]
        except ValueError:
            raise ValueError(f"{name} must be comma-separated integers (e.g. 136,144), got {ids!r}") from None
    if isinstance(ids, (int, np.integer)) and not isinstance(ids, (bool, np.bool_)):
        ids = [ids]
    try:
        items = list(ids)
    except TypeError:
        raise TypeError(f"{name} must be a sequence of integer marker ids, got {type(ids).__name__}") from None
    out = []
    for v in items:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise TypeError(f"{name} must hold integer marker ids, got {v!r}")
        if v < 0:
            raise ValueError(f"{name}: marker ids are >= 0, got {int(v)}")
        out.append(int(v))
    if not out:
        raise ValueError(f"{name} is empty: name at least one marker id")
    if len(set(out)) != len(out):
        raise ValueError(f"{name} repeats a marker id: {out}")
    return tuple(out)


def as_pair(value: Any, name: str) -> tuple[float, float]:
    """Two finite numbers (e.g. a point (x, y) or radii (inner, outer)) as
    floats; ValueError naming ``name`` otherwise."""
    try:
        a, b = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be two numbers, got {value!r}") from None
    if not (np.isfinite(a) and np.isfinite(b)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return a, b


def as_int_array(a: Any, name: str) -> np.ndarray:
    """``a`` as a 1-D int64 array of integers (floats refused: exact counts,
    such as nanoseconds, must not pass through float64)."""
    try:
        arr = np.asarray(a)
    except Exception as exc:  # ragged lists and the like
        raise TypeError(f"{name} must be array-like of integers: {exc}") from None
    if arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must hold integers, got dtype {arr.dtype}")
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    if arr.dtype.kind == "u" and arr.size and int(arr.max()) > np.iinfo(np.int64).max:
        raise ValueError(f"{name} holds values beyond the int64 range")
    return arr.astype(np.int64, copy=False)
