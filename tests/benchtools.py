"""The benchmark scripts (benches/, not a package) imported by their smoke tests."""

import importlib
import sys
from pathlib import Path

BENCHES = Path(__file__).resolve().parents[1] / "benches"


def import_bench(name: str):
    """The module benches/NAME.py (imported with benches/ on sys.path only
    while it loads, as its own imports of _benchlib need)."""
    sys.path.insert(0, str(BENCHES))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(BENCHES))
