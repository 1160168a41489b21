"""Helpers of the command-line tests: run ``sfanav`` in-process and check
its one-line errors; the tiny network config the CLI tests train."""

from __future__ import annotations

from pathlib import Path

import sfanav
from sfanav.app.cli import main

#: the directory that holds the ``sfanav`` package these tests imported (the
#: installed wheel in CI, ``python/`` in an editable install): subprocesses put
#: it on ``PYTHONPATH`` so they test the same build, never the bare source tree
SFANAV_ROOT = str(Path(sfanav.__file__).resolve().parents[1])

#: a two-layer network for 60x8 RGB panoramas (seconds to train)
TINY_TOML = """
[input]
width = 60
height = 8
channels = 3

[network]
precision = "mixed"

[[layers]]
rf = [6, 4]
stride = [3, 4]
out = 8

[[layers]]
rf = "full"
out = 10
"""


def tiny_dataset(root):
    """A 60x8 dataset of the demo garden (train and test runs) under
    ``root/data`` and the tiny config as ``root/tiny.toml``: (dataset, config path)."""
    from sfanav import sim

    ds = sim.simulate("demo", root / "data", seed=3, max_frames=40, camera=sim.PanoramicCamera(60, 8),
                      progress=False)
    cfg = root / "tiny.toml"
    cfg.write_text(TINY_TOML)
    return ds, cfg


def tiny_trained(root):
    """:func:`tiny_dataset` under ``root`` with a model trained on it by ``sfanav train`` (the tiny config):
    ``{"root", "model" (path), "loc" (the loaded model), "images" (the test run's), "odometry" (the test run's)}``."""
    import numpy as np

    from sfanav.data.sources import open_images

    tiny_dataset(root)
    model = root / "tiny.sfa"
    assert main(["train", "--dataset", str(root / "data"), "--config", str(root / "tiny.toml"), "--out", str(model),
                 "--no-progress"]) == 0
    src = open_images(root / "data", run="test")
    return {"root": root, "model": model, "loc": sfanav.load(model),
            "images": np.concatenate(list(src.batches(64))), "odometry": src.odometry}


def run(capsys, *args):
    """``sfanav ARGS`` in this process: (exit status, stdout, stderr)."""
    try:
        code = main([str(a) for a in args])
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


def assert_one_line_error(code, err, *words):
    """Exit status 2, one line on stderr with every word, no traceback."""
    assert code == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for w in words:
        assert w in lines[0], lines[0]
