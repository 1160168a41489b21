#!/usr/bin/env python3
"""One table of the product against its targets in every localization experiment (issue 44's targets: the sfanav
default's MED at most 0.9x the best peer's, without ground truth at most 1.2x its supervised MED), read from the
committed results JSONs. Writes docs/results/experiments/product-summary.json, which docs/experiments.md renders
("Where the product stands"); tests/test_product_summary.py fails when it differs from what the experiments' JSONs
say, so a rerun that moves a row must rerun this too.

    python3 scripts/product_summary.py            # rewrites the JSON (atomically)
    python3 scripts/product_summary.py --check    # exit 1 when the committed JSON is stale

Needs only the standard library.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results" / "experiments"
OUT = RESULTS / "product-summary.json"

# (row name, results file, test-run label in the row names or "")
EXPERIMENTS = [
    ("5.1.1", "5.1.1.json", ""),
    ("5.1.2", "5.1.2.json", ""),
    ("5.1.3", "5.1.3.json", ""),
    ("5.2 indoor I", "5.2.json", "indoor I"),
    ("5.2 indoor II", "5.2.json", "indoor II"),
    ("5.2.3", "5.2.3.json", ""),
    ("5.3.1-sim", "5.3.1-sim.json", ""),
    ("5.3.1-real", "5.3.1-real.json", ""),
    ("5.3.2", "5.3.2.json", ""),
    ("5.4", "5.4.json", ""),
    ("6.2.1-static", "6.2.1-static.json", ""),
    ("6.2.1-dynamic", "6.2.1-dynamic.json", ""),
    ("6.2.1-light", "6.2.1-light.json", ""),
    ("6.2.1-gain", "6.2.1-gain.json", ""),
    ("6.2.2", "6.2.2.json", ""),
]

PEER_TARGET, NO_GT_TARGET = 0.9, 1.2


def _q(quals: list[str], label: str) -> str:
    return "[" + ", ".join(quals + ([label] if label else [])) + "]"


def summary_row(name: str, rows: list[dict], label: str) -> dict:
    by = {r["metric"]: r for r in rows if isinstance(r, dict) and "metric" in r}

    def value(metric: str) -> float | None:
        r = by.get(metric)
        return None if r is None else r.get("sfanav")

    ratio = by.get(f"MED ratio sfanav default {_q(['ground truth'], label)} / best peer")
    if ratio is None:
        raise KeyError(f"{name}: no product rows (MED ratio sfanav default {_q(['ground truth'], label)} / best peer)")
    peer = ratio.get("best peer")
    tail = f" [{label}]" if label else ""
    no_gt = value(f"MED ratio sfanav default [no ground truth] / [ground truth]{tail}")
    return {
        "experiment": name,
        "sfanav default (m)": value(f"MED (m) sfanav default {_q(['ground truth'], label)}"),
        "best peer": peer,
        "best peer (m)": value(f"MED (m) peer {peer}{tail}"),
        "/ best peer": ratio["sfanav"],
        "fused / best peer": value(f"MED ratio sfanav default {_q(['ground truth', 'fused'], label)} / best peer"),
        "no ground truth / best peer": value(f"MED ratio sfanav default {_q(['no ground truth'], label)} / best peer"),
        "no ground truth / ground truth": no_gt,
        f"at most {PEER_TARGET}x the best peer": ratio["sfanav"] <= PEER_TARGET,
        f"no ground truth at most {NO_GT_TARGET}x": None if no_gt is None else no_gt <= NO_GT_TARGET,
    }


def summary(results: Path = RESULTS) -> dict:
    rows = []
    for name, file, label in EXPERIMENTS:
        data = json.loads((results / file).read_text(encoding="utf-8"))
        rows.append(summary_row(name, data["rows"], label))
    met = sum(r[f"at most {PEER_TARGET}x the best peer"] for r in rows)
    no_gt = [r[f"no ground truth at most {NO_GT_TARGET}x"] for r in rows if r[f"no ground truth at most {NO_GT_TARGET}x"]
             is not None]
    return {"rows": rows, "sources": {name: f"docs/results/experiments/{file}" for name, file, _ in EXPERIMENTS},
            "peer target met": f"{met} of {len(rows)}", "no ground truth target met": f"{sum(no_gt)} of {len(no_gt)}"}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="exit 1 when the committed summary differs")
    a = ap.parse_args(argv)
    text = json.dumps(summary(), indent=1) + "\n"
    if a.check:
        if not OUT.exists() or OUT.read_text(encoding="utf-8") != text:
            print(f"{OUT.relative_to(ROOT)} differs from the experiments' JSONs: run scripts/product_summary.py",
                  file=sys.stderr)
            return 1
        return 0
    tmp = OUT.with_name(f".{OUT.name}.tmp{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, OUT)
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
