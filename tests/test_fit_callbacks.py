"""The Rust training loop calls back into Python (image batches, progress):
a Python exception raised there comes out of fit unchanged, and the
progress reports cover every pass."""

import numpy as np
import pytest

import sfanav
from sfanav import _core


def tiny():
    return {
        "input": {"width": 48, "height": 8, "channels": 1},
        "layers": [{"rf": [8, 4], "stride": [4, 4], "out": 4}, {"rf": "full", "out": 3}],
    }


def images(n=12, seed=0):
    rng = np.random.default_rng(seed)
    x = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    return np.stack([np.sin(x[None, :] * (1 + i % 3) + rng.uniform(0, 6) + np.arange(8)[:, None] * 0.3)
                     + 0.05 * rng.standard_normal((8, 48)) for i in range(n)])


class Boom(Exception):
    pass


def test_exception_in_the_batch_iterator_comes_out_unchanged():
    imgs = images()

    def batches():
        calls["n"] += 1
        if calls["n"] == 3:  # the first is fit's own look at the first batch
            yield imgs[:4]
            raise Boom("from the iterator")
        yield from (imgs[i : i + 4] for i in range(0, len(imgs), 4))

    calls = {"n": 0}
    net = sfanav.Network(tiny())
    with pytest.raises(Boom, match="from the iterator"):
        net.fit(batches, sfanav.Rotation(step=4), progress=False)
    assert not net.is_fitted_


def test_exception_in_the_progress_callback_comes_out_unchanged():
    net = _core.Network(sfanav.Network(tiny()).config_)
    imgs = images()

    def progress(event, layer, *rest):
        if layer == 1:
            raise Boom("from progress")

    with pytest.raises(Boom, match="from progress"):
        net.fit(lambda: [imgs], 4, 48, progress=progress)
    assert net.n_trained == 1


def test_progress_reports_every_pass_and_the_cache_plan():
    net = _core.Network(sfanav.Network(tiny()).config_)
    imgs = images().astype(np.float32)
    seen = []
    plan = net.fit(lambda: [imgs[:5], imgs[5:]], 4, 48, cache=True, total=len(imgs),
                   progress=lambda *a: seen.append(a))
    assert net.n_trained == 2
    assert [p[:5] for p in seen if p[0] == "start"] == [
        ("start", 0, 2, 0, 2), ("start", 0, 2, 1, 2), ("start", 1, 2, 0, 2), ("start", 1, 2, 1, 2)]
    assert [p[5] for p in seen[:4]] == [0, 5, 12, 12]
    assert [p[7] for p in seen if p[0] == "start"] == [False, False, False, True]
    assert plan == [(2, True, plan[0][2])] and plan[0][2] > 0


def test_uint8_float32_float64_batches_train_alike():
    imgs = (images() * 60 + 128).clip(0, 255).astype(np.uint8)
    out = []
    for dtype in (np.uint8, np.float32, np.float64):
        net = sfanav.Network(tiny()).fit(imgs.astype(dtype), sfanav.Rotation(step=4), progress=False)
        out.append(net.transform(imgs.astype(dtype)))
    np.testing.assert_array_equal(out[0], out[1])
    np.testing.assert_array_equal(out[0], out[2])


def test_bad_batches_are_refused_by_the_core():
    net = _core.Network(sfanav.Network(tiny()).config_)
    with pytest.raises(ValueError, match="px wide"):
        net.fit(lambda: [images()[:, :, :40]], 4, 48)
    with pytest.raises(TypeError, match="uint8"):
        net.fit(lambda: [images().astype(np.int16)], 4, 48)
    with pytest.raises(ValueError, match="gather"):
        net.fit(lambda: [images()], 4, 48, pairs=([0], [1], [1.0], None))
