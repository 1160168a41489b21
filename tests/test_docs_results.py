"""The docs' measured tables match their results JSONs (scripts/render_docs.py).

The repository check fails when a rendered region in README.md or docs/*.md
differs from the JSON it names (fix: ``python scripts/render_docs.py
--write``). The renderer itself is pinned on small synthetic Markdown + JSON.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "render_docs.py"

if not SCRIPT.exists():  # the tests run from an installed wheel without the checkout's scripts
    pytest.skip("scripts/render_docs.py is not in this tree", allow_module_level=True)


def _load():
    spec = importlib.util.spec_from_file_location("render_docs", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["render_docs"] = mod
    spec.loader.exec_module(mod)
    return mod


rd = _load()


def test_repository_docs_match_their_results():
    differs, errors = rd.process(rd.default_files(ROOT), ROOT, write=False)
    assert not errors, "\n".join(errors)
    assert not differs, "run python scripts/render_docs.py --write:\n" + "\n".join(differs)


def test_repository_has_rendered_regions():
    regions = [r for f in rd.default_files(ROOT) for r in rd.find_regions(f)]
    files = {r.file.name for r in regions}
    assert {"README.md", "experiments.md"} <= files
    assert any(r.json_path == "docs/results/experiments/demo.json" for r in regions)


def _tree(tmp_path, rows, md):
    (tmp_path / "res").mkdir()
    (tmp_path / "res" / "x.json").write_text(json.dumps({"experiment": "x", "rows": rows, "deep": {"a": [1.5, 2]}}))
    doc = tmp_path / "doc.md"
    doc.write_text(md)
    return doc


ROWS = [{"metric": "MED (m)", "thesis": 0.21, "sfanav": 0.12345},
        {"metric": "MAE x (%)", "thesis": None, "sfanav": 2.5},
        {"metric": "best n", "thesis": 8, "sfanav": 12}]

TEMPLATE = """intro

<!-- results res/x.json
| what | thesis | sfanav |
|---|---|---|
| MED | {MED (m);thesis;g} | **{MED (m)}** / {MED (m);;.2f} |
| n | {best n;thesis} | {best n} |
| deep | - | {@deep/a/0;;.1f} |
-->
OLD
<!-- /results -->

