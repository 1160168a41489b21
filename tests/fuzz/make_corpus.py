#!/usr/bin/env python3
"""Writes the committed seed corpus of the fuzz targets (small model files
of every kind and JSON network configs): ``python3 tests/fuzz/make_corpus.py``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import sfanav

HERE = Path(__file__).resolve().parent


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
    for p in sorted(models.iterdir()) + sorted(configs.iterdir()):
        print(f"{p.stat().st_size:8d}  {p.relative_to(HERE)}")


if __name__ == "__main__":
    main()
