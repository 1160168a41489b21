"""The ``sfanav`` command on hostile input: every failure of bad input is
one line on stderr with exit status 2, and an interrupted command leaves
nothing a later command takes for complete."""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from modeltools import edit_model
from sfanav import sim
from sfanav.app.arguments import fraction as _fraction
from sfanav.app.cli import main
from clitools import TINY_TOML, assert_one_line_error, run


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("hostile")
    sim.simulate("demo", root / "data", seed=4, max_frames=24, camera=sim.PanoramicCamera(60, 8), progress=False)
    cfg = root / "tiny.toml"
    cfg.write_text(TINY_TOML)
    model = root / "tiny.sfa"
    assert main(["train", "--dataset", str(root / "data"), "--config", str(cfg), "--out", str(model),
                 "--no-progress"]) == 0
    return {"root": root, "data": root / "data", "config": cfg, "model": model}


def localize(capsys, model, tiny, tmp_path):
    return run(capsys, "localize", model, tiny["data"], "--out", tmp_path / "x.csv", "--no-progress")


def test_corrupted_and_edited_models_are_one_line_errors(tiny, tmp_path, capsys):
    data = bytearray(tiny["model"].read_bytes())
    data[data.find(b"PK\x01\x02") + 10] = 99  # the compression method of the first directory entry
    flipped = tmp_path / "flip.sfa"
    flipped.write_bytes(bytes(data))
    assert_one_line_error(*localize(capsys, flipped, tiny, tmp_path)[::2], "not a valid sfanav model file")

    def rows(m, blobs):
        m["state"]["rows"] = 1

    def trained(m, blobs):
        m["state"]["network"]["trained"] = -1

    def prep(m, blobs):
        m["state"]["info"]["preprocessing"]["width"] = -5

    for edit, words in ((rows, "AttributeError"), (trained, "trained must be at least 0"),
                        (prep, "panorama width must be 1..32767")):
        out = edit_model(tiny["model"], tmp_path / f"{edit.__name__}.sfa", edit)
        code, _, err = localize(capsys, out, tiny, tmp_path)
        assert_one_line_error(code, err, words)
        assert not (tmp_path / "x.csv").exists()


def test_configs_beyond_the_machine_and_malformed_configs(tiny, tmp_path, capsys):
    huge = tmp_path / "huge.toml"
    huge.write_text(TINY_TOML.replace("width = 60", "width = 6000000").replace("height = 8", "height = 800000"))
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00[input]\x00")
    for cfg, words in ((huge, "of memory; the limit is"), (deep, "nests too deeply"), (binary, "not UTF-8 text")):
        code, _, err = run(capsys, "train", "--dataset", tiny["data"], "--config", cfg,
                           "--out", tmp_path / "m.sfa", "--no-progress")
        assert_one_line_error(code, err, words)
        assert not (tmp_path / "m.sfa").exists()


def test_binary_and_inconsistent_dataset_tables(tiny, tmp_path, capsys):
    for name, mutate, words in (
        ("binary", lambda d: (d / "frames.csv").write_bytes(b"\x89PNG\r\n\x1a\n\xff\xff"), "not UTF-8 text"),
        ("missing", lambda d: next((d / "images").iterdir()).unlink(), "does not exist"),
    ):
        d = tmp_path / name
        shutil.copytree(tiny["data"], d)
        mutate(d)
        code, _, err = run(capsys, "train", "--dataset", d, "--config", tiny["config"],
                           "--out", tmp_path / "m.sfa", "--no-progress")
        assert_one_line_error(code, err, words)


def test_absurd_sizes_and_windows(tiny, tmp_path, capsys):
    code, _, err = run(capsys, "simulate", "--preset", "demo", "--out", tmp_path / "s",
                       "--size", "100000000x100000000")
    assert_one_line_error(code, err, "beyond 32767 px")
    code, _, err = run(capsys, "train", "--dataset", tiny["data"], "--config", tiny["config"],
                       "--out", tmp_path / "m.sfa", "--window", "2.0")
    assert_one_line_error(code, err, "more than the whole panorama", "2.0%")
    assert _fraction("0.6") == 0.6 and _fraction("60%") == 0.6 and _fraction("100%") == 1.0
    for bad in ("0", "0%", "150%", "nan", "inf%", "x"):
        with pytest.raises(argparse.ArgumentTypeError):
            _fraction(bad)


@pytest.mark.parametrize("sig,status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_an_interrupted_simulate_leaves_no_dataset(tmp_path, sig, status):
    out = tmp_path / "ds"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    # SIGINT back to its default in the child: a test run started in the background (`cmd &` in a script) ignores
    # SIGINT, and Python keeps an inherited ignore (no KeyboardInterrupt), as a user's background job would
    proc = subprocess.Popen([sys.executable, "-m", "sfanav", "simulate", "--preset", "demo", "--out", str(out),
                             "--size", "120x16"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if (out / "images").exists() and len(list((out / "images").iterdir())) >= 5:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "simulate finished before it could be interrupted"
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == status, err.decode()
    assert not (out / "metadata.json").exists()
    assert "Traceback" not in err.decode()
    r = subprocess.run([sys.executable, "-m", "sfanav", "train", "--dataset", str(out), "--preset", "thesis-5.1",
                        "--out", str(tmp_path / "m.sfa")], capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 2 and "no metadata.json" in r.stderr, r.stderr
    assert not Path(tmp_path / "m.sfa").exists()
