#!/usr/bin/env bash
# The Python package's tests: builds the package from this workspace into a virtual
# environment outside the clone (maturin through pip, reusing the Rust build under
# $CARGO_TARGET_DIR), then runs pytest on python/tests (the example included).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${DOMA_VENV:-$HOME/.cache/doma-venv}"
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
# As if activated: maturin's build hook runs `maturin` from the PATH.
export PATH="$VENV/bin:$PATH" VIRTUAL_ENV="$VENV"
PIP=("$VENV/bin/python" -m pip -q --disable-pip-version-check)
"${PIP[@]}" install -r python/requirements-dev.txt
# The interpreter that PyO3 builds for, the same for every build of the extension.
export PYO3_PYTHON="$VENV/bin/python"
"${PIP[@]}" install --no-build-isolation --force-reinstall --no-deps ./python
"$VENV/bin/python" -m pytest -q python/tests
