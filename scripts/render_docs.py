#!/usr/bin/env python3
"""Renders the measured tables in README.md and docs/*.md from the results JSONs.

A *region* in a Markdown file is an HTML comment naming a JSON file, then the
generated text, then a closing comment::

    <!-- results docs/results/experiments/demo.json
    | test walk, MED (m) | sfanav |
    |---|---|
    | sfanav default, no ground truth | **{MED (m) [no ground truth]}** |
    | JPEG 90: single images / fused | {MED (m) [no ground truth, jpeg-90 test images]} / {MED (m) perfect memory;sfanav;.2f} |
    -->
    (generated: the template with every {...} replaced)
    <!-- /results -->

The lines after the path, up to ``-->``, are a template (GitHub does not show
them); ``{...}`` is a placeholder:

``{METRIC}``
    the ``sfanav`` value of the row whose ``metric`` is METRIC;
``{METRIC;COLUMN}`` / ``{METRIC;COLUMN;FORMAT}`` / ``{METRIC;;FORMAT}``
    another column of that row (``thesis``, ...) and/or a Python format spec
    (``.2f``, ``.3g``, ``,d``);
``{@a/b/c}`` (``{@a/b/c;;FORMAT}``)
    the value at that path from the JSON's root (dict keys, list indexes), for
    results that are not experiment rows.

Without a template, options on the first line make a plain table::

    <!-- results docs/results/experiments/5.2.json columns=metric,thesis,sfanav metrics="MED (m)*" metrics="MAE*" -->

``columns=`` (default ``metric,thesis,sfanav``), ``metrics=`` (shell-style
patterns, repeatable; default every row), ``rows=`` (path of the list of rows,
default ``rows``) and ``key=`` (the field that names a row, default
``metric``) apply to both forms; a template also takes ``rows=`` and ``key=``.
``cap=N`` prints numbers beyond +-N (and NaN, infinity) as ``> N``: an error
of kilometres is no figure.

Numbers: by default 3 decimals below 100 (3 significant digits below 0.01), 1
decimal from 100, integers as they are, None as ``-``, booleans yes/no. A row
with a ``flag`` (e.g. a regression that extrapolates outside its training
positions) gets a dagger after its ``sfanav`` value and the flag as a
footnote under the region; an experiment withholds an absurd figure by writing None.

Usage::

    python scripts/render_docs.py --check   # exit 1, one line per region that differs
    python scripts/render_docs.py --write   # rewrite the regions in place (atomically)
    python scripts/render_docs.py --check README.md docs/experiments.md

Paths in a region are relative to the repository root (this script's parent's
parent, or ``--root``). The script needs only the standard library.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import math
import os
import re
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
OPEN = "<!-- results"
CLOSE = "<!-- /results -->"
DAGGER = "\u2020"
_PLACEHOLDER = re.compile(r"\{([^{}]+)\}")


class RenderError(ValueError):
    """A region that cannot be rendered (missing JSON, metric, key, bad syntax)."""


@dataclass
class Region:
    """One marked region: where it is, what it names, what it holds now."""

    file: Path
    line: int  # 1-based line of the opening comment
    json_path: str
    options: dict[str, list[str]]
    template: list[str] | None  # None: a plain table from the options
    start: int  # index of the first generated line
    end: int  # index of the closing comment line
    current: list[str]


def default_files(root: Path) -> list[Path]:
    """README.md and every Markdown file under docs/."""
    files = [root / "README.md"] if (root / "README.md").exists() else []
    return files + sorted((root / "docs").rglob("*.md"))


def format_number(v: Any, fmt: str = "") -> str:
    """A cell: ``-`` for None, yes/no for booleans, ``fmt`` (a Python format
    spec) when given, else 3 decimals below 100 (``.3g`` below 0.01), 1 from
    100, integers as they are."""
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, float)):
        if isinstance(v, float) and not math.isfinite(v):
            return str(v)
        if fmt:
            return format(v, fmt)
        if isinstance(v, int):
            return str(v)
        return f"{v:.3g}" if abs(v) < 0.01 and v != 0 else (f"{v:.3f}" if abs(v) < 100 else f"{v:.1f}")
    if fmt:
        return format(v, fmt)
    return str(v)


def _parse_open(text: str, where: str) -> tuple[str, dict[str, list[str]], list[str] | None]:
    """The opening comment's JSON path, options and template lines."""
    body = text[len(OPEN):]
    if not body.rstrip().endswith("-->"):
        raise RenderError(f"{where}: the opening comment is not closed with -->")
    body = body.rstrip()[:-3]
    first, _, rest = body.partition("\n")
    try:
        words = shlex.split(first)
    except ValueError as e:
        raise RenderError(f"{where}: bad options ({e})") from None
    if not words:
        raise RenderError(f"{where}: no JSON path after '{OPEN}'")
    options: dict[str, list[str]] = {}
    for w in words[1:]:
        k, eq, v = w.partition("=")
        if not eq or k not in ("columns", "metrics", "rows", "key", "cap"):
            raise RenderError(f"{where}: unknown option {w!r} (known: columns=, metrics=, rows=, key=, cap=)")
        options.setdefault(k, []).append(v)
    template = [ln for ln in rest.split("\n")]
    while template and not template[-1].strip():
        template.pop()
    while template and not template[0].strip():
        template.pop(0)
    return words[0], options, (template or None)


