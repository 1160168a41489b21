#!/usr/bin/env bash
# The whole test suite: builds sfanav's wheel from this checkout and installs
# it with the test extras (after checking the Rust formatting), then runs the Rust core's tests, the Python tests,
# the wheel in a fresh virtual environment without a Rust toolchain, and a
# bounded fuzzing run of the model loader, the config parser and the ROS bag import.
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH="$HOME/.cargo/bin:$PATH"
PY="${PYTHON:-python3}"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT

echo "== cargo fmt --check (rustfmt.toml)"
cargo fmt --version >/dev/null 2>&1 || rustup component add rustfmt
cargo fmt --all -- --check

echo "== building the wheel and the sdist (scripts/build_wheel.sh)"
./scripts/build_wheel.sh "$WORK/dist"
WHEEL="$(ls "$WORK"/dist/sfanav-*-abi3-*x86_64*.whl)"

echo "== ROS 1 from Debian's packages (the live node's tests run against a real roscore)"
ROS_DEBS="ros-core python3-rospy python3-rosbag python3-sensor-msgs python3-nav-msgs python3-geometry-msgs python3-tf2-msgs"
if ! command -v roscore >/dev/null || ! command -v rosbag >/dev/null; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $ROS_DEBS >/dev/null
fi
export SFANAV_REQUIRE_ROS=1   # tests/test_ros1_node.py fails instead of skipping when ROS is missing

echo "== installing the wheel with test extras"
"$PY" -m pip install --quiet --disable-pip-version-check "${WHEEL}[test]"
"$PY" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps "$WHEEL"

echo "== cargo test (sfa-core)"
cargo test --quiet

echo "== pytest"
(cd tests && "$PY" -m pytest -q -p no:cacheprovider)

echo "== the wheel in a fresh venv, no Rust toolchain on PATH: sfanav demo --quick"
"$PY" -m venv "$WORK/venv"
(
    export PATH="$WORK/venv/bin:/usr/local/bin:/usr/bin:/bin"
    unset PYTHONPATH
    if command -v cargo >/dev/null || command -v rustc >/dev/null; then
        echo "a Rust toolchain is on PATH; the no-Rust install check would prove nothing" >&2
        exit 1
    fi
    "$WORK/venv/bin/python" -m pip install --quiet --disable-pip-version-check "$WHEEL"
    cd "$WORK" && "$WORK/venv/bin/sfanav" demo --quick --no-progress --out "$WORK/demo" >/dev/null
    test -s "$WORK/demo/demo.json"
    echo "ok: $(basename "$WHEEL") ($(du -k "$WHEEL" | cut -f1) KB) installed and ran without Rust"
)

echo "== fuzz: model loader, network config parser and ROS bag import (60 s each, tests/fuzz)"
"$PY" tests/fuzz/run.py --seconds 60