outro
"""

RENDERED = ["| what | thesis | sfanav |", "|---|---|---|", "| MED | 0.21 | **0.123** / 0.12 |",
            "| n | 8 | 12 |", "| deep | - | 1.5 |"]


def test_template_renders_placeholders(tmp_path):
    doc = _tree(tmp_path, ROWS, TEMPLATE)
    (reg,) = rd.find_regions(doc)
    assert reg.line == 3 and reg.json_path == "res/x.json" and reg.current == ["OLD"]
    assert rd.render(tmp_path, reg) == RENDERED


def test_check_reports_and_write_fixes(tmp_path):
    doc = _tree(tmp_path, ROWS, TEMPLATE)
    differs, errors = rd.process([doc], tmp_path, write=False)
    assert errors == [] and len(differs) == 1
    assert differs[0].startswith("doc.md:3: res/x.json")
    assert "OLD" in doc.read_text()  # --check does not write
    assert rd.process([doc], tmp_path, write=True)[0] == differs
    text = doc.read_text()
    assert "OLD" not in text and "\n".join(RENDERED) in text
    assert text.startswith("intro\n") and text.endswith("outro\n")
    assert rd.process([doc], tmp_path, write=False) == ([], [])
    # a changed value in the JSON is reported again, and only that region
    rows = [dict(r) for r in ROWS]
    rows[0]["sfanav"] = 0.5
    (tmp_path / "res" / "x.json").write_text(json.dumps({"rows": rows, "deep": {"a": [1.5]}}))
    differs, _ = rd.process([doc], tmp_path, write=False)
    assert len(differs) == 1
    rd.process([doc], tmp_path, write=True)
    assert "**0.500** / 0.50" in doc.read_text()


def test_cli_exit_codes(tmp_path):
    doc = _tree(tmp_path, ROWS, TEMPLATE)
    run = [sys.executable, str(SCRIPT), "--root", str(tmp_path)]
    r = subprocess.run(run + ["--check", str(doc)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and r.stdout.count("\n") == 1 and ":3: res/x.json" in r.stdout
    assert subprocess.run(run + ["--write", str(doc)], capture_output=True, timeout=60).returncode == 0
    assert subprocess.run(run + ["--check", str(doc)], capture_output=True, timeout=60).returncode == 0


def test_plain_table_from_options(tmp_path):
    md = '<!-- results res/x.json columns=metric,sfanav metrics="M*" -->\n<!-- /results -->\n'
    doc = _tree(tmp_path, ROWS, md)
    (reg,) = rd.find_regions(doc)
    assert rd.render(tmp_path, reg) == ["| metric | sfanav |", "|---|---|", "| MED (m) | 0.123 |",
                                        "| MAE x (%) | 2.500 |"]


def test_flagged_row_gets_a_footnote(tmp_path):
    rows = ROWS + [{"metric": "MED (m) [thesis configuration]", "thesis": None, "sfanav": None,
                    "flag": "quadratic readout extrapolates"}]
    md = "<!-- results res/x.json\n| a | {MED (m) [thesis configuration]} |\n-->\n<!-- /results -->\n"
    doc = _tree(tmp_path, rows, md)
    (reg,) = rd.find_regions(doc)
    out = rd.render(tmp_path, reg)
    assert out[0] == f"| a | - {rd.DAGGER} |"
    assert out[-1] == f"{rd.DAGGER} MED (m) [thesis configuration]: quadratic readout extrapolates"


@pytest.mark.parametrize("md, message", [
    ("<!-- results res/missing.json\n| {MED (m)} |\n-->\n<!-- /results -->\n", "res/missing.json not found"),
    ("<!-- results res/x.json\n| {MED (km)} |\n-->\n<!-- /results -->\n", "no row with metric 'MED (km)'"),
    ("<!-- results res/x.json\n| {MED (m);nope} |\n-->\n<!-- /results -->\n", "has no column 'nope'"),
    ("<!-- results res/x.json\n| {@deep/b} |\n-->\n<!-- /results -->\n", "no 'b' at path"),
    ("<!-- results res/x.json metrics=Z* -->\n<!-- /results -->\n", "no row with metric matching 'Z*'"),
    ("<!-- results res/x.json colour=red -->\n<!-- /results -->\n", "unknown option 'colour=red'"),
])
def test_clear_errors(tmp_path, md, message):
    doc = _tree(tmp_path, ROWS, md)
    differs, errors = rd.process([doc], tmp_path, write=True)
    assert len(errors) == 1 and message in errors[0] and errors[0].startswith(f"{doc}:1")
    assert doc.read_text() == md  # nothing written


def test_unclosed_region_is_an_error(tmp_path):
    doc = _tree(tmp_path, ROWS, "<!-- results res/x.json -->\n| a |\n")
    differs, errors = rd.process([doc], tmp_path, write=False)
    assert len(errors) == 1 and "not closed" in errors[0]


def test_format_number():
    f = rd.format_number
    assert [f(None), f(True), f(12), f(0.0812), f(0.00123), f(513.1), f(2.5, ".2f")] == \
        ["-", "yes", "12", "0.081", "0.00123", "513.1", "2.50"]


def test_cap_prints_no_absurd_figure(tmp_path):
    rows = ROWS + [{"metric": "MED (m) far", "thesis": None, "sfanav": 4.5e13}]
    md = "<!-- results res/x.json cap=100\n| {MED (m) far} | {MED (m)} |\n-->\n<!-- /results -->\n"
    doc = _tree(tmp_path, rows, md)
    (reg,) = rd.find_regions(doc)
    assert rd.render(tmp_path, reg) == ["| > 100 | 0.123 |"]


def test_regions_in_code_fences_are_examples(tmp_path):
    md = "```markdown\n<!-- results res/missing.json -->\n<!-- /results -->\n```\n"
    doc = _tree(tmp_path, ROWS, md)
    assert rd.find_regions(doc) == [] and rd.process([doc], tmp_path, write=False) == ([], [])
