#!/usr/bin/env bash
# Builds sfanav's wheel (abi3: one wheel for CPython >= 3.10; manylinux2014:
# glibc >= 2.17, linked with zig so that it does not depend on this machine's
# newer glibc) and the sdist into OUT (default dist/).
#
#   scripts/build_wheel.sh [OUT]            # x86_64 wheel + sdist
#   scripts/build_wheel.sh [OUT] aarch64    # also the aarch64 wheel (cross-compiled; ARM boards)
#
# Installing the wheel needs no Rust toolchain: pip install dist/sfanav-*.whl
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH="$HOME/.cargo/bin:$PATH"
PY="${PYTHON:-python3}"
# maturin finds zig through `python3 -m ziglang` on PATH: put $PY's directory
# first so that a virtual environment's interpreter (PYTHON=venv/bin/python) is it
PATH="$(dirname "$(command -v "$PY")"):$PATH"
OUT="${1:-dist}"
"$PY" -m pip install --quiet --disable-pip-version-check "maturin>=1.7,<2" "ziglang>=0.11"
"$PY" -m maturin build --quiet --release --zig --compatibility manylinux2014 --out "$OUT"
if [[ "${2:-}" == "aarch64" ]]; then
    rustup target add aarch64-unknown-linux-gnu
    "$PY" -m maturin build --quiet --release --zig --compatibility manylinux2014 \
        --target aarch64-unknown-linux-gnu --out "$OUT"
fi
"$PY" -m maturin sdist --out "$OUT" >/dev/null
ls -l "$OUT"
