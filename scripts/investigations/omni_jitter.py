"""Why centre jitter does not help on the 5.2.3 scene: variants of the
uneven ground and of the jitter, thesis configuration (and the sfanav
default where named), MED on the test walk.

Needs the datasets of ``sfanav experiment 5.2.3 --out DIR`` (under
``DIR/data``). Re-renders the uneven scene twice from its poses and attitudes:
tilt only (no height change) and height change only (no tilt). Then trains:

* each ground (flat, tilt only, bob only, both) without jitter;
* tilt only and both with +-5 px jitter;
* both with +-2.5 px jitter;
* both with +-5 px jitter for the network, the readout fitted to the
  unjittered training images' features;

and writes ``OUT/omni-jitter.json``. ``--variants`` runs others instead,
each ``CONFIG:GROUND:JITTER[:plain]`` (CONFIG ``thesis`` or ``default``,
GROUND ``flat``, ``tilt``, ``bob`` or ``both``, ``plain``: the readout on the
unjittered features), written to ``OUT/omni-jitter-variants.json``.

    PYTHONPATH=python python3 scripts/investigations/omni_jitter.py DIR OUT [--default]
    PYTHONPATH=python python3 scripts/investigations/omni_jitter.py DIR OUT --variants thesis:both:2.5:plain ...
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from sfanav import sim
from sfanav.data import Dataset, Preprocessing, load_run, write_dataset
from sfanav.localization import fit_localizer
from sfanav.localization.recipe import default_network, default_rows
from sfanav.sfa.network import Network, Rotation

SEED = 0


def rerender(src: Path, dst: Path, *, tilt: bool, height: bool) -> Dataset:
    if (dst / "metadata.json").exists():
        return Dataset(dst)
    ds = Dataset(src)
    cam = sim.camera_from_dict(ds.metadata["camera"])
    r = sim.Renderer(sim.World.load(src / "world.json"))
    roll, pitch, dz = (ds.column(c).astype(float) for c in ("roll_deg", "pitch_deg", "camera_dz_m"))

    def imgs():
        for k in range(len(ds)):
            att = sim.Attitude(roll[k] if tilt else 0.0, pitch[k] if tilt else 0.0, dz[k] if height else 0.0)
            yield r.render(cam, ds.poses[k], float(ds.timestamps[k]), attitude=att)

    meta = {"camera": ds.metadata["camera"], "source": f"{src} re-rendered, tilt={tilt}, height={height}"}
    return write_dataset(dst, imgs(), ds.poses, runs=ds.runs, timestamps=ds.timestamps, metadata=meta)


def med(loc, X, xy) -> float:
    return float(np.hypot(*(loc.predict(X) - xy).T).mean())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("data", type=Path, help="the 5.2.3 experiment's output directory")
    ap.add_argument("out", type=Path)
    ap.add_argument("--default", action="store_true", help="also the sfanav default on tilt only")
    ap.add_argument("--variants", nargs="+", default=None, metavar="CONFIG:GROUND:JITTER[:plain]")
    a = ap.parse_args()
    root = a.data / "data"
    both = root / f"thesis-5.2.3-outdoor-seed{SEED}"
    grounds = {"flat": Dataset(root / f"thesis-5.2.3-outdoor-seed{SEED}-flat"), "both": Dataset(both),
               "tilt only": rerender(both, a.out / "tilt-only", tilt=True, height=False),
               "bob only": rerender(both, a.out / "bob-only", tilt=False, height=True)}
    mirror = (199.5, 199.5, 121.4, 199.5)  # as the experiment estimated it (the camera's: 199.5, 121.6, 199)
    makers = {"thesis configuration": (lambda: Network.from_preset("thesis-5.3", out=12), True),
              "sfanav default": (default_network, False)}
    if a.variants is None:
        todo = [("thesis configuration", g, j, p) for g, j, p in (
            ("flat", 0.0, False), ("tilt only", 0.0, False), ("bob only", 0.0, False), ("both", 0.0, False),
            ("tilt only", 5.0, False), ("both", 5.0, False), ("both", 2.5, False), ("both", 5.0, True))]
        if a.default:
            todo += [("sfanav default", "tilt only", 0.0, False), ("sfanav default", "tilt only", 5.0, False)]
    else:
        names = {"thesis": "thesis configuration", "default": "sfanav default", "flat": "flat",
                 "tilt": "tilt only", "bob": "bob only", "both": "both"}
        todo = []
        for v in a.variants:
            parts = v.split(":")
            todo.append((names[parts[0]], names[parts[1]], float(parts[2]), parts[3:] == ["plain"]))
    results = []
    for name, ground, jitter, plain_readout in todo:
        make, thesis = makers[name]
        prep = Preprocessing.for_network(make(), normalize=thesis)
        kw = ({"readout": "quadratic", "n_outputs": 8} if thesis else
              {"readout": "auto", "rows": default_rows((-30.0, 20.0)), "signature": "fourier"})
        ds = grounds[ground]
        tr, te = ds.select(run="train"), ds.select(run="test")
        X, xy = load_run(tr, prep, mirror=mirror, jitter=jitter, seed=SEED if jitter else None, log=lambda m: None)
        Xt, xyt = load_run(te, prep, mirror=mirror, log=lambda m: None)
        t0 = time.perf_counter()
        loc = fit_localizer(make(), X, xy, rotation=Rotation(step=5), prep=prep, progress=False, **kw)
        if plain_readout:
            X0, _ = load_run(tr, prep, mirror=mirror, log=lambda m: None)
            F0 = loc.transform_rows(loc.rows(X0) if loc.rows is not None else X0)
            loc.fit_features(F0, xy, signatures=loc.signatures(X0) if loc.n_signature_ else None)
        row = {"configuration": name, "ground": ground, "jitter_px": jitter,
               "readout on unjittered features": plain_readout, "med": med(loc, Xt, xyt),
               "train_med": loc.train_metrics_["med"], "seconds": round(time.perf_counter() - t0, 1)}
        print(json.dumps(row), flush=True)
        results.append(row)
    a.out.mkdir(parents=True, exist_ok=True)
    name = "omni-jitter.json" if a.variants is None else "omni-jitter-variants.json"
    (a.out / name).write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
