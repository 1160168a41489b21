#!/usr/bin/env python3
"""The camera-gamma tracker where every recording has its own light (docs/robustness.md, "The camera's gamma from
the stream"): 6.2.2's product trained on nine recordings of the split the experiment's product rows use, the tenth
recording localized as it is and through ``sfanav.data.camera_gamma.predict_corrected`` (what ``sfanav localize
--camera-gamma`` runs), clean and under gamma 0.7 / 1.4. A light the training never saw must not read as a camera
gamma (the factor stays 1 and the MED is unchanged), and a gamma should still be taken out.

    PYTHONPATH=python python3 scripts/investigations/camera_gamma_622.py DATA docs/results/investigations/camera-gamma-622.json

DATA: the experiment's simulated scene (``sfanav experiment 6.2.2`` writes it to OUT/data/thesis-6.2.2-conditions-seed0).
About 5 min.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from _split622 import trained_split

from sfanav.data.camera_gamma import CameraGamma, predict_corrected
from sfanav.data.corruptions import corrupt
from sfanav.localization.error_metrics import localization_metrics


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    split = trained_split(sys.argv[1])
    loc, images, xy = split["loc"], split["images_te"], split["xy_te"]
    out = {}
    for c in ("clean", "gamma-0.7", "gamma-1.4", "exposure-1.5"):
        X = images if c == "clean" else corrupt(images, c, seed=1)
        tracker = CameraGamma.for_localizer(loc)
        fixed = predict_corrected(loc, tracker, X)
        out[c] = {"MED (m)": localization_metrics(loc.predict(X), xy)["med"],
                  "MED (m), camera gamma": localization_metrics(fixed, xy)["med"],
                  "factor": tracker.factor_, "median log ratio": tracker.log_ratio_}
        print(c, out[c], flush=True)
    Path(sys.argv[2]).write_text(json.dumps({"training (s)": split["seconds"], "test recording": out}, indent=1) + "\n")


if __name__ == "__main__":
    main()