def find_regions(path: Path) -> list[Region]:
    """Every region in one Markdown file (RenderError on an unclosed one)."""
    lines = path.read_text(encoding="utf-8").split("\n")
    regions = []
    i = 0
    fence = None  # regions inside fenced code blocks are examples, not regions
    while i < len(lines):
        s = lines[i].lstrip()
        if s.startswith(("```", "~~~")):
            fence = None if fence and s.startswith(fence) else (fence or s[:3])
        if fence or not s.startswith(OPEN):
            i += 1
            continue
        where = f"{path}:{i + 1}"
        j = i
        while "-->" not in lines[j]:
            j += 1
            if j == len(lines):
                raise RenderError(f"{where}: the opening comment is not closed with -->")
        json_path, options, template = _parse_open("\n".join(lines[i:j + 1]).strip(), where)
        k = j + 1
        while k < len(lines) and lines[k].strip() != CLOSE:
            if lines[k].lstrip().startswith(OPEN):
                raise RenderError(f"{where}: region not closed with {CLOSE} before the next one")
            k += 1
        if k == len(lines):
            raise RenderError(f"{where}: region not closed with {CLOSE}")
        regions.append(Region(path, i + 1, json_path, options, template, j + 1, k, lines[j + 1:k]))
        i = k + 1
    return regions


def _load(root: Path, region: Region) -> Any:
    p = root / region.json_path
    if not p.is_file():
        raise RenderError(f"{region.file}:{region.line}: JSON {region.json_path} not found")
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise RenderError(f"{region.file}:{region.line}: JSON {region.json_path} is not valid JSON ({e})") from None


def _walk(data: Any, path: str, where: str) -> Any:
    cur = data
    for part in [p for p in path.split("/") if p != ""]:
        if isinstance(cur, dict) and part in cur:
            cur = cur[part]
        elif isinstance(cur, list) and re.fullmatch(r"-?\d+", part) and -len(cur) <= int(part) < len(cur):
            cur = cur[int(part)]
        else:
            raise RenderError(f"{where}: no {part!r} at path {path!r}")
    return cur


class _Context:
    def __init__(self, root: Path, region: Region):
        self.where = f"{region.file}:{region.line}: JSON {region.json_path}"
        self.data = _load(root, region)
        self.key = (region.options.get("key") or ["metric"])[-1]
        given = region.options.get("rows")
        rows_path = (given or ["rows"])[-1]
        if not given and isinstance(self.data, dict) and "rows" not in self.data:
            rows = None  # a file of values, not rows: only {@path} placeholders can read it
        else:
            rows = _walk(self.data, rows_path, self.where) if rows_path else self.data
        self.rows = rows if isinstance(rows, list) else None
        self.flags: list[str] = []
        cap = (region.options.get("cap") or [None])[-1]
        try:
            self.cap = None if cap is None else float(cap)
        except ValueError:
            raise RenderError(f"{self.where}: cap must be a number, got {cap!r}") from None

    def fmt(self, v: Any, fmt: str) -> str:
        if self.cap is not None and isinstance(v, (int, float)) and not isinstance(v, bool) and not abs(v) <= self.cap:
            return f"> {self.cap:g}"
        try:
            return format_number(v, fmt)
        except (ValueError, TypeError) as e:
            raise RenderError(f"{self.where}: cannot format {v!r} with {fmt!r} ({e})") from None

    def row(self, name: str) -> dict:
        if self.rows is None:
            raise RenderError(f"{self.where}: no list of rows to find {name!r} in")
        for r in self.rows:
            if isinstance(r, dict) and r.get(self.key) == name:
                return r
        raise RenderError(f"{self.where}: no row with {self.key} {name!r}")

    def cell(self, row: dict, column: str, fmt: str) -> str:
        if column not in row and column != "flag":
            raise RenderError(f"{self.where}: row {row.get(self.key)!r} has no column {column!r}")
        text = self.fmt(row.get(column), fmt)
        flag = row.get("flag")
        if flag and column == "sfanav":
            note = f"{DAGGER} {row.get(self.key)}: {flag}"
            if note not in self.flags:
                self.flags.append(note)
            text += f" {DAGGER}"
        return text

    def placeholder(self, spec: str) -> str:
        name, column, fmt = (spec.split(";") + ["", ""])[:3]
        if spec.count(";") > 2:
            raise RenderError(f"{self.where}: bad placeholder {{{spec}}} (NAME;COLUMN;FORMAT)")
        name, column, fmt = name.strip(), column.strip(), fmt.strip()
        if name.startswith("@"):
            return self.fmt(_walk(self.data, name[1:], self.where), fmt)
        return self.cell(self.row(name), column or "sfanav", fmt)


