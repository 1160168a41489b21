#!/usr/bin/env python3
"""An experiment rerun with another low-pass width in the default's photometric normalisation (sfanav.data.photometric,
lowpass_log_contrast: 2 px at the network's resolution), everything else as `sfanav experiment NAME` runs it: what
the low-pass costs or buys the product rows of a scene (docs/robustness.md, "The omnidirectional scenes of 6.2.1").
Only the width of the invariance partners', the readout copies' and the queries' normalisation changes.

    PYTHONPATH=python python3 scripts/investigations/lowpass_sigma.py SIGMA NAME OUT   # e.g. 1.0 6.2.1-dynamic runs/s1
"""
import sys

import sfanav.data.photometric as photometric
import sfanav.localization.recipe as recipe

photometric.lowpass_log_contrast.__kwdefaults__["sigma"] = float(sys.argv[1])
recipe.lowpass_for = lambda elevation, height: (float(sys.argv[1]),) * 2  # the recipe's rows in degrees, replaced
from sfanav.app.cli import main  # noqa: E402

sys.exit(main(["experiment", sys.argv[2], "--no-progress", "--out", sys.argv[3]]))
