"""docs/results/experiments/product-summary.json (the product against its targets in every localization
experiment, rendered in docs/experiments.md) is what scripts/product_summary.py computes from the committed
experiment JSONs: a rerun that moves a row and forgets the summary fails here."""

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("product_summary", ROOT / "scripts" / "product_summary.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_committed_summary_is_up_to_date():
    mod = _script()
    committed = json.loads((ROOT / "docs/results/experiments/product-summary.json").read_text())
    assert committed == json.loads(json.dumps(mod.summary())), "run scripts/product_summary.py"
    assert mod.main(["--check"]) == 0


def test_a_row_reads_the_product_rows_of_a_labelled_test_run():
    mod = _script()
    rows = [
        {"metric": "MED ratio sfanav default [ground truth, room] / best peer", "sfanav": 0.5, "best peer": "perfect memory"},
        {"metric": "MED (m) sfanav default [ground truth, room]", "sfanav": 0.1},
        {"metric": "MED (m) peer perfect memory [room]", "sfanav": 0.2},
        {"metric": "MED ratio sfanav default [no ground truth] / [ground truth] [room]", "sfanav": 1.3},
    ]
    r = mod.summary_row("x", rows, "room")
    assert r["sfanav default (m)"] == 0.1 and r["best peer (m)"] == 0.2 and r["/ best peer"] == 0.5
    assert r["at most 0.9x the best peer"] is True and r["no ground truth at most 1.2x"] is False
    assert r["fused / best peer"] is None
    with pytest.raises(KeyError, match="no product rows"):
        mod.summary_row("x", rows[1:], "room")
