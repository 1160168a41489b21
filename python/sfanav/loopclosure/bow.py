"""Loop closures from a bag of visual words (thesis 6.2.1).

Every training panorama is described by SIFT descriptors (OpenCV) computed
on a dense grid of keypoints of one fixed size: the thesis used SURF, which
is not in OpenCV's free build; a fixed scale keeps the words specific to
the place in a small open garden. A vocabulary of ``n_words`` words is
learned by k-means (scikit-learn's ``MiniBatchKMeans``) on a sample of the
descriptors; each image becomes a tf-idf weighted, L2-normalised word
histogram, and a frame's loop closure is the earlier frame of most similar
histogram (cosine). The ``verify`` most similar earlier frames are then
re-ranked by the distance of the aligned, illumination-normalised
panoramas (each image shifted and scaled to zero mean and unit variance,
compared at its best column shift), and the nearest is accepted when it is
at most ``accept`` times as far as the frame's temporal neighbours.
Panoramas are padded circularly by half a keypoint so that descriptors
wrap around the seam.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import as_images, check_int, check_nonneg_float, check_positive_float
from .detectors import LoopClosureDetector


def _one_thread():
    """One thread for scikit-learn's k-means (OpenMP and BLAS): on small
    batches two threads on two shared cores are many times slower."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1)


def _gray_uint8(images: np.ndarray) -> np.ndarray:
    X = images
    if X.ndim == 4:
        X = X.astype(np.float32) @ np.array([0.299, 0.587, 0.114][: X.shape[3]] if X.shape[3] == 3 else
                                            [1.0 / X.shape[3]] * X.shape[3], np.float32)
    if X.dtype != np.uint8:
        X = np.asarray(X, np.float32)
        hi = float(X.max()) if X.size else 0.0
        X = np.clip(X * (255.0 / hi if 0 < hi <= 1.0 + 1e-6 else 1.0), 0, 255)
        X = np.rint(X).astype(np.uint8)
    return X


