#!/usr/bin/env python3
"""The default readout's fit on runs longer than it keeps, as ratios measured in one run.

``SignatureGPReadout`` keeps at most ``max_train`` (3000) samples. Since
2026-12-07 a longer run is not thinned away: every sample informs the kept
ones' weights (the DTC posterior, kept samples chosen farthest-first;
docs/localization.md "Runs longer than the readout keeps"). This times, on N
seeded synthetic samples (12 slow features, a 1800-value signature like the
default's Fourier signature of 40 rows x 3 channels x 15 coefficients), what
``Localizer.fit_features`` asks of it:

* **the DTC** (the default): ``SignatureGPReadout.fit_nested`` (the slow
  features with the signature, and the signature alone) and the training
  predictions the localizer scores itself with;
* **the reference, thinned as before**: the same two fits on the 3000 evenly
  spaced samples alone (the exact GP, what the readout did before), then
  ``predict`` on all N samples for those training predictions.

    python3 benches/bench_readout.py [--sizes 5022,11826] [--repeats 1] [--json out.json]
    python3 benches/bench_readout.py --small      # 600 / 900 samples, max_train 400: a smoke test

Prints seconds and the ratio DTC / thinned; quote the ratio. The model's size
and query time do not change (the same number of samples is kept). The
samples are synthetic: what the DTC buys in precision is measured on the
experiments' runs (docs/localization.md), not here.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _benchlib import best  # noqa: E402  (shared with the other benches)

N_SLOW, N_SIGNATURE = 12, 1800


def samples(n: int, q: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(features (n, 12 + q), positions (n, 2)): smooth slow features and a
    signature of positions in a 15 m square, with noise."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 15, (n, 2))
    S = np.column_stack([np.sin(xy[:, 0] / 3 + k) * np.cos(xy[:, 1] / 4 - k) for k in range(N_SLOW)])
    S += 0.01 * rng.normal(size=S.shape)
    G = np.abs(rng.normal(size=(n, q))) + np.sin(xy[:, :1] / 2)
    return np.hstack([S, G]), xy


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", default="5022,11826", help="training samples N (default: %(default)s: 6.2.2's and "
                   "5.1.2's product readouts, each image with its corrupted copy)")
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--small", action="store_true", help="600 / 900 samples, 200 signature values, max_train 400")
    p.add_argument("--json", help="also write every number here")
    a = p.parse_args(argv)

    from sfanav import get_num_threads
    from sfanav.localization.signature_readout import SignatureGPReadout

    sizes = [600, 900] if a.small else [int(v) for v in a.sizes.split(",")]
    q, keep_n = (200, 400) if a.small else (N_SIGNATURE, 3000)
    rows = []
    print(f"SignatureGPReadout, {N_SLOW} slow features + {q}-value signature, max_train {keep_n}, "
          f"{get_num_threads()} core threads")
    for n in sizes:
        F, xy = samples(n, q)

        def dtc():
            both, _ = SignatureGPReadout.fit_nested(F, xy, N_SLOW, q, max_train=keep_n)
            return both.training_predictions_ if both.training_predictions_ is not None else both.predict(F)

        def thinned():
            keep = np.unique(np.linspace(0, n - 1, min(n, keep_n)).round().astype(int))
            both, _ = SignatureGPReadout.fit_nested(F[keep], xy[keep], N_SLOW, q, max_train=keep_n)
            return both.predict(F)

        p_dtc, t_dtc = best(dtc, a.repeats)
        p_thin, t_thin = best(thinned, a.repeats)
        assert p_dtc.shape == p_thin.shape == xy.shape and np.isfinite(p_dtc).all()
        rows.append({"samples": n, "kept": min(n, keep_n), "seconds DTC": t_dtc, "seconds thinned": t_thin,
                     "ratio DTC to thinned": t_dtc / t_thin})
        print(f"  N {n:6d}: DTC {t_dtc:7.2f} s, thinned {t_thin:7.2f} s, ratio {t_dtc / t_thin:.2f}x")
    if a.json:
        Path(a.json).write_text(json.dumps({"small": a.small, "signature": q, "max_train": keep_n,
                                            "threads": get_num_threads(), "cpus": os.cpu_count(), "rows": rows},
                                           indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
