"""Appearance-based localization baselines to compare the SFA localizer with.

* :class:`PerfectMemory`: store every training view; a query takes the
  position of the stored view that matches best over all rotations, by the
  rotational image difference function (RIDF; Zeil, Hofmann and Chahl 2003:
  RMS pixel difference between the query and the stored view rolled by every
  column shift). Computed for all shifts at once by FFT-based circular
  cross-correlation.
* :class:`FourierSignature`: Menegatti, Maeda and Ishiguro 2004: per image row
  the magnitudes of the first ``k`` coefficients of the DFT along the azimuth
  (rotation invariant: a rotation only changes the phases); nearest
  neighbour by L1 distance.

Both take panoramas (N, H, W[, C]) whose columns span 360 degrees and
positions (N, 2) in metres, with scikit-learn-like ``fit(images, xy)`` /
``predict(images)``, and report ``bytes_per_place_`` (memory per stored
place) for tables of error vs memory vs query time (:func:`benchmark`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .._checks import NotFittedError, as_images, as_matrix, check_int, check_same_length
from .error_metrics import euclidean_errors, localization_metrics


def _as_rows(images: Any, name: str, normalize: bool) -> np.ndarray:
    """Images (N, H, W[, C]) -> float32 (N, H * C, W): channels become extra
    rows, so a rotation is a roll along the last axis."""
    a = as_images(images, name)
    if a.ndim == 4:
        a = np.moveaxis(a, 3, 2)  # (N, H, C, W)
    out = a.reshape(len(a), -1, a.shape[-1]).astype(np.float32)
    if normalize:
        flat = out.reshape(len(out), -1)
        mean = flat.mean(axis=1, dtype=np.float64)
        std = flat.std(axis=1, dtype=np.float64)
        std[std == 0] = 1.0
        out = ((flat - mean[:, None]) / std[:, None]).astype(np.float32).reshape(out.shape)
    return out


def fourier_signature(images: Any, n_coefficients: int = 15) -> np.ndarray:
    """The Fourier signature of panoramas (N, H, W[, C]): per image row and
    channel the magnitudes of the first ``n_coefficients`` DFT coefficients
    along the azimuth (DC included), flattened to (N, H * C *
    n_coefficients) float32. A rotation of the panorama only changes the
    phases, so the signature does not depend on the heading.

    Raises ValueError for more coefficients than ``W // 2 + 1``.

    >>> fourier_signature(np.zeros((2, 4, 16)), 3).shape
    (2, 12)
    """
    k = check_int(n_coefficients, "n_coefficients")
    rows = _as_rows(images, "images", False)
    if k > rows.shape[2] // 2 + 1:
        raise ValueError(f"n_coefficients={k}, but {rows.shape[2]}-px wide panoramas have only {rows.shape[2] // 2 + 1}")
    return np.abs(np.fft.rfft(rows, axis=2)[:, :, :k]).astype(np.float32).reshape(len(rows), -1)


class _Memory:
    """Shared fit/validation of the view-based baselines."""

    normalize: bool

    def _fit_common(self, images: Any, xy: Any) -> np.ndarray:
        imgs = as_images(images)
        Y = as_matrix(xy, "xy", n_cols=2)
        check_same_length(imgs, Y, "images", "xy")
        self.xy_ = Y.copy()
        self.image_shape_ = imgs.shape[1:]
        self.n_places_ = len(imgs)
        self._itemsize = imgs.dtype.itemsize
        return _as_rows(imgs, "images", self.normalize)

    def _check_query(self, images: Any) -> np.ndarray:
        if not hasattr(self, "xy_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call fit first")
        a = as_images(images)
        if a.shape[1:] != self.image_shape_:
            raise ValueError(f"query images have shape {a.shape[1:]}, but the stored views are {self.image_shape_}")
        return _as_rows(a, "images", self.normalize)

    def predict(self, images: Any) -> np.ndarray:
        """Positions (N, 2) in metres: those of the best-matching stored views."""
        idx = self.match(images)[0]  # checks fitted first
        return self.xy_[idx]

    def score(self, images: Any, xy: Any) -> float:
        """Mean Euclidean distance (MED, metres); lower is better."""
        return float(euclidean_errors(self.predict(images), xy).mean())

    def match(self, images: Any) -> tuple[np.ndarray, ...]:  # pragma: no cover - overridden
        raise NotImplementedError


class PerfectMemory(_Memory):
    """Perfect memory with the rotational image difference function (Zeil et
    al. 2003).

    Every training view is stored. For a query, ``RIDF_i(d) = sqrt(mean((q -
    roll(v_i, d, axis=width))^2))`` over all stored views ``v_i`` and all
    column shifts ``d``; the estimate is the position of the minimising view.
    All shifts come from one FFT-based circular cross-correlation per pair,
    batched as a complex matrix product per frequency.

    Parameters
    ----------
    normalize : bool, default False
        Zero mean and unit variance per image before comparing (robustness to
        global brightness; the original compares raw pixels).
    chunk_bytes : int, default 2**28
        Working memory per query chunk.

    Attributes
    ----------
    xy_ : ndarray (n_places, 2)
        Stored positions, metres.
    bytes_per_place_ : int
        Memory per stored place: the view as given (H x W x C x itemsize of
        the input dtype, e.g. 1 byte per pixel for uint8) plus its position.
    cache_bytes_ : int
        Extra memory of the precomputed spectra (a speed-up, not part of the
        method): H x C x (W // 2 + 1) x 8 bytes per place, about 4x a uint8
        view (e.g. 2.5 GB for 5900 RGB 600x60 views).
    """

    def __init__(self, normalize: bool = False, chunk_bytes: int = 2**28) -> None:
        self.normalize = normalize
        self.chunk_bytes = chunk_bytes

    def __repr__(self) -> str:
        return f"PerfectMemory(normalize={self.normalize!r})"

    def fit(self, images: Any, xy: Any) -> "PerfectMemory":
        """Stores the views (N, H, W[, C]) and their positions (N, 2), metres."""
        imgs = as_images(images)
        Y = as_matrix(xy, "xy", n_cols=2)
        check_same_length(imgs, Y, "images", "xy")
        self.xy_ = Y.copy()
        self.image_shape_ = imgs.shape[1:]
        self.n_places_ = n = len(imgs)
        self._itemsize = imgs.dtype.itemsize
        # Spectra in chunks of views, straight into the one stored copy, laid out
        # conjugated as (F, R, n) for the per-frequency products of match():
        # no float32 copy of all views, no complex128 or transposed temporaries
        # (for 5900 RGB 600x60 views that kept the peak ~4x the cache).
        first = _as_rows(imgs[:1], "images", self.normalize)
        R, W = first.shape[1], first.shape[2]
        F = W // 2 + 1
        self.width_ = W
        self._spectra_t = np.empty((F, R, n), np.complex64)
        self._sq_norms = np.empty(n)
        step = max(1, int(self.chunk_bytes) // max(1, R * W * 24))
        for i in range(0, n, step):
            rows = _as_rows(imgs[i : i + step], "images", self.normalize)
            self._spectra_t[:, :, i : i + step] = np.conj(np.fft.rfft(rows, axis=2)).transpose(2, 1, 0)
            self._sq_norms[i : i + step] = (rows.astype(np.float64) ** 2).sum(axis=(1, 2))
        self._n_values = R * W
        self.bytes_per_place_ = int(np.prod(self.image_shape_)) * self._itemsize + 2 * 8
        self.cache_bytes_ = int(self._spectra_t.nbytes + self._sq_norms.nbytes)
        return self

    def _spectra_of(self, idx: Any) -> np.ndarray:
        """Spectra (m, R, F) of the stored views ``idx`` (int array)."""
        return np.conj(self._spectra_t[:, :, np.asarray(idx)]).transpose(2, 1, 0)

    def match(self, images: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Best stored view for each query image.

        Returns
        -------
        index : ndarray (N,) of int
            Index of the best stored view.
        shift : ndarray (N,) of int
            Columns the stored view must be rolled (``np.roll(view, shift,
            axis=1)``) to match the query; ``360 * shift / W`` degrees.
        rms : ndarray (N,)
            The RIDF minimum (RMS pixel difference, in input units).
        """
        q = self._check_query(images)
        n, W = len(self.xy_), self.width_
        Q = np.fft.rfft(q, axis=2).astype(np.complex64)  # (m, R, F)
        q_norms = (q.astype(np.float64) ** 2).sum(axis=(1, 2))
        S = self._spectra_t  # (F, R, n), conjugated
        per_query = W * n * 24 + S.shape[0] * n * 8  # correlations, distances, their copy, products
        chunk = max(1, int(self.chunk_bytes) // per_query)
        idx = np.empty(len(q), dtype=np.int64)
        shift = np.empty(len(q), dtype=np.int64)
        for start in range(0, len(q), chunk):
            sl = slice(start, start + chunk)
            Qc = np.ascontiguousarray(Q[sl].transpose(2, 0, 1))  # (F, m, R)
            corr = np.fft.irfft(np.matmul(Qc, S), n=W, axis=0)  # (W, m, n): sum_w q[w] v[w - d]
            d2 = q_norms[sl][None, :, None] + self._sq_norms[None, None, :] - 2.0 * corr
            flat = d2.transpose(1, 2, 0).reshape(d2.shape[1], -1)  # (m, n * W)
            best = np.argmin(flat, axis=1)
            idx[sl], shift[sl] = np.divmod(best, W)
        # The float32 spectra rank the candidates; the winners' RMS is recomputed
        # directly (the norm expansion loses digits to cancellation near 0).
        views = np.fft.irfft(self._spectra_of(idx), n=W, axis=2)  # (m, R, W)
        cols = (np.arange(W)[None, :] - shift[:, None]) % W  # roll(view, d)[w] = view[w - d]
        rolled = np.take_along_axis(views, cols[:, None, :], axis=2)
        rms = np.sqrt(((q.astype(np.float64) - rolled) ** 2).mean(axis=(1, 2)))
        return idx, shift, rms

    def ridf(self, image: Any, index: int) -> np.ndarray:
        """The RIDF (W,) of one query image (H, W[, C]) against stored view
        ``index``: RMS difference for every shift ``d`` (``np.roll(view, d, axis=1)``)."""
        q = self._check_query(np.asarray(image)[None])[0].astype(np.float64)
        v = np.fft.irfft(self._spectra_of([index])[0], n=self.width_, axis=1).astype(np.float64)
        W = self.width_
        return np.array([np.sqrt(((q - np.roll(v, d, axis=1)) ** 2).mean()) for d in range(W)])


class FourierSignature(_Memory):
    """Fourier signature (Menegatti et al. 2004): per image row the magnitudes
    of the first ``n_coefficients`` DFT coefficients along the azimuth (DC
    included). Rotations only change phases, so the signature is rotation
    invariant; queries take the position of the nearest stored signature.

    Parameters
    ----------
    n_coefficients : int, default 15
        Coefficients kept per row (at most W // 2 + 1).
    metric : {"l1", "l2"}, default "l1"
        Distance between signatures.
    normalize : bool, default False
        Zero mean and unit variance per image first.
    chunk_bytes : int, default 2**27
        Working memory per query chunk.

    Attributes
    ----------
    signatures_ : ndarray (n_places, H * C, n_coefficients), float32
    xy_ : ndarray (n_places, 2)
    bytes_per_place_ : int
        Signature bytes (float32) plus the position.
    """

    def __init__(self, n_coefficients: int = 15, metric: str = "l1", normalize: bool = False, chunk_bytes: int = 2**27) -> None:
        self.n_coefficients = n_coefficients
        self.metric = metric
        self.normalize = normalize
        self.chunk_bytes = chunk_bytes

    def __repr__(self) -> str:
        return f"FourierSignature(n_coefficients={self.n_coefficients!r}, metric={self.metric!r}, normalize={self.normalize!r})"

    def _signature(self, rows: np.ndarray) -> np.ndarray:
        return np.abs(np.fft.rfft(rows, axis=2)[:, :, : self.n_coefficients]).astype(np.float32)

    def fit(self, images: Any, xy: Any) -> "FourierSignature":
        """Stores the signatures of views (N, H, W[, C]) and their positions (N, 2), metres."""
        k = check_int(self.n_coefficients, "n_coefficients")
        if self.metric not in ("l1", "l2"):
            raise ValueError(f"metric must be 'l1' or 'l2', got {self.metric!r}")
        rows = self._fit_common(images, xy)
        if k > rows.shape[2] // 2 + 1:
            raise ValueError(
                f"n_coefficients={k}, but {rows.shape[2]}-px wide panoramas have only {rows.shape[2] // 2 + 1}"
            )
        self.signatures_ = self._signature(rows)
        self.bytes_per_place_ = int(self.signatures_[0].nbytes) + 2 * 8
        return self

    def transform(self, images: Any) -> np.ndarray:
        """Signatures (N, H * C, n_coefficients) of images (N, H, W[, C])."""
        return self._signature(self._check_query(images))

    def match(self, images: Any) -> tuple[np.ndarray, np.ndarray]:
        """Nearest stored signature for each query: ``(index (N,), distance (N,))``."""
        sig = self.transform(images).reshape(-1, self.signatures_[0].size)
        ref = self.signatures_.reshape(len(self.signatures_), -1)
        idx = np.empty(len(sig), dtype=np.int64)
        dist = np.empty(len(sig))
        if self.metric == "l2":
            ref64 = ref.astype(np.float64)
            ref_sq = (ref64**2).sum(axis=1)
            d2 = (sig.astype(np.float64) ** 2).sum(axis=1)[:, None] + ref_sq[None] - 2.0 * sig.astype(np.float64) @ ref64.T
            idx[:] = np.argmin(d2, axis=1)
            dist[:] = np.sqrt(np.clip(d2[np.arange(len(sig)), idx], 0, None))
            return idx, dist
        chunk = max(1, int(self.chunk_bytes) // max(1, ref.nbytes))
        for start in range(0, len(sig), chunk):
            d = np.abs(sig[start : start + chunk, None, :] - ref[None]).sum(axis=2)
            i = np.argmin(d, axis=1)
            idx[start : start + chunk] = i
            dist[start : start + chunk] = d[np.arange(len(i)), i]
        return idx, dist


def benchmark(model: Any, images: Any, xy: Any, *, coordinate_range: Any = None) -> dict[str, Any]:
    """Error, memory and query time of a fitted localizer on a test run.

    Works with :class:`PerfectMemory`, :class:`FourierSignature`,
    :class:`sfanav.Localizer` or anything with ``predict(images) -> (N, 2)``.

    Returns
    -------
    dict
        :func:`sfanav.localization.localization_metrics` plus ``query_ms`` (wall
        time per query image, milliseconds, one batched call) and
        ``bytes_per_place`` (the model's ``bytes_per_place_``, or None for
        models whose memory does not grow with the places, such as the SFA
        localizer).
    """
    Y = as_matrix(xy, "xy", n_cols=2)
    t0 = time.perf_counter()
    pred = model.predict(images)
    dt = time.perf_counter() - t0
    out: dict[str, Any] = localization_metrics(pred, Y, coordinate_range=coordinate_range)
    out["query_ms"] = 1000.0 * dt / len(Y)
    out["bytes_per_place"] = getattr(model, "bytes_per_place_", None)
    return out
