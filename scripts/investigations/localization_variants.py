"""Training variants (graph weights) on a thesis localization scene, beside
the thesis configuration: transition weight between consecutive images and
supervised spatial pairs (graph-based SFA). Does not change the thesis
experiments; reads a dataset they simulated.

    PYTHONPATH=python python3 scripts/investigations/localization_variants.py DATASET OUT \\
        --variant "thesis" --variant "tw=70" --variant "pairs r=1.3 k=4 gap=2 w=1"

Variant syntax: ``thesis``; ``tw=<w>``; ``pairs r=<radius m> k=<k> gap=<min_gap> w=<weight> [shifted]`` (ground-truth
positions of the training run; ``shifted``: each pair at a random relative orientation; ``layers=3,4``: pairs only in those layers), optionally `` tw=<w>``. Per variant: Table 5.1 network (thesis-5.1
preset, 12 outputs, double precision as in the 5.1.1 experiment), rotation 5 px, 100 % window; the thesis's
quadratic regression on the 8 slowest outputs (training grid -> test grid, and the thesis's random 50/50 splits
of the test grid), kNN and kernel ridge chosen by blocked CV on the training run; max eta_phi (outputs 1-8).
Writes OUT/variants.json and OUT/variants.md.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from threadpoolctl import threadpool_limits

from sfanav.localization.plots import plot_firing_maps
from sfanav.sfa.diagnostics import eta_values, orientation_angles
from sfanav.data import Dataset
from sfanav.experiments.gardens import THESIS_SPEC, random_splits_errors
from sfanav.localization import localization_metrics
from sfanav.sfa import Network, Rotation, spatial_pairs
from sfanav.localization import default_candidates, make_readout, select_readout
from sfanav.localization.readouts import describe_spec
from sfanav.data import Preprocessing, load_run
from sfanav.localization.evaluation import coordinate_range


def parse(v: str) -> dict:
    opts: dict = {"transition_weight": 1.0, "pairs": None, "pair_layers": None}
    for tok in v.split():
        if tok.startswith("layers="):
            opts["pair_layers"] = [int(x) for x in tok.split("=")[1].split(",")]
            continue
        if tok == "shifted":
            opts["pairs"]["shifts"] = True
            continue
        if tok in ("thesis", "pairs"):
            if tok == "pairs":
                opts["pairs"] = {}
            continue
        key, val = tok.split("=")
        if key == "tw":
            opts["transition_weight"] = float(val)
        else:
            opts["pairs"][{"r": "radius", "k": "k", "gap": "min_gap", "w": "weight"}[key]] = float(val)
    return opts


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset")
    ap.add_argument("out")
    ap.add_argument("--variant", action="append", default=[])
    ap.add_argument("--precision", default="double")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    ds = Dataset(a.dataset)
    net0 = Network.from_preset("thesis-5.1", out=12, precision=a.precision)
    prep = Preprocessing.for_network(net0)
    X_tr, xy_tr = load_run(ds.select(run="train"), prep)
    X_te, xy_te = load_run(ds.select(run="test"), prep)
    crange = coordinate_range(xy_te)
    res = {}
    for v in a.variant or ["thesis"]:
        o = parse(v)
        pairs = None
        if o["pairs"] is not None:
            p = o["pairs"]
            pa, pb, pw, *sh = spatial_pairs(xy_tr, p["radius"], int(p["k"]) if "k" in p else None,
                                            min_gap=int(p.get("min_gap", 0)),
                                            shifts=X_tr.shape[2] if p.get("shifts") else None)
            pairs = (pa, pb, pw * p.get("weight", 1.0), *sh)
        net = Network.from_preset("thesis-5.1", out=12, precision=a.precision)
        t0 = time.perf_counter()
        net.fit(X_tr, Rotation(5, 1.0), progress=False, transition_weight=o["transition_weight"], pairs=pairs,
                pair_layers=o["pair_layers"])
        fit_s = time.perf_counter() - t0
        F_tr, F_te = net.transform(X_tr), net.transform(X_te)
        R = net.transform(X_tr, rotations=True)
        _, eta_phi = eta_values(R[:, :, :8])
        p = out / f"firing-maps-{v.replace(' ', '_').replace('=', '')}.png"
        plot_firing_maps(R, xy_tr, p, which=(0, 1, 2, 3),
                         angles=orientation_angles(R.shape[1], step=5, width=X_tr.shape[2]),
                         title=f"{ds.metadata.get('preset')}: {v}")
        row = {"training (s)": fit_s, "max eta_phi": float(eta_phi.max()),
               "n pairs": 0 if pairs is None else len(pairs[0])}
        for name, kinds in (("quadratic (thesis)", None), ("kNN", ("knn",)), ("kernel ridge", ("kernel",))):
            if kinds is None:
                spec = dict(THESIS_SPEC)
                reader = make_readout(spec).fit(F_tr, xy_tr)
            else:
                sel = select_readout(F_tr, xy_tr, default_candidates(kinds, n_outputs=(8, 12)))
                spec, reader = sel.spec, sel.readout
            m = localization_metrics(reader.predict(F_te), xy_te, coordinate_range=crange)
            rs = random_splits_errors(spec, F_te, xy_te, crange, n_repeats=20, seed=0)
            row[name] = {"MAE x (%)": m["mae_x_pct"], "MAE y (%)": m["mae_y_pct"], "MED (m)": m["med"],
                         "random splits MAE x (%)": rs["mae_x_pct"], "random splits MAE y (%)": rs["mae_y_pct"],
                         "readout": describe_spec(spec)}
            print(f"{v} | {name}: {m['mae_x_pct']:.2f} / {m['mae_y_pct']:.2f} %, MED {m['med']:.3f} m; random "
                  f"splits {rs['mae_x_pct']:.2f} / {rs['mae_y_pct']:.2f} %; eta_phi {eta_phi.max():.3f}; "
                  f"fit {fit_s:.0f} s", flush=True)
        res[v] = row
        (out / "variants.json").write_text(json.dumps(res, indent=1, default=float))
    lines = ["| variant | readout | MAE x / y (%) | MED (m) | random splits MAE x / y (%) | max eta_phi | training (s) |",
             "|---|---|---|---|---|---|---|"]
    for v, row in res.items():
        for name in ("quadratic (thesis)", "kNN", "kernel ridge"):
            r = row[name]
            lines.append(f"| {v} | {name} | {r['MAE x (%)']:.2f} / {r['MAE y (%)']:.2f} | {r['MED (m)']:.3f} | "
                         f"{r['random splits MAE x (%)']:.2f} / {r['random splits MAE y (%)']:.2f} | "
                         f"{row['max eta_phi']:.3f} | {row['training (s)']:.0f} |")
    (out / "variants.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    with threadpool_limits(limits=1, user_api="blas"):
        main()
