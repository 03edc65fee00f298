#!/usr/bin/env bash
# Builds the Python package as one abi3 wheel (CPython >= 3.11, tagged manylinux) into
# dist/, with maturin, reusing the Rust build under $CARGO_TARGET_DIR. The wheel installs
# with `pip install dist/doma-*.whl` on another Linux machine of the same or a newer glibc,
# with no Rust toolchain. DOMA_WHEEL_FEATURES adds Cargo features (e.g. "wgpu"; the
# default wheel has the CPU backends). Prints the wheel's path.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${DOMA_VENV:-$HOME/.cache/doma-venv}"
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/python" -m pip -q --disable-pip-version-check install -r python/requirements-dev.txt
export PYO3_PYTHON="$VENV/bin/python"
FEATURES=()
[ -n "${DOMA_WHEEL_FEATURES:-}" ] && FEATURES=(--features "$DOMA_WHEEL_FEATURES")
rm -rf dist
# manylinux_2_35: what the extension needs of glibc on this machine (Debian 12, glibc 2.36;
# maturin finds it eligible); maturin checks that the extension
# needs no newer symbol and no library outside the manylinux set.
"$VENV/bin/maturin" build --release -m python/Cargo.toml --out dist \
  --compatibility "${DOMA_MANYLINUX:-manylinux_2_35}" "${FEATURES[@]}" >&2
ls dist/doma-*.whl
