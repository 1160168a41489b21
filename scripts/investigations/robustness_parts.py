#!/usr/bin/env python3
"""Which part of the sfanav default's robustness costs precision on clean images, on an experiment's scene: the
default (robustness "standard", supervised, no feedback) trained with each part alone or left out, the clean test
run's MED (docs/robustness.md, "The clean cost on 5.1.3's coarse images").

    sfanav simulate --preset thesis-5.1.1-grid --size 200x20 --seed 0 --out runs/grid200     # 5.1.3's images
    PYTHONPATH=python python3 scripts/investigations/robustness_parts.py 5.1.3 runs/grid200 OUT.json [VARIANT ...]

Variants (the recipe's fit_localizer arguments changed): "none" (no robustness), "photometric only",
"photometric + readout copies" (robustness "light"), "photometric + invariance partners", "standard" (the default),
"readout copies + invariance partners" (no photometric normalisation), and the default with its normalisation
changed (sfanav.data.photometric.lowpass_log_contrast replaced): "standard, no flat field" (the log image's mean
removed instead of its rows' quadratic profile), "standard, no fixed contrast" (the images' own log contrast kept,
times the fixed scale). Adds OUT.json[NAME][variant] =
{"MED (m)", "seconds"}; about a minute a variant on 5.1.3's 624 frames.
"""

from __future__ import annotations

import functools
import sys
import time
from pathlib import Path

import sfanav.data.photometric as ph
from _feedback_scene import add_entry
from sfanav.data import Dataset
from sfanav.experiments.product_rows import product_runs
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.recipe import CAMERA_ELEVATION, default_network, recipe_for
from sfanav.localization.training import fit_localizer
from sfanav.pipeline import ROTATION_STEP
from sfanav.sfa.network import Rotation

VARIANTS = {
    "none": None,
    "photometric only": {"readout_augmentation": None, "invariance": None},
    "photometric + readout copies": {"invariance": None},
    "photometric + invariance partners": {"readout_augmentation": None},
    "standard": {},
    "readout copies + invariance partners": {"photometric": None, "lowpass": None},
    "standard, no flat field": {},
    "standard, no fixed contrast": {},
}


def _no_fixed_contrast(images, *, sigma=ph.LOWPASS_SIGMA, offset=ph.LOG_OFFSET, scale=ph.LOG_SCALE, flat=True):
    """lowpass_log_contrast without its last step (each image scaled to a fixed contrast): the log intensities'
    deviation from the flat field, times ``scale`` / 1.0 (the training images' own contrast kept)."""
    import numpy as np
    from scipy.ndimage import gaussian_filter

    a = np.asarray(images)
    sy, sx = ph.lowpass_widths(sigma)
    out = np.empty(a.shape, np.float32)
    h = a.shape[1]
    t = np.linspace(-1.0, 1.0, h)
    V = np.stack([np.ones(h), t, t * t], axis=1)
    P = (V @ np.linalg.pinv(V)).astype(np.float32)
    for i, im in enumerate(a):
        v = gaussian_filter(im.astype(np.float32), (sy, sx, 0.0)[: a.ndim - 1], mode=("nearest", "wrap", "nearest")[: a.ndim - 1])
        v = np.log(np.maximum(v, 0.0) + np.float32(offset))
        v -= (P @ v.mean(axis=1).reshape(h, -1)).reshape((h, 1) + v.shape[2:])
        out[i] = v * np.float32(scale)
    return out


PATCHES = {"standard, no flat field": functools.partial(ph.lowpass_log_contrast, flat=False),
           "standard, no fixed contrast": _no_fixed_contrast}


ORIGINAL = ph.lowpass_log_contrast


def main() -> None:
    if len(sys.argv) < 4 or any(v not in VARIANTS for v in sys.argv[4:]):
        sys.exit(__doc__)
    name, root, out_path = sys.argv[1], sys.argv[2], Path(sys.argv[3])
    ds = Dataset(root)
    elev = tuple(ds.metadata.get("camera", {}).get("elevation_deg", CAMERA_ELEVATION))
    train, (test,) = product_runs(ds, default_network())
    height = train.images.shape[1]
    for label in sys.argv[4:] or VARIANTS:
        change = VARIANTS[label]
        kw = (recipe_for(robustness="none") if change is None else recipe_for()).fit_kwargs(elev, height)
        kw.update(change or {})
        ph.lowpass_log_contrast = PATCHES.get(label, ORIGINAL)  # what normalize() calls
        t0 = time.perf_counter()
        loc = fit_localizer(default_network(), train.images, train.xy, rotation=Rotation(step=ROTATION_STEP),
                            progress=False, **kw)
        entry = {"MED (m)": localization_metrics(loc.predict(test.images), test.xy)["med"],
                 "seconds": time.perf_counter() - t0}
        add_entry(out_path, name, {label: entry}, merge=True)


if __name__ == "__main__":
    main()
