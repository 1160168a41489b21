"""Shared by robustness_candidates.py and camera_gamma_summary.py: a candidates JSON's entries grouped by garden and
candidate over the seeds they were trained at."""

from __future__ import annotations

from typing import Any


def seed_groups(entries: dict[str, Any]) -> dict[str, dict[int, dict[str, float]]]:
    """``{"garden|NAME": {seed: {corruption: MED}}}`` from entries keyed ``garden|NAME`` (seed 0) or
    ``garden|NAME@S`` (seed S) whose value holds ``"MED (m)"``; other keys are skipped."""
    groups: dict[str, dict[int, dict[str, float]]] = {}
    for key, v in entries.items():
        parts = key.split("|")
        if len(parts) != 2 or not isinstance(v, dict) or "MED (m)" not in v:
            continue
        g, name = parts
        base, _, seed = name.partition("@")
        groups.setdefault(f"{g}|{base}", {})[int(seed or 0)] = v["MED (m)"]
    return groups
