#!/usr/bin/env python3
"""Runs the fuzz targets (model loader, config parser, ROS bag import) for
a bounded time each (the CI step): each starts from
the committed corpus, writes what it finds to a scratch directory, and a
crash, a timeout or an out-of-memory fails the run with the input's path.

    python3 tests/fuzz/run.py                 # 60 s per target
    python3 tests/fuzz/run.py --seconds 600   # longer, by hand
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
TARGETS = {"model": 200_000, "config": 20_000, "bag": 64_000}  # target -> largest input (bytes)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=int, default=60, help="fuzzing time per target (default 60)")
    ap.add_argument("--artifacts", default=None, help="where crashing inputs go (default: a temporary folder)")
    args = ap.parse_args()
    artifacts = Path(args.artifacts or tempfile.mkdtemp(prefix="sfanav-fuzz-artifacts-"))
    artifacts.mkdir(parents=True, exist_ok=True)
    failed = False
    for target, max_len in TARGETS.items():
        with tempfile.TemporaryDirectory(prefix=f"sfanav-fuzz-{target}-") as scratch:
            cmd = [sys.executable, str(HERE / "fuzz.py"), target, scratch, str(HERE / "corpus" / target),
                   f"-max_total_time={args.seconds}", f"-max_len={max_len}", "-timeout=30", "-rss_limit_mb=5000",
                   f"-artifact_prefix={artifacts}/{target}-", "-print_final_stats=1"]
            r = subprocess.run(cmd, capture_output=True, text=True, check=False)
            lines = [ln for ln in r.stderr.splitlines() if not ln.startswith("INFO: Instrumenting")]
            runs = next((ln.split()[-1] for ln in lines if ln.startswith("stat::number_of_executed_units")), "?")
            if r.returncode != 0:
                failed = True
                print(f"fuzz {target}: FAILED (exit {r.returncode}); inputs in {artifacts}")
                print("\n".join(lines[-40:]))
            else:
                print(f"fuzz {target}: {runs} inputs in {args.seconds} s, no crash")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
