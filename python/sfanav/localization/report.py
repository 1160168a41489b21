"""Markdown reports of experiment rows: :func:`write_report` writes a table of
``{"metric", "thesis", "sfanav"}`` rows and the figures beside it."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not np.isfinite(v):
            return str(v)
        if v != 0 and (abs(v) >= 1e5 or abs(v) < 1e-3):
            return f"{v:.3e}"
        return f"{v:.3f}" if abs(v) < 100 else f"{v:.1f}"
    return str(v).replace("|", "\\|").replace("\n", " ")


def _row(value: Any) -> dict[str, Any]:
    if hasattr(value, "metrics") and hasattr(value, "protocol"):  # a RegressionResult
        return {"protocol": value.protocol, **value.metrics}
    if isinstance(value, Mapping):
        return dict(value)
    raise TypeError(f"a metrics row must be a dict or a RegressionResult, got {type(value).__name__}")


def write_report(
    path: Any,
    *,
    title: str = "sfanav localization report",
    metrics: Mapping[str, Any] | None = None,
    columns: Sequence[str] | None = None,
    figures: Sequence[tuple[str, Any]] | Mapping[str, Any] = (),
    text: str | Sequence[str] | None = None,
) -> Path:
    """Writes a Markdown report: title, text paragraphs, a metrics table and
    the figures (embedded by paths relative to the report).

    Parameters
    ----------
    path : str or Path
        The ``.md`` file to write.
    metrics : mapping of row name -> dict or RegressionResult, optional
        One table row per entry (e.g. ``{"SFA, test run": result, "perfect
        memory": {...}}``); a RegressionResult contributes its protocol and
        test metrics.
    columns : sequence of str, optional
        Columns to show, in order; default all keys in order of appearance.
    figures : sequence of (caption, png path) or mapping caption -> path
    text : str or sequence of str, optional
        Paragraphs placed after the title.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [f"# {title}", ""]
    if text:
        for para in [text] if isinstance(text, str) else text:
            lines += [str(para), ""]
    if metrics:
        rows = {str(k): _row(v) for k, v in metrics.items()}
        if columns is None:
            columns = []
            for r in rows.values():
                columns += [c for c in r if c not in columns]
        columns = list(columns)
        lines += ["| | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
        for name, r in rows.items():
            lines.append(f"| {_fmt(name)} | " + " | ".join(_fmt(r.get(c)) for c in columns) + " |")
        lines.append("")
    items = list(figures.items()) if isinstance(figures, Mapping) else list(figures)
    for caption, fig_path in items:
        rel = Path(os.path.relpath(Path(fig_path).resolve(), path.parent.resolve())).as_posix()
        lines += [f"![{_fmt(caption)}]({rel})", "", f"*{_fmt(caption)}*", ""]
    path.write_text("\n".join(lines))
    return path
