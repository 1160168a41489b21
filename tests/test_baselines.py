"""Perfect memory (RIDF) and Fourier-signature baselines."""

import numpy as np
import pytest

import sfanav
from sfanav.localization import FourierSignature, PerfectMemory, benchmark


@pytest.fixture(scope="module")
def views():
    """40 random smooth-ish panoramas 8 x 36 (gray) with positions."""
    rng = np.random.default_rng(0)
    raw = rng.random((40, 8, 36))
    imgs = (raw + np.roll(raw, 1, axis=2) + np.roll(raw, 1, axis=1)) / 3
    xy = rng.uniform(0, 5, (40, 2))
    return imgs, xy


def rotated(imgs, shifts):
    return np.stack([np.roll(im, k, axis=1) for im, k in zip(imgs, shifts)])


def brute_force_match(stored, query):
    """Exhaustive RIDF: every stored view, every column shift."""
    best = (np.inf, -1, -1)
    for i, v in enumerate(stored):
        for d in range(v.shape[1]):
            rms = np.sqrt(((query - np.roll(v, d, axis=1)) ** 2).mean())
            if rms < best[0]:
                best = (rms, i, d)
    return best


@pytest.mark.parametrize("model", [PerfectMemory(), FourierSignature(n_coefficients=6), FourierSignature(metric="l2")])
def test_exact_on_training_views_and_rotated_training_views(views, model):
    imgs, xy = views
    model.fit(imgs, xy)
    np.testing.assert_array_equal(model.predict(imgs), xy)
    shifts = np.random.default_rng(1).integers(0, 36, len(imgs))
    np.testing.assert_array_equal(model.predict(rotated(imgs, shifts)), xy)
    assert model.score(imgs, xy) == 0.0


def test_ridf_shift_and_distance(views):
    imgs, xy = views
    pm = PerfectMemory().fit(imgs, xy)
    shifts = np.arange(len(imgs)) % 36
    idx, shift, rms = pm.match(rotated(imgs, shifts))
    np.testing.assert_array_equal(idx, np.arange(len(imgs)))
    np.testing.assert_array_equal(shift, shifts)
    np.testing.assert_allclose(rms, 0.0, atol=1e-4)
    # a new view: the FFT search equals the exhaustive search
    rng = np.random.default_rng(2)
    for q in (0.7 * imgs[3] + 0.3 * rng.random((8, 36)), np.roll(imgs[10], 7, axis=1) + 0.05 * rng.random((8, 36))):
        best_rms, best_i, best_d = brute_force_match(imgs, q)
        i, d, r = (a[0] for a in pm.match(q[None]))
        assert (i, d) == (best_i, best_d) and r == pytest.approx(best_rms, rel=1e-4)
        curve = pm.ridf(q, best_i)
        assert curve.shape == (36,) and np.argmin(curve) == best_d and curve.min() == pytest.approx(best_rms, rel=1e-4)


def test_chunking_gives_the_same_answer(views):
    imgs, xy = views
    q = imgs[:10] + 0.1 * np.random.default_rng(3).random(imgs[:10].shape)
    big = PerfectMemory().fit(imgs, xy).match(q)
    small = PerfectMemory(chunk_bytes=1).fit(imgs, xy).match(q)  # one query per chunk
    for a, b in zip(big, small):
        np.testing.assert_allclose(a, b, rtol=1e-5)
    f_big = FourierSignature().fit(imgs, xy).match(q)
    f_small = FourierSignature(chunk_bytes=1).fit(imgs, xy).match(q)
    np.testing.assert_array_equal(f_big[0], f_small[0])


def test_rgb_uint8_and_memory_per_place(views):
    imgs, xy = views
    rgb = np.round(np.stack([imgs, imgs**2, 1 - imgs], axis=-1) * 255).astype(np.uint8)
    pm = PerfectMemory().fit(rgb, xy)
    assert pm.bytes_per_place_ == 8 * 36 * 3 + 16 and pm.cache_bytes_ > 0
    np.testing.assert_array_equal(pm.predict(np.roll(rgb, 5, axis=2)), xy)
    fs = FourierSignature(n_coefficients=10).fit(rgb, xy)
    assert fs.signatures_.shape == (40, 8 * 3, 10) and fs.bytes_per_place_ == 8 * 3 * 10 * 4 + 16
    np.testing.assert_array_equal(fs.predict(np.roll(rgb, 11, axis=2)), xy)
    # normalisation makes the memory blind to global brightness and contrast
    pmn = PerfectMemory(normalize=True).fit(imgs, xy)
    np.testing.assert_array_equal(pmn.predict(2.0 * imgs + 5.0), xy)
    fsn = FourierSignature(normalize=True).fit(imgs, xy)
    np.testing.assert_array_equal(fsn.predict(2.0 * imgs + 5.0), xy)


def test_fourier_signature_is_rotation_invariant(views):
    imgs, xy = views
    fs = FourierSignature(n_coefficients=8).fit(imgs, xy)
    np.testing.assert_allclose(fs.transform(imgs[:3]), fs.transform(np.roll(imgs[:3], 13, axis=2)), atol=1e-5)


def test_benchmark_table_row(views):
    imgs, xy = views
    row = benchmark(PerfectMemory().fit(imgs, xy), imgs[:5], xy[:5])
    assert row["med"] == 0.0 and row["query_ms"] > 0 and row["bytes_per_place"] == 8 * 36 * 8 + 16

    class Fixed:
        def predict(self, images):
            return np.zeros((len(images), 2))

    assert benchmark(Fixed(), imgs[:5], xy[:5])["bytes_per_place"] is None


def test_baseline_errors(views):
    imgs, xy = views
    with pytest.raises(sfanav.NotFittedError, match="PerfectMemory is not fitted"):
        PerfectMemory().predict(imgs)
    with pytest.raises(sfanav.NotFittedError, match="FourierSignature is not fitted"):
        FourierSignature().match(imgs)
    pm = PerfectMemory().fit(imgs, xy)
    with pytest.raises(ValueError, match=r"query images have shape \(8, 30\)"):
        pm.predict(imgs[:, :, :30])
    with pytest.raises(ValueError, match="images has 40 rows but xy has 39"):
        PerfectMemory().fit(imgs, xy[:-1])
    with pytest.raises(ValueError, match="xy must have 2 columns"):
        PerfectMemory().fit(imgs, np.zeros((40, 3)))
    bad = imgs.copy()
    bad[4, 0, 0] = np.nan
    with pytest.raises(ValueError, match="image 4 contains NaN"):
        pm.predict(bad)
    with pytest.raises(ValueError, match="n_coefficients=30, but 36-px wide panoramas have only 19"):
        FourierSignature(n_coefficients=30).fit(imgs, xy)
    with pytest.raises(ValueError, match="metric"):
        FourierSignature(metric="cosine").fit(imgs, xy)
    with pytest.raises(ValueError, match=r"\(N, H, W\)"):
        pm.predict(imgs[0, 0])
