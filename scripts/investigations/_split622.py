"""Shared by the 6.2.2 readout studies (readout_*_622.py): the split of the experiment's product rows (first
permutation: nine recordings in place-major order, the tenth as test) and the product trained on it as
`sfanav experiment 6.2.2` trains it, with the samples its readout was fitted on."""
from __future__ import annotations

import time
from typing import Any

import numpy as np
from sfanav.data import Dataset
from sfanav.data.preprocessing import Preprocessing
from sfanav.data.sources import load_run
from sfanav.experiments.product_rows import configuration as product_configuration
from sfanav.localization.localizer import Localizer
from sfanav.loopclosure.conditions import correspondences, place_major_order
from sfanav.pipeline import train_localizer


def trained_split(data: str, *, groups: bool = True) -> dict[str, Any]:
    """The product trained on 6.2.2's split of the dataset DATA (``groups``: told which recording each image comes
    from, as the experiment does since 2026-12-07). Returns the localizer ``loc``, the readout's training samples
    ``X`` (images and corrupted copies interleaved, slow features then signature), ``Y``, their recordings
    ``groups``, the test run's readout features ``X_te``, images ``images_te`` and positions ``xy_te``, and the
    training time."""
    ds = Dataset(data)
    conds = sorted(set(ds.conditions.tolist()), key=lambda c: int(c.lstrip("c")) if c.lstrip("c").isdigit() else c)
    perm = np.random.default_rng(0).permutation(len(conds))
    train, test = perm[:9], perm[9]
    make_net, recipe = product_configuration(False)
    prep = Preprocessing.for_network(make_net())
    recs = [load_run(ds.select(condition=c), prep) for c in conds]
    places = [correspondences(recs[0][1], r[1]) for r in recs]
    order = place_major_order([places[s] for s in train])
    X = np.concatenate([recs[s][0] for s in train])[order]
    xy = np.concatenate([recs[s][1] for s in train])[order]
    rec = np.concatenate([np.full(len(recs[s][1]), conds[s]) for s in train])[order]
    X_te, xy_te = recs[test]
    elev = tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))
    seen: dict[str, Any] = {}
    orig = Localizer._fit_samples

    def spy(self: Any, *a: Any) -> Any:  # the samples the readout sees: originals and copies, paired
        seen["args"] = a
        return orig(self, *a)

    Localizer._fit_samples = spy
    t = time.perf_counter()
    try:
        loc = train_localizer(X, xy=xy, supervision="ground-truth", network=make_net(), recipe=recipe,
                              camera_elevation=elev, seed=0, groups=rec if groups else None)
    finally:
        Localizer._fit_samples = orig
    seconds = time.perf_counter() - t
    F, Y, G, g, _ = seen["args"]
    return {"loc": loc, "X": np.hstack([F, G]), "Y": np.asarray(Y, float), "groups": g,
            "X_te": loc.readout_features(loc.features(X_te), loc.signatures(X_te)), "xy_te": xy_te, "images_te": X_te,
            "seconds": seconds}
