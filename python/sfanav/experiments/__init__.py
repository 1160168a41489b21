"""Reruns of the thesis's experiments on the built-in simulator.

Every experiment is a function registered under a stable name (``"5.1.1"``,
``"7.1-open"``, ...) that runs on its own (simulating, training and
evaluating as needed) and returns an :class:`ExperimentResult`: rows of
``{"metric": ..., "thesis": ..., "sfanav": ...}`` with plain, stable metric
names (``"MAE x (%)"``, ``"MED (m)"``, ...), plus the plots it wrote. The
``sfanav experiment NAME`` command prints the table and writes it as JSON.

Families live in their own modules (``localization``, ``odometry``,
``navigation``, ...) and register themselves with :func:`register`; this
module imports them lazily on first use.
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

# Modules that register experiments (imported on first lookup).
FAMILIES = ("localization", "odometry", "navigation", "gardens")


@dataclass
class ExperimentResult:
    """What an experiment reports.

    ``rows``: one dict per metric with keys ``metric`` (plain, stable name),
    ``thesis`` (the thesis's value, or None when it reports none) and
    ``sfanav`` (ours); optional extra keys (e.g. ``"protocol"``,
    ``"baseline"``) are kept in the JSON. ``plots``: paths of PNGs written.
    ``notes``: free text printed under the table (settings, protocol).
    """

    experiment: str
    rows: list[dict[str, Any]]
    plots: list[str] = field(default_factory=list)
    notes: str = ""

    def to_json(self) -> dict[str, Any]:
        return {"experiment": self.experiment, "rows": self.rows, "plots": self.plots, "notes": self.notes}

    def write_json(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_json(), indent=2, default=float) + "\n")
        return path

    def table(self) -> str:
        """The rows as an aligned text table (metric, thesis, sfanav)."""

        def fmt(v: Any) -> str:
            if v is None:
                return "-"
            if isinstance(v, float):
                return f"{v:.4g}"
            return str(v)

        rows = [("metric", "thesis", "sfanav")] + [(str(r["metric"]), fmt(r.get("thesis")), fmt(r.get("sfanav"))) for r in self.rows]
        widths = [max(len(r[i]) for r in rows) for i in range(3)]
        lines = [f"{a:<{widths[0]}}  {b:>{widths[1]}}  {c:>{widths[2]}}" for a, b, c in rows]
        lines.insert(1, "-" * (sum(widths) + 4))
        return "\n".join(lines)


@dataclass(frozen=True)
class Experiment:
    """A registered experiment: ``run(out, quick=..., seed=..., progress=...)``
    writes plots under ``out`` and returns an :class:`ExperimentResult`.
    ``quick`` shrinks it to a smoke test (tests, CI); the default is the
    full setting."""

    name: str
    title: str
    run: Callable[..., ExperimentResult]


_REGISTRY: dict[str, Experiment] = {}


_loaded = False


def register(name: str, title: str) -> Callable[[Callable[..., ExperimentResult]], Callable[..., ExperimentResult]]:
    """Decorator: registers ``fn(out: Path, *, quick: bool, seed: int,
    progress: bool) -> ExperimentResult`` under ``name``."""

    def deco(fn: Callable[..., ExperimentResult]) -> Callable[..., ExperimentResult]:
        if name in _REGISTRY:
            raise ValueError(f"experiment {name!r} is registered twice")
        _REGISTRY[name] = Experiment(name, title, fn)
        return fn

    return deco


def _load() -> None:
    global _loaded
    if _loaded:
        return
    _loaded = True
    for fam in FAMILIES:
        try:
            importlib.import_module(f"{__name__}.{fam}")
        except ModuleNotFoundError as e:  # a family not written yet
            if e.name != f"{__name__}.{fam}":
                raise


def names() -> list[str]:
    """Registered experiment names, sorted."""
    _load()
    return sorted(_REGISTRY)


def get(name: str) -> Experiment:
    """The experiment called ``name`` (ValueError listing the known ones)."""
    _load()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown experiment {name!r}; known: {', '.join(sorted(_REGISTRY)) or 'none'}") from None


def run(name: str, out: str | Path, *, quick: bool = False, seed: int = 0, progress: bool = True) -> ExperimentResult:
    """Runs one experiment, writes ``out/<name>.json`` and returns its result."""
    exp = get(name)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    result = exp.run(out, quick=quick, seed=seed, progress=progress)
    result.write_json(out / f"{name}.json")
    return result
