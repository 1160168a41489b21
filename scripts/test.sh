#!/usr/bin/env bash
# The whole test suite: installs sfanav (and the test extras) from this
# checkout, then runs the Rust core's tests, the Python tests and a bounded
# fuzzing run of the model loader and the config parser.
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH="$HOME/.cargo/bin:$PATH"
PY="${PYTHON:-python3}"

echo "== installing sfanav with test extras (builds the Rust extension)"
"$PY" -m pip install --quiet --disable-pip-version-check ".[test]"

echo "== cargo test (sfa-core)"
cargo test --quiet

echo "== pytest"
(cd tests && "$PY" -m pytest -q -p no:cacheprovider)

echo "== fuzz: model loader and network config parser (60 s each, tests/fuzz)"
"$PY" tests/fuzz/run.py --seconds 60
