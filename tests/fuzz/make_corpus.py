#!/usr/bin/env python3
"""Writes the committed seed corpus of the fuzz targets (small model files
of every kind, JSON network configs, and small ROS bags: ROS 1 with plain,
bz2 and lz4 chunks, ROS 2 MCAP and SQLite files; raw, JPEG and PNG images):
``python3 tests/fuzz/make_corpus.py``."""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import sfanav

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # tests/: bagtools


def main() -> None:
    models, configs = HERE / "corpus" / "model", HERE / "corpus" / "config"
    models.mkdir(parents=True, exist_ok=True)
    configs.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    X = rng.normal(size=(200, 4)).cumsum(0)
    sfanav.SFA(2).fit(X).save(models / "sfa-linear.sfa")
    sfanav.SFA(2, degree=2, reduce_to=3).fit(X).save(models / "sfa-reduce.sfa")
    sfanav.SFA(2, degree=2).partial_fit(X).save(models / "sfa-training.sfa")
    sfanav.SFA(3).save(models / "sfa-unfitted.sfa")
    cfg = {"input": {"width": 24, "height": 4, "channels": 1},
           "layers": [{"rf": [6, 4], "stride": [6, 4], "out": 4}, {"rf": "full", "out": 3}]}
    imgs = rng.random((30, 4, 24)).cumsum(0)
    net = sfanav.Network(cfg).fit(imgs, sfanav.Rotation(step=6), progress=False)
    net.save(models / "network.sfa")
    xy = rng.random((len(imgs), 2))
    for name, readout in (("quadratic", "quadratic"), ("knn", {"kind": "knn", "n_outputs": 3, "k": 3}),
                          ("gp", {"kind": "gp", "n_outputs": 3})):
        sfanav.Localizer(net, n_outputs=3, readout=readout).fit(imgs, xy).save(models / f"localizer-{name}.sfa")
    for name in ("thesis-5.1", "sfanav-default"):
        (configs / f"{name}.json").write_text(json.dumps(sfanav.Network.from_preset(name).config))
    (configs / "tiny.json").write_text(json.dumps(cfg))
    (configs / "unshared.json").write_text(json.dumps({**cfg, "network": {"weight_sharing": False}}))
    bags = HERE / "corpus" / "bag"
    bags.mkdir(parents=True, exist_ok=True)
    write_bags(bags)
    for p in sorted(models.iterdir()) + sorted(configs.iterdir()) + sorted(bags.iterdir()):
        print(f"{p.stat().st_size:8d}  {p.relative_to(HERE)}")


def write_bags(folder: Path) -> None:
    """Small bags the bag target starts from: three 4x6 images on /cam and
    PoseStamped odometry on /odom, in every storage and chunk compression
    sfanav reads (a ROS 2 bag as its single .mcap or .db3 file)."""
    from bagtools import (
        compressed_image,
        good_images,
        jpeg_bytes,
        png_bytes,
        raw_image,
        write_camera_bag,
    )

    imgs = good_images(3, h=4, w=6)
    raw = [raw_image(i) for i in imgs]
    jpeg = [compressed_image(jpeg_bytes(i)) for i in imgs]
    png = [compressed_image(png_bytes(i), "png") for i in imgs]
    for name, images, kw in (("ros1-raw.bag", raw, {}), ("ros1-bz2.bag", raw, {"compression": "bz2"}),
                             ("ros1-lz4-jpeg.bag", jpeg, {"compression": "lz4"}),
                             ("ros1-bz2-png.bag", png, {"compression": "bz2"})):
        (folder / name).unlink(missing_ok=True)
        write_camera_bag(folder / name, images, **kw)
    with tempfile.TemporaryDirectory() as tmp:
        for name, images, storage in (("ros2-raw.mcap", raw, "mcap"), ("ros2-png.db3", png, "sqlite3")):
            bag = write_camera_bag(Path(tmp) / name.split(".")[0], images, ros=2, storage=storage)
            (folder / name).write_bytes(next(bag.glob(f"*.{name.split('.')[1]}")).read_bytes())


if __name__ == "__main__":
    main()
