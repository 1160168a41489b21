#!/usr/bin/env bash
# The whole test suite: installs sfanav (and the test extras) from this
# checkout, then runs the Rust core's tests and the Python tests.
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH="$HOME/.cargo/bin:$PATH"
PY="${PYTHON:-python3}"

echo "== installing sfanav with test extras (builds the Rust extension)"
"$PY" -m pip install --quiet --disable-pip-version-check ".[test]"

echo "== cargo test (sfa-core)"
cargo test --quiet

echo "== pytest"
cd tests && "$PY" -m pytest -q -p no:cacheprovider
