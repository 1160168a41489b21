"""Loop closures from a bag of visual words (thesis 6.2.1).

Every training panorama is described by SIFT descriptors (OpenCV) computed
on a dense grid of keypoints of one fixed size: the thesis used SURF, which
is not in OpenCV's free build; a fixed scale keeps the words specific to
the place in a small open garden. A vocabulary of ``n_words`` words is
learned by k-means (scikit-learn's ``MiniBatchKMeans``) on a sample of the
descriptors; each image becomes a tf-idf weighted, L2-normalised word
histogram, and a frame's loop closure is the earlier frame of most similar
histogram (cosine), accepted like the Fourier detector's matches: at most
``accept`` times as far (1 - cosine) as the frame's temporal neighbours.
Panoramas are padded circularly by half a keypoint so that descriptors
wrap around the seam.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import as_images, check_int, check_nonneg_float, check_positive_float
from .detectors import LoopClosureDetector, nearest_earlier


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
    keypoint_size : float, default 12
        Diameter of the fixed-scale SIFT keypoints, pixels.
    grid_step : int, default 8
        Keypoint spacing, pixels (rows and columns).
    max_descriptors : int, default 200000
        Descriptors sampled to learn the vocabulary.
    min_gap, max_odometry_distance, accept, neighbor_lag, suppress
        As :class:`~sfanav.loopclosure.FourierDetector`.
    seed : int
        Seed of the sampling and of k-means.

    Fitted attributes (after :meth:`candidates` / :meth:`detect`):
    ``vocabulary_`` (n_words, 128), ``idf_`` (n_words,).
    """

    def __init__(self, n_words: int = 1500, keypoint_size: float = 12.0, grid_step: int = 8,
                 max_descriptors: int = 200_000, min_gap: int = 40, max_odometry_distance: float = 3.0,
                 accept: float = 1.0, neighbor_lag: int = 2, suppress: int = 0, seed: int = 0) -> None:
        self.n_words = n_words
        self.keypoint_size = keypoint_size
        self.grid_step = grid_step
        self.max_descriptors = max_descriptors
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
        if h < 2 * pad + 1:
            raise ValueError(f"images of {h} rows are too low for keypoints of {size:g} px; lower keypoint_size")
        kps = [cv2.KeyPoint(float(x), float(y), size) for y in range(pad, h - pad, step)
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
        check_int(self.suppress, "suppress", minimum=0)
        self.fit(X)
        H = self._normalise(self._train_counts)
        return nearest_earlier(H, lambda A, B: np.maximum(1.0 - A @ B.T, 0.0), self, odo, max_odo, lag, accept)