def render(root: Path, region: Region) -> list[str]:
    """The generated lines of one region (RenderError naming what is missing)."""
    ctx = _Context(root, region)
    if region.template is not None:
        out = [_PLACEHOLDER.sub(lambda m: ctx.placeholder(m.group(1)), ln) for ln in region.template]
    else:
        if ctx.rows is None:
            raise RenderError(f"{ctx.where}: a table without a template needs a list of rows (rows=)")
        columns = ",".join(region.options.get("columns") or ["metric,thesis,sfanav"]).split(",")
        patterns = region.options.get("metrics")
        rows = [r for r in ctx.rows if isinstance(r, dict)]
        if patterns:
            chosen = []
            for pat in patterns:
                hits = [r for r in rows if fnmatch.fnmatchcase(str(r.get(ctx.key)), pat) and r not in chosen]
                if not hits and not any(fnmatch.fnmatchcase(str(r.get(ctx.key)), pat) for r in rows):
                    raise RenderError(f"{ctx.where}: no row with {ctx.key} matching {pat!r}")
                chosen += hits
            rows = chosen
        out = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
        for r in rows:
            out.append("| " + " | ".join(ctx.cell(r, c, "") for c in columns) + " |")
    if ctx.flags:
        out += [""] + [f + "  " if i < len(ctx.flags) - 1 else f for i, f in enumerate(ctx.flags)]
    return out


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def process(files: list[Path], root: Path, write: bool) -> tuple[list[str], list[str]]:
    """Checks (and with ``write`` rewrites) every region in ``files``.

    Returns ``(differs, errors)``: one line per region whose text differs from
    its JSON (``file:line: JSON path differs``) and one per region that cannot
    be rendered. With ``write``, files whose regions all render are rewritten.
    """
    differs, errors = [], []
    for f in files:
        try:
            regions = find_regions(f)
        except RenderError as e:
            errors.append(str(e))
            continue
        if not regions:
            continue
        lines = f.read_text(encoding="utf-8").split("\n")
        changed = False
        for reg in reversed(regions):
            try:
                new = render(root, reg)
            except RenderError as e:
                errors.append(str(e))
                continue
            if new != reg.current:
                differs.append(f"{_rel(f, root)}:{reg.line}: {reg.json_path} differs from the text")
                lines[reg.start:reg.end] = new
                changed = True
        if write and changed:
            _atomic_write(f, "\n".join(lines))
    differs.sort(key=lambda s: (s.split(":")[0], int(s.split(":")[1])))
    return differs, errors


def _rel(f: Path, root: Path) -> str:
    try:
        return str(f.resolve().relative_to(root.resolve()))
    except ValueError:
        return str(f)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Render the docs' measured tables from the results JSONs.")
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true", help="exit 1 listing every region that differs from its JSON")
    mode.add_argument("--write", action="store_true", help="rewrite the regions in place")
    ap.add_argument("--root", type=Path, default=ROOT, help="repository root (JSON paths are relative to it)")
    ap.add_argument("files", nargs="*", type=Path, help="Markdown files (default: README.md and docs/**/*.md)")
    a = ap.parse_args(argv)
    files = a.files or default_files(a.root)
    differs, errors = process(files, a.root, write=a.write)
    for e in errors:
        print(f"error: {e}", file=sys.stderr)
    if a.check:
        for d in differs:
            print(d)
        if differs:
            print(f"{len(differs)} region(s) differ from their JSON; run python scripts/render_docs.py --write",
                  file=sys.stderr)
    elif differs:
        print(f"rewrote {len(differs)} region(s)")
    return 1 if errors or (a.check and differs) else 0


if __name__ == "__main__":
    sys.exit(main())
