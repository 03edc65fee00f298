#!/usr/bin/env bash
# The GPU figures of docs/speed.md in one short run, for a machine with a real GPU (wgpu:
# Vulkan, Metal or DX12). Everything it measures lands in $OUT (default: ./gpu-figures):
#   bench.json        doma bench --backend all (flex, ndarray, wgpu; both Jacobian methods)
#   synthetic.json    one full Affinity-H fit on wgpu (1000 iterations, rotation), its EPE
#                     and seconds: the goal is < 15 s (the paper: 96 s, TITAN RTX)
#   tests.log         the wgpu tests (kernels against their reference, Analytic against
#                     Autodiff, wgpu against flex, no host read inside a step), with CI=true
#                     so that a missing adapter fails
# Usage: scripts/gpu_check.sh [DOMA_BINARY]   (builds the release binary when none is given)
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-gpu-figures}"
mkdir -p "$OUT"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"
DOMA="${1:-}"
if [ -z "$DOMA" ]; then
  cargo build --release --features wgpu --bin doma
  DOMA="${CARGO_TARGET_DIR:-target}/release/doma"
fi
nvidia-smi -L > "$OUT/gpu.txt" 2>&1 || true
"$DOMA" bench --backend all --json "$OUT/bench.json" 2>&1 | tee "$OUT/bench.log"
"$DOMA" synthetic --motion rotation --variant affinity --reg h --backend wgpu \
  --json "$OUT/synthetic.json" 2>&1 | tee "$OUT/synthetic.log"
if [ -z "${1:-}" ]; then
  CI=true cargo test --release --features wgpu --test numerics --test fitting --test host_sync \
    2>&1 | tee "$OUT/tests.log"
fi
