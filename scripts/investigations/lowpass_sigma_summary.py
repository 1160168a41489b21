#!/usr/bin/env python3
"""The product rows of experiments rerun with another low-pass width (lowpass_sigma.py) beside the committed runs
(2 px, the default), in one JSON for docs/robustness.md:

    python3 scripts/investigations/lowpass_sigma_summary.py OUT.json docs/results/investigations/lowpass-1px-*.json

Each input is a results JSON of `lowpass_sigma.py SIGMA NAME OUT` (its "experiment" names the committed run it is
compared with, docs/results/experiments/NAME.json).
"""
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
from product_summary import summary_row  # noqa: E402

rows = []
for f in sys.argv[2:]:
    new = json.loads(Path(f).read_text())
    name = new["experiment"]
    old = json.loads((ROOT / "docs" / "results" / "experiments" / f"{name}.json").read_text())
    for label, data in (("2 px (the default)", old), ("1 px", new)):
        r = summary_row(name, data["rows"], "")
        rows.append({"experiment": name, "low-pass": label, **{k: v for k, v in r.items() if k != "experiment"}})
Path(sys.argv[1]).write_text(json.dumps({"rows": rows, "sources": sys.argv[2:]}, indent=1) + "\n")
print(f"wrote {sys.argv[1]} ({len(rows)} rows)")
