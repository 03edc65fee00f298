#!/usr/bin/env bash
# The Python package's tests, against the wheel a user installs: builds the abi3 wheel
# (scripts/build_wheel.sh, reusing the Rust build under $CARGO_TARGET_DIR, with the wgpu
# feature of the README's test command), installs it into a fresh virtual environment, and
# runs pytest on python/tests (the examples included) with no cargo or rustc on PATH.
set -euo pipefail
cd "$(dirname "$0")/.."
WHEEL="$(DOMA_WHEEL_FEATURES="${DOMA_WHEEL_FEATURES-wgpu}" scripts/build_wheel.sh | tail -1)"
TEST_VENV="${DOMA_TEST_VENV:-$HOME/.cache/doma-test-venv}"
rm -rf "$TEST_VENV"
python3 -m venv "$TEST_VENV"
"$TEST_VENV/bin/python" -m pip -q --disable-pip-version-check install \
  -r python/requirements-dev.txt "$WHEEL"
# The toolchain's folder off PATH: the installed wheel must need no Rust.
NO_RUST_PATH="$(printf '%s' "$PATH" | tr ':' '\n' | grep -v -e '\.cargo/bin' -e '\.rustup' | paste -sd:)"
if PATH="$NO_RUST_PATH" command -v cargo >/dev/null; then
  echo "cargo is still on PATH without the Rust folders: $(PATH="$NO_RUST_PATH" command -v cargo)" >&2
  exit 1
fi
PATH="$TEST_VENV/bin:$NO_RUST_PATH" VIRTUAL_ENV="$TEST_VENV" "$TEST_VENV/bin/python" -m pytest -q python/tests
