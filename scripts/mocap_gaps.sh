#!/usr/bin/env bash
# Gap filling on real motion-capture markers (docs/gap-filling.md, "Real markers, thinned").
# The recordings are not in the repository (two have no stated licence): point MOCAP_DIR at
# a folder holding their masked .npz (tracks [T, N, 3] in metres, observed [T, N]).
# Each file is cut to about 100 frames (every 4th or 7th frame), 15 % of its observed
# entries are hidden in spans inside the tracks' observations, short (2–8 frames) or long
# (10–30 frames), and one fit at the defaults but 300 iterations fills them. Writes
# results/mocap/NAME_SPAN_SEED.json (each fit's report) and prints the table, in mm.
#   scripts/mocap_gaps.sh MOCAP_DIR [SEEDS] [DOMA_BINARY]     (SEEDS: "0 1 2" for the table)
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:?the folder of the recordings}
seeds=${2:-0}
DOMA=${3:-${CARGO_TARGET_DIR:-target}/release/doma}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p results/mocap
# name, stride, clip (frames of the recording).
clips="85_12 4 1000..1400
Qualisys 4 0..340
right_knee 4 0..400
codamotion_gaitwands_20150204 7 0..700
Walking_Hybrid_1_5 7 0..646"
for seed in $seeds; do
  while read -r name stride frames; do
    for span in 2..=8 10..=30; do
      out="results/mocap/${name}_${span/..=/-}_$seed.json"
      "$DOMA" fit "$dir/$name.npz" --stride "$stride" --frames "$frames" --iters 300 \
        --holdout-observations 0.15 --holdout-span "$span" --seed "$seed" \
        --out "$work/$name-$span-$seed" --quiet --json "$out"
    done
  done <<< "$clips"
done
python3 - "$seeds" <<'PY'
import json, sys
seeds = sys.argv[1].split()
# The columns by name, from the reports: doma's fill, the field alone, then every filler.
# The field's fills are not baselines (reports before 2026-12 called them carried and
# framewise).
FIELDS = {"doma", "field", "field_fill", "field_fill_framewise", "carried", "framewise"}
# doma's own donor fillers are reported, not counted as baselines.
OWN = {"segment", "chain"}
first = json.load(open(f"results/mocap/85_12_2-8_{seeds[0]}.json"))["held_out_observations"]
cols = list(first["distance"])
base = [c for c in cols if c not in FIELDS | OWN]
fmt = lambda v: f"{v:.1f}" if v >= 10 else f"{v:.2f}"
print("| recording | gaps | hidden | " + " | ".join(cols) + " | doma / best baseline | per seed | seeds whose field's fills took weight (gaps ≤ 16 frames; longer) |")
print("|---" * (6 + len(cols)) + "|")
for name in ["85_12", "Qualisys", "right_knee", "codamotion_gaitwands_20150204", "Walking_Hybrid_1_5"]:
    for span, label in [("2-8", "short"), ("10-30", "long")]:
        gs = [json.load(open(f"results/mocap/{name}_{span}_{s}.json"))["held_out_observations"] for s in seeds]
        mm = [{c: 1000 * g["distance"][c] for c in cols} for g in gs]
        mean = {c: sum(m[c] for m in mm) / len(mm) for c in cols}
        best = min(mean[c] for c in base)
        per = [m["doma"] / min(m[c] for c in base) for m in mm]
        # The seeds whose blend gave the field's fills weight, in the class of these gaps.
        field_share = lambda w: w.get("field_fill", 0) + w.get("field_fill_framewise", 0)
        def weighed(g, k):
            b = g["blend"]
            return field_share(b["short"]) > 0 if k == 0 else any(field_share(c["weights"]) > 0 for c in b.get("by_length", [])) or field_share(b["long"]) > 0
        used = "; ".join(f"{sum(weighed(g, k) for g in gs)}/{len(gs)}" for k in range(2))
        n = sum(g["entries"] for g in gs) // len(gs)
        print(f"| `{name}` | {label} | {n} | " + " | ".join(fmt(mean[c]) for c in cols)
              + f" | {mean['doma'] / best:.2f} | " + ", ".join(f"{p:.2f}" for p in per) + f" | {used} |")
PY
