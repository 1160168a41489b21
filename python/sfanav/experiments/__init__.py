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
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

# Modules that register experiments (imported on first lookup).
FAMILIES = ("localization", "odometry", "navigation", "gardens", "gardens_suite", "robustness", "features", "landmarks",
            "corruptions", "updates")


@dataclass
class ExperimentResult:
    """What an experiment reports.

    Attributes
    ----------
    experiment : str
        The registered name (``"5.1.1"``, ``"5.3.2"``, ...); also ``name``.
    rows : list of dict
        One dict per metric with keys ``metric`` (plain, stable name),
        ``thesis`` (the thesis's value, or None when it reports none) and
        ``sfanav`` (ours); extra keys (e.g. ``"protocol"``) are kept in the
        JSON.
    plots : list of str
        Paths of the PNGs written.
    notes : str
        Free text printed under the table (settings, protocol).
    targets : dict str -> bool
        Named targets and whether they are met (printed under the table).
    figures : dict str -> Path
        Caption -> PNG, where an experiment names its figures.
    details : dict
        The objects behind the numbers (learners, estimates, ...), for further
        use in Python; not written to JSON.
    """

    experiment: str
    rows: list[dict[str, Any]]
    plots: list[str] = field(default_factory=list)
    notes: str = ""
    targets: dict[str, bool] = field(default_factory=dict)
    figures: dict[str, Path] = field(default_factory=dict)
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.experiment

    def row(self, metric: str) -> Any:
        """The sfanav value of one metric (KeyError if there is no such row)."""
        for r in self.rows:
            if r["metric"] == metric:
                return r["sfanav"]
        raise KeyError(f"no row {metric!r} in {self.experiment}")

    def to_json(self) -> dict[str, Any]:
        out = {"experiment": self.experiment, "rows": self.rows, "plots": self.plots, "notes": self.notes}
        if self.targets:
            out["targets"] = self.targets
        return out

    def write_json(self, path: str | Path) -> Path:
        """Writes :meth:`to_json` to ``path`` atomically (a temporary file
        renamed into place). Plots in the JSON's folder or below it are
        written relative to it, so that a results file stays valid when
        its folder is moved or committed."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        out = self.to_json()
        base = path.parent.resolve()

        def relative(p: str) -> str:
            q = Path(p).resolve()
            return q.relative_to(base).as_posix() if q.is_relative_to(base) else str(p)

        out["plots"] = [relative(p) for p in out["plots"]]
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(out, indent=2, default=float) + "\n")
        os.replace(tmp, path)
        return path

    def table(self) -> str:
        """The rows as an aligned text table (metric, thesis, sfanav), then
        the targets."""
        return format_rows(self.rows, self.targets)


def format_value(v: Any) -> str:
    """A table cell: ``-`` for None, yes/no for booleans, 3 significant
    decimals for small floats."""
    if v is None:
        return "-"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return f"{v:.3g}" if abs(v) < 0.01 and v != 0 else (f"{v:.3f}" if abs(v) < 100 else f"{v:.1f}")
    return str(v)


def format_rows(rows: Sequence[Mapping[str, Any]], targets: Mapping[str, bool] | None = None) -> str:
    """Rows ``{"metric", "thesis", "sfanav"}`` as an aligned text table, then
    the targets with ``met`` / ``NOT met``, then each row's ``flag`` (a figure
    to distrust or withheld: :mod:`sfanav.experiments.flags`)."""
    cells = [("metric", "thesis", "sfanav")] + [
        (str(r["metric"]), format_value(r.get("thesis")), format_value(r.get("sfanav"))) for r in rows]
    w = [max(len(c[i]) for c in cells) for i in range(3)]
    lines = [f"{a:<{w[0]}}  {b:>{w[1]}}  {c:>{w[2]}}" for a, b, c in cells]
    lines.insert(1, "-" * (sum(w) + 4))
    for name, ok in (targets or {}).items():
        lines.append(f"target: {name}: {'met' if ok else 'NOT met'}")
    for r in rows:
        if r.get("flag"):
            lines.append(f"flag: {r['metric']}: {r['flag']}")
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
