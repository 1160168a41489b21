"""How close IncSFA comes to the exact top stage on 6.2.1-changes-online's run A.

The stale model of ``6.2.1-changes-online`` (the sfanav default trained on
run A, as the experiment trains it) is split at its top stage; the stage's
training sequence (the frozen stages' outputs under the 70 simulated
rotations of every image, quadratically expanded: 124 530 x 299 at seed 0)
is fed to IncSFA, one pass per ``--rates`` value (its ``mca_rate`` in that
pass), and after each pass the canonical correlations between IncSFA's 12
features and the exact stage's on A's views are printed. ``--ceiling``
first prints the same for batch SFA restricted to the K leading principal
components of the expanded sequence (K = 20, 40, 80, 150, 299): the best an
IncSFA whitening K directions can reach. Quoted in docs/updates.md ("The
online peer: IncSFA").

    PYTHONPATH=python python3 scripts/investigations/incsfa_top_stage.py --out results/changes --ceiling \
        --whitened 40 --rates 0.5 0.5 0.5 0.5 0.5          # ~15 min on a loaded 2-core machine
    PYTHONPATH=python python3 scripts/investigations/incsfa_top_stage.py --out results/changes \
        --whitened 40 --rates 0.5 0.1 0.02
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from sfanav.data.sources import load_run
from sfanav.experiments.incsfa_peer import IncSFATopStage, canonical_correlations
from sfanav.experiments.localization import simulated
from sfanav.experiments.robustness import long_term_configuration
from sfanav.experiments.updates import CHANGES_PRESET, CONFIG
from sfanav.localization.updates import MAX_VIEWS, top_stage_features, top_stage_training_inputs
from sfanav.pipeline import train_localizer
from sfanav.sfa.network import Rotation


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="the experiment's --out (its simulated dataset is reused)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--whitened", type=int, default=40)
    ap.add_argument("--rates", type=float, nargs="*", default=[0.5, 0.1, 0.02])
    ap.add_argument("--ceiling", action="store_true")
    args = ap.parse_args()
    ds = simulated(args.out, CHANGES_PRESET, args.seed, quick=False, progress=False)
    make_net, prep, recipe = long_term_configuration(CONFIG, False)
    X, xy = load_run(ds.select(run="A"), prep)
    elev = tuple(ds.metadata["camera"].get("elevation_deg", (-30.0, 20.0)))
    stale = train_localizer(X, xy=xy, network=make_net(), recipe=recipe, camera_elevation=elev,
                            rotation=Rotation(5, 1.0), readout_memory=MAX_VIEWS, readout_memory_images=True)
    mem = stale.readout_memory_
    exact = top_stage_features(stale.trained_network(), mem.inputs)
    Z = top_stage_training_inputs(stale, X)
    model = IncSFATopStage(stale, n_whitened=args.whitened, mca_rates=args.rates or [0.5])
    E = model.expand(Z.reshape(-1, Z.shape[2]))
    print(f"sequence {Z.shape} -> expanded {E.shape}", flush=True)
    if args.ceiling:
        mu = E.mean(axis=0)
        w, V = np.linalg.eigh(np.cov(E.T, bias=True))
        w, V = w[::-1], V[:, ::-1]
        D = np.diff(E, axis=0)
        n, K, k = mem.inputs.shape
        for m in (20, 40, 80, 150, E.shape[1]):
            keep = np.arange(m)[w[:m] > w[0] * 1e-12]
            W = V[:, keep] / np.sqrt(w[keep])
            _, U = np.linalg.eigh(W.T @ (D.T @ D / len(D)) @ W)
            F = ((model.expand(mem.inputs.reshape(n * K, k)) - mu) @ W @ U[:, : exact.shape[1]])
            cc = canonical_correlations(F.reshape(n, K, -1).mean(axis=1), exact)
            print(f"batch SFA in the top {m} principal components: mean {cc.mean():.3f}, "
                  f"{np.round(cc, 3).tolist()}", flush=True)
    for p, rate in enumerate(model.mca_rates, 1):
        model.node_.mca_rate = rate
        t0 = time.perf_counter()
        model.node_.partial_fit(E)
        dt = time.perf_counter() - t0
        cc = canonical_correlations(model.features_of_inputs(mem.inputs), exact)
        print(f"IncSFA ({args.whitened} whitened) pass {p}, mca_rate {rate:g} ({dt:.0f} s): mean {cc.mean():.3f}, "
              f"{np.round(cc, 3).tolist()}", flush=True)


if __name__ == "__main__":
    main()
