#!/usr/bin/env python3
"""Where a clipped overexposure hurts (docs/robustness.md, "The corruption suite"): the demo garden's test walk
(the raw model of ``scripts/robot_bag_path.py``, no ground truth; MED in the world frame by the rigid transform
fitted on the training run, scoring only), its 600x60 images x1.5 with and without clipping at 255, and the
clipping kept only in the sky rows (0-19) or only below them (the horizon rows 20-23, where the rest of the clipped
pixels are), and the would-be-clipped pixels made flat without the gain.

    PYTHONPATH=python python3 scripts/investigations/clipping_sky.py BAGPATH docs/results/investigations/clipping-sky.json

About 30 s.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from _bagpath import raw_recording

from sfanav.data.preprocessing import Preprocessing, Preprocessor
from sfanav.data.sources import open_images

SKY_ROWS = 20


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    root, path = Path(sys.argv[1]), Path(sys.argv[2])
    loc, frame, truth = raw_recording(root)
    x = np.concatenate(list(open_images(root / "raw" / "dataset", run="test").batches(64))).astype(np.float32)
    conform = Preprocessor(Preprocessing.of_model(loc), log=lambda *a: None)

    def med(images: np.ndarray) -> float:
        return float(np.linalg.norm(frame.apply(loc.predict(conform(images))) - truth, axis=1).mean())

    sat = (1.5 * x >= 255).all(axis=-1, keepdims=True)  # the pixels x1.5 clips in every channel
    sky = np.zeros_like(sat)
    sky[:, :SKY_ROWS] = True
    res = {"clipped pixels (fraction of the image)": float(sat.mean()),
           "clipped pixels in the sky rows (fraction of them)": float((sat & sky).sum() / sat.sum()),
           "MED (m)": {"clean": med(x), "x1.5 clipped": med(np.minimum(1.5 * x, 255)),
                       "x1.5 not clipped": med(1.5 * x),
                       "x1.5, clipped in the sky rows only": med(np.where(sat & sky, 255, 1.5 * x)),
                       "x1.5, clipped below the sky rows only": med(np.where(sat & ~sky, 255, 1.5 * x)),
                       "no gain, those pixels flat": med(np.where(sat, 255 / 1.5, x))}}
    print(json.dumps(res, indent=1))
    path.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
