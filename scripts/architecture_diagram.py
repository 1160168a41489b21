#!/usr/bin/env python3
"""Draws docs/architecture.md's diagram from the code: the imports between
sfanav's stages (subpackages), as a Mermaid graph, with each stage's modules.

    python3 scripts/architecture_diagram.py            # prints the Mermaid block
    python3 scripts/architecture_diagram.py --counts   # also the number of imports per edge

Imports under ``if TYPE_CHECKING:`` (annotations only) are left out; so are
the private helpers (_checks, _progress, ...), which every stage may use.
"""

from __future__ import annotations

import argparse
import ast
from collections import Counter
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "python" / "sfanav"
STAGES = ["data", "features", "groundtruth", "sim", "loopclosure", "sfa", "localization", "landmarks", "odometry", "pipeline",
          "navigation", "experiments", "app"]
LABEL = {
    "data": "data<br/>images, datasets, unwarping",
    "features": "features<br/>local features over the seasons, robustness prediction",
    "groundtruth": "groundtruth<br/>marker ground truth, camera calibration",
    "sim": "sim<br/>simulated garden",
    "loopclosure": "loopclosure<br/>places seen again, long-term order",
    "sfa": "sfa<br/>SFA node, network -> slow features",
    "localization": "localization<br/>slow features -> position",
    "landmarks": "landmarks<br/>marker views -> stacked position",
    "odometry": "odometry<br/>metric map, pose graph, EKF",
    "pipeline": "pipeline<br/>the training recipe applied to a run",
    "navigation": "navigation<br/>cost, gradient, descents",
    "experiments": "experiments<br/>thesis reruns",
    "app": "app<br/>sfanav command, demo",
}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def stage(module: str) -> str | None:
    parts = module.split(".")
    if len(parts) < 2 or parts[1].startswith("_"):
        return "app" if len(parts) > 1 and parts[1] == "__main__" else None
    return parts[1]


def imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text())
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for sub in node.body for n in ast.walk(sub))
    mod = module_name(path)
    out = []
    for node in ast.walk(tree):
        if id(node) in skip or not isinstance(node, ast.ImportFrom) or not node.level:
            continue
        base = mod.split(".")
        if path.name != "__init__.py":
            base = base[:-1]
        base = base[: len(base) - (node.level - 1)]
        target = ".".join(base + ([node.module] if node.module else []))
        if node.module is None:
            out += [f"{target}.{a.name}" for a in node.names]
        else:
            out.append(target)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", action="store_true", help="label edges with the number of imports")
    args = ap.parse_args()
    edges: Counter[tuple[str, str]] = Counter()
    modules: dict[str, list[str]] = {s: [] for s in STAGES}
    for path in sorted(PKG.rglob("*.py")):
        mod = module_name(path)
        here = stage(mod)
        if here is None:
            continue
        if path.name != "__init__.py" and here in modules:
            modules[here].append("/".join(mod.split(".")[2:]) or path.stem)  # a subfolder's modules as folder/module
        for target in imports(path):
            there = stage(target)
            if there in STAGES and there != here:
                edges[(here, there)] += 1
    print("```mermaid")
    print("flowchart LR")
    for s in STAGES:
        mods = ", ".join(sorted(modules[s]))
        print(f'  {s}["{LABEL[s]}<br/><small>{mods}</small>"]')
    for (a, b), n in sorted(edges.items(), key=lambda e: (STAGES.index(e[0][0]), STAGES.index(e[0][1]))):
        print(f"  {a} -->{'|' + str(n) + '|' if args.counts else ''} {b}")
    print("```")


if __name__ == "__main__":
    main()
