"""The corruption suite (sfanav experiment corruptions) as a quick smoke
run: rows for every garden, mode, corruption and method, the summary
ratios, targets, the JSON, the Markdown tables and the plot."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sfanav import experiments
from sfanav.experiments.corruptions import FUSED, METHODS, NO_GAMMA, QUICK_CORRUPTIONS, ROWS, summarize


def test_corruptions_quick(tmp_path):
    res = experiments.run("corruptions", tmp_path, quick=True, progress=False)
    d = json.loads((tmp_path / "corruptions.json").read_text())
    assert d["experiment"] == "corruptions" and len(d["rows"]) == len(res.rows)
    names = [r["metric"] for r in res.rows]
    assert len(names) == len(set(names))
    table = res.details["results"]["demo"]
    assert list(table["test only"]) == ["clean", *QUICK_CORRUPTIONS]
    # the product path beside the trained rows (the demo's test walk has odometry), in the rows' order
    assert list(table["test only"]["clean"]) == list(ROWS) and FUSED not in METHODS and NO_GAMMA not in METHODS
    assert table["test only"]["clean"]["sfanav default"] == table["test only"]["clean"][NO_GAMMA]  # a camera like training's: as it is
    assert list(table["both runs"]["jpeg-90"]) == list(ROWS[:1]) + list(ROWS[2:])  # all but the no-gamma row
    assert f"worst / clean [demo, test only, {FUSED}]" in names
    for r in res.rows:
        if r["metric"].startswith("MED"):
            assert r["sfanav"] >= 0 and math.isfinite(r["sfanav"])
    s = summarize(table["test only"])
    clean = table["test only"]["clean"]
    worst = max(table["test only"][c]["sfanav default"] for c in QUICK_CORRUPTIONS) / clean["sfanav default"]
    assert np.isclose(s["sfanav default"]["worst / clean"], worst)
    assert np.isclose(s["sfanav robustness none"]["clean / robustness none"], 1.0)
    assert any("1.2x its clean MED" in t for t in res.targets)
    md = (tmp_path / "corruptions.md").read_text()
    assert "| jpeg-90 |" in md and "worst / best peer" in md
    assert Path(res.plots[0]).exists()


def test_summary_by_hand():
    table = {"clean": {"sfanav default": 0.1, "sfanav robustness none": 0.2, "perfect memory": 0.3,
                       "Fourier signature": 0.4},
             "jpeg-90": {"sfanav default": 0.15, "sfanav robustness none": 1.0, "perfect memory": 0.25,
                         "Fourier signature": 0.5}}
    s = summarize(table)
    assert s["sfanav default"] == pytest.approx({"worst / clean": 1.5, "worst / best peer": 0.6,
                                                 "clean / robustness none": 0.5})
    assert s["sfanav robustness none"]["worst / best peer"] == 4.0
