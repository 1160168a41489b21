#!/usr/bin/env python3
"""What each candidate means against camera corruptions costs and buys (docs/robustness.md): the sfanav
default's network trained on a clean exploration run, tested on the clean test run and on corrupted copies
of it (the corruption applied at the images' own resolution), in four gardens; MED per corruption and its
ratio to the candidate's clean MED, and the clean MED against robustness "none" (the default before).

Candidates (all the sfanav default's network, rows, pooling, signature and readout):

* none: nothing (the default before the corruption study);
* photometric: the log-contrast normalisation alone;
* row-gain: every row and channel divided by its mean (a per-row normalisation, which also removes
  vignetting) instead;
* channel-gain: every channel divided by its image mean (exposure and white balance without the log);
* readout: the readout fitted on a corrupted copy of the run as well (CAMERA), no normalisation;
* light: photometric + readout (the default);
* full: light + the network's invariance partners (CAMERA, weight 1);
* full-0.5: the same at weight 0.5;
* full-0.25: the same at weight 0.25;
* full-24: full with 24 top outputs, all read out (does capacity buy back the precision the invariance costs?);
* jpeg-invariance: light + invariance partners that are JPEG round trips only (quality 50..95).

    for p in suite-inner suite-control suite-dense-trees; do sfanav simulate --preset $p --seed 1 --out runs/cand/$p; done
    sfanav simulate --preset demo --out runs/cand/demo
    PYTHONPATH=python python3 scripts/investigations/robustness_candidates.py runs/cand \\
        --json docs/results/investigations/robustness-candidates.json
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.data.corruptions import CAMERA, CorruptionModel, corrupt
from sfanav.data.preprocessing import Preprocessor
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.localization.training import fit_localizer
from sfanav.sfa import Rotation

GARDENS = {"suite-inner": ("train-grid", "test-walk"), "demo": ("train", "test"),
           "suite-control": ("train-grid", "test-walk"), "suite-dense-trees": ("train-grid", "test-walk")}
CORRUPTIONS = ["jpeg-90", "jpeg-50", "noise-10", "defocus-1", "defocus-2", "motion-blur", "exposure-1.5",
               "gamma-1.4", "white-balance", "vignetting", "dead-pixels"]
JPEG_ONLY = CorruptionModel({"jpeg": {"kind": "jpeg", "quality": (50, 95)}})


def row_gain(images):
    a = np.asarray(images, np.float32)
    return a / np.maximum(a.mean(axis=2, keepdims=True), 8.0) * 100.0


def channel_gain(images):
    a = np.asarray(images, np.float32)
    return a / np.maximum(a.mean(axis=(1, 2), keepdims=True), 4.0) * 100.0


CANDIDATES = {
    "none": ({"robustness": "none"}, None),
    "photometric": ({"robustness": "none", "photometric": "log-contrast"}, None),
    "row-gain": ({"robustness": "none"}, row_gain),
    "channel-gain": ({"robustness": "none"}, channel_gain),
    "readout": ({"robustness": "none", "readout_augmentation": CAMERA}, None),
    "light": ({"robustness": "light"}, None),
    "full": ({"robustness": "full"}, None),
    "full-0.5": ({"robustness": "full", "invariance_weight": 0.5}, None),
    "full-0.25": ({"robustness": "full", "invariance_weight": 0.25}, None),
    "full-24": ({"robustness": "full", "n_outputs": 24, "network": {"out": 24}}, None),
    "jpeg-invariance": ({"robustness": "light", "invariance": JPEG_ONLY}, None),
}


class _Normalised:
    def __init__(self, f, loc):
        self.f, self.loc = f, loc

    def predict(self, X):
        return self.loc.predict(self.f(X))


def train(name, X, xy, elev):
    opts, pre = CANDIDATES[name]
    opts = dict(opts)
    kw = recipe_for(robustness=opts.pop("robustness")).fit_kwargs(elev)
    net = default_network(**opts.pop("network", {}))
    kw.update(opts)
    if pre is None:
        return fit_localizer(net, X, xy, rotation=Rotation(5, 1.0), progress=False, **kw)
    return _Normalised(pre, fit_localizer(net, pre(X), xy, rotation=Rotation(5, 1.0), progress=False, **kw))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("root", help="folder with one simulated dataset per garden (named as the preset)")
    ap.add_argument("--candidates", default=",".join(CANDIDATES))
    ap.add_argument("--gardens", default=",".join(GARDENS))
    ap.add_argument("--json")
    a = ap.parse_args()
    out = json.loads(Path(a.json).read_text()) if a.json and Path(a.json).exists() else {}
    prep = Preprocessing.for_network(default_network())
    for g in a.gardens.split(","):
        ds = Dataset(Path(a.root) / g)
        cam = ds.metadata["camera"]
        native = Preprocessing(int(cam["width"]), int(cam["height"]), False)
        tr, te = GARDENS[g]
        X0, xy = load_run(ds.select(run=tr), native, log=lambda m: None)
        T0, xyt = load_run(ds.select(run=te), native, log=lambda m: None)
        conform = Preprocessor(prep, log=lambda *m, **k: None)
        X = conform(X0)
        tests = {"clean": conform(T0), **{c: conform(corrupt(T0, c, seed=1)) for c in CORRUPTIONS}}
        elev = tuple(cam["elevation_deg"])
        for name in a.candidates.split(","):
            t0 = time.perf_counter()
            model = train(name, X, xy, elev)
            secs = time.perf_counter() - t0
            med = {c: localization_metrics(model.predict(T), xyt)["med"] for c, T in tests.items()}
            out[f"{g}|{name}"] = {"MED (m)": med, "training (s)": secs}
            ratios = {c: v / med["clean"] for c, v in med.items() if c != "clean"}
            print(f"{g:18s} {name:16s} clean {med['clean']:.3f} worst x{max(ratios.values()):.2f} "
                  f"train {secs:.0f} s | " + " ".join(f"{c} {r:.2f}" for c, r in ratios.items()), flush=True)
            if a.json:
                Path(a.json).write_text(json.dumps(out, indent=1) + "\n")
    summary = {}
    for name in a.candidates.split(","):
        cells = [out[f"{g}|{name}"]["MED (m)"] for g in a.gardens.split(",") if f"{g}|{name}" in out]
        base = [out[f"{g}|none"]["MED (m)"]["clean"] for g in a.gardens.split(",") if f"{g}|none" in out]
        if not cells:
            continue
        worst = max(max(v for c, v in m.items() if c != "clean") / m["clean"] for m in cells)
        cost = float(np.exp(np.mean(np.log([m["clean"] / b for m, b in zip(cells, base)])))) if base else None
        summary[name] = {"worst ratio to own clean": worst, "clean / none (geometric mean)": cost}
        print(f"{name:16s} worst x{worst:.2f}, clean / none {cost:.2f}" if cost else name, flush=True)
    out["summary"] = summary
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
