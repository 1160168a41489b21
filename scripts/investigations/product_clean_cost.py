#!/usr/bin/env python3
"""The robustness's price on flawless images for the product path (docs/robustness.md, "The corruption suite"): in
the corruption suite's three gardens (seed 0, the suite's runs), the default trained without ground truth with
robustness "standard" (the default) and "none" (the thesis-era default), each localizing the clean test walk as
``sfanav localize --odometry`` does (single images, and fused with the walk's odometry): MED (m) and the ratio
standard / none. The suite's own "clean / none" compares supervised single images; this is the product's.

    PYTHONPATH=python python3 scripts/investigations/product_clean_cost.py OUT docs/results/investigations/product-clean-cost.json [LEVEL...]

LEVEL: the robustness levels (default: standard none; the JSON keeps the levels of earlier runs), the library's
or a part of "light" alone: "photometric-only" (the normalisation, no corrupted copies in the readout) or
"copies-only" (the readout's corrupted copies, no normalisation).

OUT: the suite's --out (OUT/data holds its gardens). About 6 min.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from _suite_garden import load_garden

from sfanav.experiments.corruptions import GARDENS
from sfanav.localization.error_metrics import align
from sfanav.odometry.fusion import fuse_images


def main() -> None:
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out, path = Path(sys.argv[1]), Path(sys.argv[2])
    levels = sys.argv[3:] or ["standard", "none"]
    res: dict = json.loads(path.read_text()) if path.exists() else {}
    for preset, _, _ in GARDENS:
        g = load_garden(out, preset)
        X, T = g.conform(g.native[0]), g.conform(g.native[1])
        xy, xyt, test = g.xy, g.xyt, g.test
        r: dict = res.get(preset, {})
        for robustness in levels:
            loc = g.product(robustness)
            frame = align(loc.predict(X), xy)  # scoring only
            est, fused = fuse_images(loc, T, test.odometry, source=g.native[1], conform=g.conform)
            r[robustness] = {"MED (m) single images": float(np.linalg.norm(frame.apply(est) - xyt, axis=1).mean()),
                             "MED (m) fused": float(np.linalg.norm(frame.apply(fused[:, :2]) - xyt, axis=1).mean())}
            print(preset, robustness, r[robustness], flush=True)
        for level in [v for v in r if v in ("standard", "light", "full", "photometric-only", "copies-only")]:
            if "none" in r:
                r[f"{level} over none"] = {k: r[level][k] / r["none"][k] for k in r[level]}
        res[preset] = r
        path.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
