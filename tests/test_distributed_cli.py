"""``sfanav train --scheduler ADDRESS``: the model trained with the network
on a Dask LocalCluster equals the one trained in this process; without
Dask, or without a scheduler at the address, one-line errors."""

import sys
import time

import numpy as np
import pytest
import sfanav
from clitools import assert_one_line_error, run, tiny_dataset


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A 60x8 dataset of the demo garden (train and test runs) and the tiny config."""
    root = tmp_path_factory.mktemp("scheduler")
    ds, cfg = tiny_dataset(root)
    return {"root": root, "ds": ds, "config": cfg}


def _train(capsys, tiny, out, *extra):
    return run(capsys, "train", "--dataset", tiny["root"] / "data", "--config", tiny["config"], "--precision",
               "double", "--readout", "quadratic", "--out", out, "--no-progress", *extra)


def test_train_on_a_scheduler_equals_training_here(tiny, tmp_path, capsys):
    pytest.importorskip("distributed")
    from dasktools import local_cluster

    code, _, err = _train(capsys, tiny, tmp_path / "here.sfa")
    assert code == 0, err
    with local_cluster(2) as cluster:
        code, out, err = _train(capsys, tiny, tmp_path / "dask.sfa", "--scheduler", cluster.scheduler_address)
    assert code == 0, err
    assert "wrote" in out and "Dask scheduler at tcp://" in err and "(2 worker(s))" in err
    here, there = sfanav.load(tmp_path / "here.sfa"), sfanav.load(tmp_path / "dask.sfa")
    images = tiny["ds"].load_images()  # both runs: the training run and unseen places
    fa, fb = here.features(images), there.features(images)
    assert np.max(np.abs(fa - fb)) / np.max(np.abs(fa)) < 1e-9
    np.testing.assert_allclose(there.network.delta_values_, here.network.delta_values_, rtol=1e-9)
    np.testing.assert_allclose(there.predict(images), here.predict(images), atol=1e-6)
    assert there.info["n_train_images"] == here.info["n_train_images"] == 40


def test_scheduler_errors_are_one_line(tiny, tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed")
    t0 = time.perf_counter()
    code, _, err = _train(capsys, tiny, tmp_path / "x.sfa", "--scheduler", "tcp://127.0.0.1:1")
    assert_one_line_error(code, err, "cannot reach the Dask scheduler at tcp://127.0.0.1:1")
    assert time.perf_counter() - t0 < 30  # a short connect timeout, no hang
    code, _, err = _train(capsys, tiny, tmp_path / "x.sfa", "--scheduler", "tcp://127.0.0.1:1", "--landmarks", "1")
    assert_one_line_error(code, err, "--scheduler", "--landmarks")
    monkeypatch.setitem(sys.modules, "distributed", None)  # Dask not installed
    code, _, err = _train(capsys, tiny, tmp_path / "x.sfa", "--scheduler", "tcp://127.0.0.1:1")
    assert_one_line_error(code, err, '--scheduler needs Dask: pip install "sfanav[dask]"')
    assert not (tmp_path / "x.sfa").exists()
