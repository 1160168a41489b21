"""Landmark models (thesis 5.4) on the 5.4 scenes: view and readout variants.

Reads the simulated datasets that ``sfanav experiment 5.4 --out OUT`` made
(OUT/data/thesis-5.4-*-seed0), extracts the marker views once per margin
(cached under OUT/cache/) and compares, on the test walk: each marker's own
readout, the stacked readout (the thesis's: quadratic on 8 outputs per marker
and a flag each), and variants named on the command line.

    PYTHONPATH=python python3 scripts/investigations/landmarks_variants.py OUT [--margin 50] [--occlusion]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from sfanav.data.dataset import Dataset
from sfanav.landmarks import LandmarkLocalizer, MarkerViews, ViewExtractor
from sfanav.localization.error_metrics import med
from sfanav.localization.readouts import make_readout


def views_of(out: Path, preset: str, margin: float, size: int) -> dict[str, tuple[MarkerViews, np.ndarray]]:
    cache = out / "cache" / f"{preset}-m{margin:g}-s{size}.npz"
    ids = (136, 144)
    if cache.exists():
        z = np.load(cache)
        return {r: (MarkerViews(ids, z[f"{r}_views"], z[f"{r}_found"], z[f"{r}_angles"], z[f"{r}_corners"]),
                    z[f"{r}_xy"]) for r in ("train", "test")}
    ds = Dataset(out / "data" / f"{preset}-seed0")
    ex = ViewExtractor(ids, size=size, margin=margin)
    res = {}
    for r in ("train", "test"):
        part = ds.select(run=r)
        t0 = time.perf_counter()
        res[r] = (ex.transform(part.images(batch_size=32)), part.poses[:, :2].copy())
        print(f"{preset} {r}: {len(part)} frames in {time.perf_counter() - t0:.0f} s, found "
              f"{np.round(100 * res[r][0].detection_rate(), 1)} %", file=sys.stderr)
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, **{f"{r}_{k}": (getattr(v, k) if k != "xy" else xy) for r, (v, xy) in res.items()
                       for k in ("views", "found", "angles", "corners", "xy")})
    return res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=Path)
    ap.add_argument("--margin", type=float, default=50.0)
    ap.add_argument("--size", type=int, default=120)
    ap.add_argument("--occlusion", action="store_true")
    ap.add_argument("--n-outputs", default="8", help="comma-separated outputs per marker to try")
    ap.add_argument("--ridges", default="0", help="comma-separated ridge values of the quadratic readouts")
    ap.add_argument("--gp", action="store_true", help="also a GP readout of the stack")
    args = ap.parse_args()
    preset = "thesis-5.4-occlusion" if args.occlusion else "thesis-5.4-landmarks"
    d = views_of(args.out, preset, args.margin, args.size)
    (V_tr, xy_tr), (V_te, xy_te) = d["train"], d["test"]
    results = []
    for n in (int(v) for v in args.n_outputs.split(",")):
        base = LandmarkLocalizer(ViewExtractor((136, 144), size=args.size, margin=args.margin), n_outputs=n)
        t0 = time.perf_counter()
        base.fit_views(V_tr, xy_tr)
        fit_s = time.perf_counter() - t0
        S_tr, S_te = base.stack(V_tr), base.stack(V_te)
        F = {m: (base.marker_features(V_tr, m), base.marker_features(V_te, m)) for m in base.ids}
        for ridge in (float(v) for v in args.ridges.split(",")):
            row = {"preset": preset, "margin": args.margin, "n_outputs": n, "ridge": ridge, "fit_s": round(fit_s, 1)}
            for m, ((Ftr, itr), (Fte, ite)) in F.items():
                r = make_readout({"kind": "quadratic", "n_outputs": n, "ridge": ridge}).fit(Ftr, xy_tr[itr])
                row[f"marker {m}"] = med(r.predict(Fte), xy_te[ite])
                row[f"marker {m} train"] = med(r.predict(Ftr), xy_tr[itr])
            r = make_readout({"kind": "quadratic", "n_outputs": S_tr.shape[1], "ridge": ridge}).fit(S_tr, xy_tr)
            row["stacked"] = med(r.predict(S_te), xy_te)
            row["stacked train"] = med(r.predict(S_tr), xy_tr)
            both = V_te.found.all(axis=1)
            row["stacked, both found"] = med(r.predict(S_te[both]), xy_te[both])
            results.append(row)
            print(json.dumps(row))
        if args.gp:
            r = make_readout({"kind": "gp", "n_outputs": S_tr.shape[1]}).fit(S_tr, xy_tr)
            print(json.dumps({"preset": preset, "n_outputs": n, "readout": "gp", "stacked": med(r.predict(S_te), xy_te)}))


if __name__ == "__main__":
    main()