class BagOfWordsDetector(LoopClosureDetector):
    """Visual-word loop closures (see the module docstring).

    Parameters
    ----------
    n_words : int, default 1500
        Vocabulary size (the thesis's).
    keypoint_size : float, default 4
        Size of the fixed-scale SIFT keypoints, pixels (OpenCV's descriptor
        spans about six times this: 24-px windows).
    grid_step : int, default 4
        Keypoint spacing, pixels (rows and columns).
    rows : (float, float), default (0.0, 1.0)
        The band of image rows described, as fractions of the height from
        the top (e.g. ``(0.0, 0.5)``: the upper half, leaving out the lawn
        near the robot, which looks alike everywhere).
    max_descriptors : int, default 200000
        Descriptors sampled to learn the vocabulary.
    verify : int, default 20
        Candidates re-ranked by the aligned image distance (1: the
        histograms alone decide).
    accept : float, default 0.7
        A match is accepted when its aligned image distance is at most
        ``accept`` times the frame's distance to its temporal neighbours.
        Lower: fewer, more precise closures; feedback training gains more
        from more closures a few decimetres apart than from fewer exact
        ones under changing light (docs/loop-closures.md).
    min_gap, max_odometry_distance, neighbor_lag, suppress
        As :class:`~sfanav.loopclosure.FourierDetector`.
    seed : int
        Seed of the sampling and of k-means.

    Fitted attributes (after :meth:`candidates` / :meth:`detect`):
    ``vocabulary_`` (n_words, 128), ``idf_`` (n_words,).
    """

    def __init__(self, n_words: int = 1500, keypoint_size: float = 4.0, grid_step: int = 4,
                 rows: tuple[float, float] = (0.0, 1.0), max_descriptors: int = 200_000, verify: int = 20,
                 min_gap: int = 40, max_odometry_distance: float = 3.0, accept: float = 0.7, neighbor_lag: int = 2,
                 suppress: int = 0, seed: int = 0) -> None:
        self.n_words = n_words
        self.keypoint_size = keypoint_size
        self.grid_step = grid_step
        self.rows = rows
        self.max_descriptors = max_descriptors
        self.verify = verify
        self.min_gap = min_gap
        self.max_odometry_distance = max_odometry_distance
        self.accept = accept
        self.neighbor_lag = neighbor_lag
        self.suppress = suppress
        self.seed = seed

    def descriptors(self, images: Any) -> list[np.ndarray]:
        """Dense SIFT descriptors (K, 128) float32 of every image."""
        import cv2

        G = _gray_uint8(as_images(images))
        size = check_positive_float(self.keypoint_size, "keypoint_size")
        step = check_int(self.grid_step, "grid_step")
        pad = int(np.ceil(size / 2))
        h, w = G.shape[1:3]
        try:
            lo, hi = (float(v) for v in self.rows)
        except (TypeError, ValueError):
            raise ValueError(f"rows must be two fractions (top, bottom) of the image height, got {self.rows!r}") from None
        if not 0.0 <= lo < hi <= 1.0:
            raise ValueError(f"rows must satisfy 0 <= top < bottom <= 1, got {self.rows!r}")
        y0, y1 = max(pad, int(round(lo * h))), min(h - pad, int(round(hi * h)))
        if y1 <= y0:
            raise ValueError(f"rows {self.rows!r} of {h}-px images leave no room for keypoints of {size:g} px; "
                             "widen rows or lower keypoint_size")
        kps = [cv2.KeyPoint(float(x), float(y), size) for y in range(y0, y1, step)
               for x in range(pad, pad + w, step)]
        sift = cv2.SIFT_create()
        out = []
        for g in G:
            wrapped = np.concatenate([g[:, -pad:], g, g[:, :pad]], axis=1)
            _, d = sift.compute(wrapped, kps)
            out.append(np.zeros((0, 128), np.float32) if d is None else d.astype(np.float32))
        return out

    def fit(self, images: Any) -> "BagOfWordsDetector":
        """Learns the vocabulary and idf weights on ``images``."""
        from sklearn.cluster import MiniBatchKMeans

        k = check_int(self.n_words, "n_words", minimum=2)
        D = self.descriptors(images)
        allD = np.concatenate(D)
        if len(allD) < k:
            raise ValueError(f"{len(allD)} descriptors cannot make {k} words: lower n_words or use more images")
        rng = np.random.default_rng(self.seed)
        m = check_int(self.max_descriptors, "max_descriptors", minimum=k)
        sample = allD[rng.choice(len(allD), min(m, len(allD)), replace=False)]
        with _one_thread():
            km = MiniBatchKMeans(n_clusters=k, random_state=self.seed, n_init=1, batch_size=4096,
                                 max_no_improvement=20).fit(sample)
        self.vocabulary_ = km.cluster_centers_.astype(np.float32)
        self._kmeans = km
        counts = self._counts(D)
        df = (counts > 0).sum(axis=0)
        self.idf_ = np.log(len(D) / np.maximum(df, 1)).astype(np.float64)
        self._train_counts = counts
        return self

    def _counts(self, D: list[np.ndarray]) -> np.ndarray:
        k = len(self.vocabulary_)
        out = np.zeros((len(D), k))
        sizes = [len(d) for d in D]
        allD = np.concatenate(D)
        with _one_thread():
            words = np.concatenate([self._kmeans.predict(allD[s : s + 65536]) for s in range(0, len(allD), 65536)])
        owner = np.repeat(np.arange(len(D)), sizes)
        np.add.at(out, (owner, words), 1.0)
        return out

    def histograms(self, images: Any) -> np.ndarray:
        """tf-idf word histograms (N, n_words), L2-normalised rows."""
        if not hasattr(self, "vocabulary_"):
            raise ValueError("this BagOfWordsDetector has no vocabulary yet: call fit (or detect) first")
        return self._normalise(self._counts(self.descriptors(images)))

    def _normalise(self, counts: np.ndarray) -> np.ndarray:
        tf = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1.0)
        H = tf * self.idf_
        return H / np.maximum(np.linalg.norm(H, axis=1, keepdims=True), 1e-12)

    def _best(self, X, pos, odo):
        self.min_gap = check_int(self.min_gap, "min_gap", minimum=1)
        accept = check_nonneg_float(self.accept, "accept")
        max_odo = check_positive_float(self.max_odometry_distance, "max_odometry_distance")
        lag = check_int(self.neighbor_lag, "neighbor_lag")
        k = check_int(self.verify, "verify")
        check_int(self.suppress, "suppress", minimum=0)
        self.fit(X)
        H = self._normalise(self._train_counts)
        P = _normalised_panoramas(X)
        n = len(X)
        nb = np.full(n, np.inf)
        for d in (-lag, lag):
            for i in range(max(0, -d), min(n, n - d)):
                nb[i] = min(nb[i], _aligned_distance(P[i], P[i + d : i + d + 1])[0])
        cur, past, dist = [], [], []
        for s in range(self.min_gap, n, 256):
            q = np.arange(s, min(n, s + 256))
            sims = np.where(self._gate(n, q, odo, max_odo), H[q] @ H.T, -np.inf)
            top = np.argsort(-sims, axis=1)[:, :k]
            for row, i in enumerate(q):
                cand = top[row][np.isfinite(sims[row, top[row]])]
                if not len(cand):
                    continue
                dj = _aligned_distance(P[i], P[cand])
                b = int(np.argmin(dj))
                cur.append(i)
                past.append(int(cand[b]))
                dist.append(float(dj[b]))
        if not cur:
            z = np.zeros(0, np.int64)
            return z, z, np.zeros(0), np.zeros(0), np.zeros(0, bool)
        c, p, d = np.array(cur, np.int64), np.array(past, np.int64), np.array(dist)
        ratio = d / np.maximum(nb[c], 1e-12)
        return c, p, d, 1.0 / (1.0 + ratio), ratio <= accept


def _normalised_panoramas(images: np.ndarray) -> np.ndarray:
    """Gray panoramas (N, H, W) float32, each at zero mean and unit variance."""
    G = _gray_uint8(images).astype(np.float32)
    G -= G.mean(axis=(1, 2), keepdims=True)
    G /= np.maximum(G.std(axis=(1, 2), keepdims=True), 1e-6)
    return G


def _aligned_distance(a: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Mean squared difference of panorama ``a`` (H, W) and each of ``B``
    (K, H, W) at the column shift that fits best."""
    W = a.shape[1]
    fa = np.fft.rfft(a, axis=1)
    fb = np.fft.rfft(B, axis=2)
    corr = np.fft.irfft((fa[None] * np.conj(fb)).sum(axis=1), n=W, axis=1).max(axis=1)
    # identical panoramas give zero up to rounding, which may be slightly negative
    return np.maximum(((a**2).sum() + (B**2).sum(axis=(1, 2)) - 2.0 * corr) / a.size, 0.0)
