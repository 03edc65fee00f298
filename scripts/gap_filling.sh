#!/usr/bin/env bash
# Gap filling on tracker-like data made from the shipped meshes (examples/tracker_data.rs):
# each sequence in both layouts, 20 % of the observations hidden in spans, 90 % of the
# tracks fitted at doma fit's defaults. Writes results/tracks/NAME.json
# (each fit's report, its per-track leans counted) and prints the table of docs/gap-filling.md.
#   scripts/gap_filling.sh [DOMA_BINARY]
set -euo pipefail
cd "$(dirname "$0")/.."
DOMA=${1:-${CARGO_TARGET_DIR:-target}/release/doma}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cargo run --release --quiet --example tracker_data -- "$work/data"
mkdir -p results/tracks
for name in cdp_male_wave md2_faerie; do
  for layout in pointodyssey tapvid3d; do
    "$DOMA" fit "$work/data/${name}_$layout.npz" --out "$work/$name-$layout" --quiet --json - \
      --drop-unobserved --holdout-observations 0.2 --test-fraction 0.1 \
      > "results/tracks/${name}_$layout.json"
  done
done
python3 - <<'PY'
import json
# A report lists every track's lean (1,180 of cdp_male_wave's 9,293 tracks): the files
# kept here count them by the filler each leans toward.
for name in ["cdp_male_wave", "md2_faerie"]:
    for layout in ["pointodyssey", "tapvid3d"]:
        path = f"results/tracks/{name}_{layout}.json"
        r = json.load(open(path))
        blend = r["held_out_observations"]["blend"]
        if isinstance(blend.get("leans"), list):
            toward = {}
            for lean in blend["leans"]:
                top = max(lean["toward"], key=lean["toward"].get)
                toward[top] = toward.get(top, 0) + 1
            blend["leans"] = {"count": len(blend["leans"]), "toward": toward}
            json.dump(r, open(path, "w"), indent=2)
# The columns by name, from the reports: doma's fill, the field alone, then every filler.
first = json.load(open("results/tracks/cdp_male_wave_pointodyssey.json"))["held_out_observations"]
cols = list(first["epe_x1e4"])
print("| sequence | layout | hidden observations | " + " | ".join(cols) + " |")
print("|---" * (3 + len(cols)) + "|")
for name in ["cdp_male_wave", "md2_faerie"]:
    for layout in ["pointodyssey", "tapvid3d"]:
        g = json.load(open(f"results/tracks/{name}_{layout}.json"))["held_out_observations"]
        e = g["epe_x1e4"]
        print(f"| `{name}` | {layout} | {g['entries']} | " + " | ".join(f"{e[c]:.2f}" for c in cols) + " |")
PY
