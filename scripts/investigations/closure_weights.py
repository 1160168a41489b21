#!/usr/bin/env python3
"""The recipe's loop-closure feedback with each closure weighted by the bag of words' match score
(``closure_weights="score"``) against uniform weights (the recipe's), supervised, on an experiment's scene: the
bag-of-words closures the recipe's feedback finds, the sfanav default trained with them both ways, the test run's MED
(docs/loop-closures.md, "When feedback is used"). A third variant, "mean score", weighs every closure alike by the
scores' mean: whether the score's order or only the closures' total weight matters. SKIP=score,uniform (environment)
leaves variants out; SEED=N (environment) draws the robustness's corrupted copies with seed N (entries keyed
LABEL@N), to compare the weights' effect with the draw's.

    sfanav simulate --preset thesis-6.2.1-light --seed 0 --out runs/light
    PYTHONPATH=python python3 scripts/investigations/closure_weights.py 6.2.1-light runs/light OUT.json

Adds OUT.json[NAME] = {"closures", "uniform": {"MED (m)", "seconds"}, "score": {...}, "mean score": {...}}.
"""

from __future__ import annotations

import os
import time

import numpy as np

from _feedback_scene import add_entry, feedback_scene
from sfanav.localization.error_metrics import localization_metrics
from sfanav.pipeline import train_localizer

# variants to leave out (environment, comma-separated labels)
SKIP = set(filter(None, os.environ.get("SKIP", "").split(",")))
# the robustness's draw (train_localizer(seed=)); entries of seeds other than 0 are keyed LABEL@SEED
SEED = int(os.environ.get("SEED", "0"))


def main() -> None:
    name, out_path, train, test, elev, found = feedback_scene(__doc__)
    entry = {"closures": int(len(found))}
    variants = (("score", "score"), ("uniform", None), ("mean score", np.full(len(found), np.mean(found.score))))
    for label, weights in variants:
        if label in SKIP:
            continue
        t0 = time.perf_counter()
        loc = train_localizer(train.images, xy=train.xy, supervision="ground-truth", camera_elevation=elev,
                              loop_closures=found, closure_weights=weights, filter_noise=False, seed=SEED)
        label = label if SEED == 0 else f"{label}@{SEED}"
        entry[label] = {"MED (m)": localization_metrics(loc.predict(test.images), test.xy)["med"],
                        "seconds": time.perf_counter() - t0}
        add_entry(out_path, name, {"closures": entry["closures"], label: entry[label]}, merge=True)


if __name__ == "__main__":
    main()
