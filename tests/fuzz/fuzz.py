#!/usr/bin/env python3
"""Coverage-guided fuzzing (atheris / libFuzzer) of the model loader, the
network config parser and the ROS bag import, with the structure-aware
mutations of ``mutations.py``.

    python3 tests/fuzz/fuzz.py model  SCRATCH_DIR tests/fuzz/corpus/model  -max_total_time=60
    python3 tests/fuzz/fuzz.py config SCRATCH_DIR tests/fuzz/corpus/config -max_total_time=60
    python3 tests/fuzz/fuzz.py bag    SCRATCH_DIR tests/fuzz/corpus/bag    -max_total_time=60

The first corpus directory receives the new inputs libFuzzer finds (give a
scratch directory so that the committed corpus stays as it is); a crash is
written as ``crash-*`` under ``-artifact_prefix``. The contract under test:
``sfanav.load`` of any bytes raises at most a ValueError (and a loaded model
transforms without anything but a ValueError), and ``sfanav.Network`` of
any JSON object raises at most a ValueError or a TypeError; importing any
bytes as a ROS bag (``sfanav.Dataset.from_bag``, ROS 1, MCAP or SQLite by the
file's first bytes, and ``bag_info``) raises at most a ValueError or a
TypeError and leaves no file behind when it fails; never another
exception, an abort, a hang or an allocation beyond the address-space limit
set below (an unchecked allocation would show as a MemoryError or a crash).
"""

from __future__ import annotations

import os
import random
import resource
import sys
import tempfile
import warnings
from pathlib import Path

import atheris

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # tests/: bagrecords
from mutations import mutate_bag, mutate_config, mutate_model

with atheris.instrument_imports(include=["sfanav", "rosbags"]):
    import numpy as np
    import rosbags.highlevel
    import rosbags.rosbag1
    import rosbags.rosbag2  # noqa: F401
    import sfanav
    from sfanav.data import bag_info

ADDRESS_SPACE = 6 * 2**30  # bytes: an unchecked allocation fails instead of swapping
warnings.simplefilter("ignore")
_DIR = Path(tempfile.mkdtemp(prefix="sfanav-fuzz-"))
_PATH = _DIR / "input.sfa"
_BAGS = _DIR / "bags"
_BAGS.mkdir()
BAG_KINDS = ((b"#ROSBAG V2.0", "input.bag"), (b"\x89MCAP", "input.mcap"), (b"SQLite format 3", "input.db3"))


def exercise(obj: object) -> None:
    """Uses a loaded model once, on zeros of the shape it declares."""
    if isinstance(obj, sfanav.SFA) and getattr(obj, "n_features_in_", None):
        obj.transform(np.zeros((2, obj.n_features_in_)))
    elif isinstance(obj, sfanav.Network) and obj.is_fitted_:
        h, v, c = obj.input_shape
        obj.transform(np.zeros((1, h, v, c) if c > 1 else (1, h, v), np.uint8))
    elif isinstance(obj, sfanav.Localizer):
        obj.predict_features(np.zeros((1, obj.n_features_in_)))


def model_one(data: bytes) -> None:
    _PATH.write_bytes(data)
    try:
        obj = sfanav.load(_PATH)
    except ValueError:
        return
    try:
        exercise(obj)
    except ValueError:
        pass


def config_one(data: bytes) -> None:
    import json

    try:
        cfg = json.loads(data)
    except (ValueError, RecursionError):
        return
    if not isinstance(cfg, dict):  # a string would be a config path or a preset name
        return
    try:
        sfanav.Network(cfg)
    except (ValueError, TypeError):
        pass


def bag_one(data: bytes) -> None:
    name = next((n for magic, n in BAG_KINDS if data.startswith(magic)), "input.bag")
    for p in _BAGS.iterdir():
        p.unlink()
    path = _BAGS / name
    path.write_bytes(data)
    out = _DIR / "dataset"
    try:
        bag_info(path).describe()
        sfanav.Dataset.from_bag(path, out, odom_topic="/odom", overwrite=True, log=lambda m: None)
    except (ValueError, TypeError):
        left = sorted(p.name for p in _DIR.iterdir() if p.name not in ("bags", "input.sfa", "dataset"))
        if left:
            raise AssertionError(f"a failed import left {left} behind") from None


def _mutator(structured):
    def mutate(data: bytes, max_size: int, seed: int) -> bytes:
        if random.Random(seed).random() < 0.85:
            try:
                out = structured(data, seed)
            except RecursionError:  # a deeply nested input: mutate its bytes instead
                out = None
            if out is not None and len(out) <= max_size:
                return out
        return atheris.Mutate(data, max_size)

    return mutate


TARGETS = {"model": (model_one, mutate_model), "config": (config_one, mutate_config), "bag": (bag_one, mutate_bag)}


def main() -> None:
    if len(sys.argv) < 2 or sys.argv[1] not in TARGETS:
        sys.exit(f"usage: {sys.argv[0]} {{{','.join(TARGETS)}}} [libFuzzer arguments]")
    one, structured = TARGETS[sys.argv.pop(1)]
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))
    os.environ.setdefault("RUST_BACKTRACE", "0")
    atheris.Setup(sys.argv, one, custom_mutator=_mutator(structured))
    atheris.Fuzz()


if __name__ == "__main__":
    main()
