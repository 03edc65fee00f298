#!/usr/bin/env bash
# The wall time of a default completion: `doma fit` at its defaults on 100 frames × 73
# markers of the shipped motion-capture recording (data/mocap/right_knee.c3d, every 4th
# of its first 400 frames), with 15 % of the observations hidden in spans so that the
# tracks have gaps (which turns on the gap-filling defaults: 300 iterations, L_H at 0.1),
# then `doma complete` to a .c3d. Prints each step's seconds and the fill's error on the
# hidden entries, mm (docs/speed.md, "A completion").
#   scripts/completion_time.sh [DOMA_BINARY]
set -euo pipefail
cd "$(dirname "$0")/.."
DOMA=${1:-${CARGO_TARGET_DIR:-target}/release/doma}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
now() { date +%s.%N; }
t0=$(now)
"$DOMA" fit data/mocap/right_knee.c3d --frames 0..400 --stride 4 \
  --holdout-observations 0.15 --out "$work/run" --quiet --json "$work/report.json"
t1=$(now)
"$DOMA" complete "$work/run" --out "$work/filled.c3d" 2> /dev/null
t2=$(now)
python3 - "$work/report.json" "$t0" "$t1" "$t2" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
t0, t1, t2 = map(float, sys.argv[2:5])
g = r["held_out_observations"]
print(f"fit {t1 - t0:.1f} s ({r['iterations']} iterations), complete {t2 - t1:.1f} s, "
      f"total {t2 - t0:.1f} s")
print("hidden entries:", g["entries"], "; mean error, mm:",
      ", ".join(f"{k} {v:.2f}" for k, v in g["distance"].items()))
PY
