#!/usr/bin/env python3
"""The product rows of the experiments whose training run the recipe's ``feedback="auto"`` sends to loop-closure
feedback, before (the results JSONs at git revision REV) and after (the committed ones), in one JSON for
docs/loop-closures.md:

    python3 scripts/investigations/feedback_auto_summary.py OUT.json 1de5f3a 6.2.1-light 6.2.1-dynamic 6.2.1-gain 5.2.3 \\
        5.3.1-real 5.3.1-sim 5.4

Each row: the experiment, "without feedback" or "the recipe now" (its feedback chosen by itself; in the 6.2.1 scenes
also the low-pass in degrees of elevation), and the product summary's columns (scripts/product_summary.py) with the
supervised and no-ground-truth MEDs.
"""
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
from product_summary import summary_row  # noqa: E402


def med(rows: list, metric: str) -> float | None:
    return next((r["sfanav"] for r in rows if r["metric"] == metric), None)


def main() -> None:
    out, rev, names = sys.argv[1], sys.argv[2], sys.argv[3:]
    rows = []
    for name in names:
        path = f"docs/results/experiments/{name}.json"
        before = json.loads(subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, check=True,
                                           capture_output=True, text=True).stdout)
        after = json.loads((ROOT / path).read_text())
        for label, data in (("without feedback", before), ("the recipe now", after)):
            r = summary_row(name, data["rows"], "")
            rows.append({"experiment": name, "training": label,
                         "supervised (m)": med(data["rows"], "MED (m) sfanav default [ground truth]"),
                         "no ground truth (m)": med(data["rows"], "MED (m) sfanav default [no ground truth]"),
                         "revisit ratio": med(data["rows"], "revisit ratio sfanav default [ground truth]"),
                         "revisit ratio, learned positions": med(data["rows"],
                                                                 "revisit ratio sfanav default [no ground truth]"),
                         **{k: v for k, v in r.items() if k != "experiment"}})
    Path(out).write_text(json.dumps({"rows": rows, "before": rev, "experiments": names}, indent=1) + "\n")
    print(f"wrote {out} ({len(rows)} rows)")


if __name__ == "__main__":
    main()
