"""Photometric normalisation candidates against gamma and the other corruptions,
on the demo garden (docs/robustness.md, "Gamma and the order of low-pass and
logarithm").

The sfanav default (robustness "standard") is trained on the clean
exploration run with each candidate in place of the default's
``lowpass_log_contrast`` (or, for ``gamma-partners``, with gamma added to the
camera corruption model its invariance partners and readout copies are drawn
from), then localizes the test run clean and under ten corruptions
(applied at the images' own 600x60, as the corruption suite does). MED in m.

* ``current``: 2 px Gaussian low-pass of the intensities, log(I + 8), flat
  field, fixed contrast (the default);
* ``log-first-8`` / ``log-first-2``: the logarithm (offset 8 / 2 grey levels)
  before the 2 px low-pass, so that a gamma (a scale of the logarithm) commutes
  with the low-pass and the contrast step removes it;
* ``pre-1``: 1 px low-pass of the intensities, log(I + 8), 1.73 px low-pass
  of the logarithm (2 px in all);
* ``gamma-partners``: the default's normalisation, gamma 0.6..1.6 added to
  the camera corruption model.

    PYTHONPATH=python python3 scripts/investigations/photometric_variants.py /path/to/demo-dataset out.json [VARIANT ...]

The dataset is the demo's (``sfanav simulate demo``, seed 0). About 7 min per
variant on 2 cores.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

import sfanav.data.photometric as ph
import sfanav.localization.recipe as rc
from sfanav import Dataset
from sfanav.data.corruptions import CAMERA, CorruptionModel, corrupt
from sfanav.data.preprocessing import Preprocessing, Preprocessor
from sfanav.data.sources import load_run
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.pipeline import train_localizer

VARIANTS = ("current", "log-first-8", "log-first-2", "pre-1", "gamma-partners")
CORRUPTIONS = ("gamma-0.7", "gamma-1.4", "jpeg-50", "jpeg-90", "defocus-2", "noise-10", "exposure-1.5",
               "white-balance", "exposure-0.6")
ORIGINAL = ph.lowpass_log_contrast


def log_then_lowpass(offset: float, pre: float = 0.0):
    """A normalisation: ``pre`` px low-pass of the intensities, log(I +
    offset), the rest of the 2 px low-pass on the logarithm, flat field,
    fixed contrast."""
    def f(images, *, sigma=ph.LOWPASS_SIGMA, offset_=offset, scale=ph.LOG_SCALE, flat=True, **_):
        a = ph.as_image_batch(images)
        modes = ("nearest", "wrap", "nearest")[: a.ndim - 1]
        post = float(np.sqrt(max(sigma**2 - pre**2, 0.0)))
        h = a.shape[1]
        t = np.linspace(-1.0, 1.0, h)
        V = np.stack([np.ones(h), t, t * t], axis=1)[:, : min(3, h)]
        P = (V @ np.linalg.pinv(V)).astype(np.float32)
        out = np.empty(a.shape, np.float32)
        for i, im in enumerate(a):
            v = im.astype(np.float32)
            if pre > 0:
                v = gaussian_filter(v, (pre, pre, 0.0)[: a.ndim - 1], mode=modes)
            v = np.log(np.maximum(v, 0.0) + np.float32(offset_))
            if post > 0:
                v = gaussian_filter(v, (post, post, 0.0)[: a.ndim - 1], mode=modes)
            v -= (P @ v.mean(axis=1).reshape(h, -1)).reshape((h, 1) + v.shape[2:])
            sd = float(v.std(dtype=np.float64))
            out[i] = v * np.float32(scale / sd) if sd > 1e-6 else v
        return out
    return f


def use(variant: str) -> None:
    ph.lowpass_log_contrast = ORIGINAL
    rc.Recipe.robust_kwargs.__defaults__ = (CAMERA,)
    if variant == "log-first-8":
        ph.lowpass_log_contrast = log_then_lowpass(8.0)
    elif variant == "log-first-2":
        ph.lowpass_log_contrast = log_then_lowpass(2.0)
    elif variant == "pre-1":
        ph.lowpass_log_contrast = log_then_lowpass(8.0, pre=1.0)
    elif variant == "gamma-partners":
        families = dict(CAMERA.families)
        families["gamma"] = {"kind": "gamma", "gamma": (0.6, 1.6)}
        rc.Recipe.robust_kwargs.__defaults__ = (CorruptionModel(families),)
    elif variant != "current":
        raise SystemExit(f"unknown variant {variant!r}; use {', '.join(VARIANTS)}")


def main(data: Path, out: Path, variants: list[str]) -> None:
    ds = Dataset(data)
    cam = ds.metadata["camera"]
    elev = tuple(cam.get("elevation_deg", (-30.0, 20.0)))
    native = Preprocessing(int(cam["width"]), int(cam["height"]), False)
    X0_tr, xy_tr = load_run(ds.select(run="train"), native)
    X0_te, xy_te = load_run(ds.select(run="test"), native)
    conform = Preprocessor(Preprocessing.for_network(default_network()), log=lambda *a, **k: None)
    res = {"command": "scripts/investigations/photometric_variants.py " + " ".join(sys.argv[1:]),
           "dataset": str(data), "variants": {}}
    for v in variants:
        use(v)
        t0 = time.time()
        loc = train_localizer(conform(X0_tr), xy=xy_tr, network=default_network(), recipe=recipe_for(),
                              camera_elevation=elev, seed=0)
        med = {}
        for name in ("clean",) + CORRUPTIONS:
            X = conform(X0_te if name == "clean" else corrupt(X0_te, name, seed=1))
            med[name] = float(np.median(np.hypot(*(loc.predict(X) - xy_te).T)))
            print(v, name, round(med[name], 4), flush=True)
        res["variants"][v] = {"train_s": time.time() - t0, "med": med,
                              "worst_ratio_to_clean": max(m / med["clean"] for m in med.values())}
    use("current")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(res, indent=1) + "\n")
    os.replace(tmp, out)


if __name__ == "__main__":
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3:] or list(VARIANTS))
