#!/usr/bin/env python3
"""What each class of gap's weights gave on the validation that chose them, over many fits:
`doma complete RUN --blend FILE` on every run folder, each class's held-out figures (its
weights against the best classic filler alone on the same held-out spans) gathered and
summarised.

    python3 scripts/held_out_classes.py FOLDER... [--doma BIN] [--json OUT]

A FOLDER is a run folder of `doma fit`, or a folder holding run folders at any depth (those
with a `config.json`), as `native_rate_gaps.py --fits DIR` keeps them. The summary splits
the classes as the blend chooses them: the short gaps, the pooled long gaps, a length class
on its own weights, a length class on the pooled long weights (its spans could not tell
its own choice from them). Standard library only.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile


def runs(folder):
    if os.path.isfile(os.path.join(folder, "config.json")):
        return [folder]
    found = []
    for root, dirs, files in os.walk(folder):
        dirs.sort()
        if "config.json" in files:
            found.append(root)
            dirs.clear()
    return found


def classes(doma, run):
    with tempfile.TemporaryDirectory() as tmp:
        blend = os.path.join(tmp, "blend.json")
        out = os.path.join(tmp, "filled.npz")
        done = subprocess.run(
            [doma, "complete", run, "--out", out, "--blend", blend],
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            sys.exit(f"doma complete {run} failed:\n{done.stderr}")
        with open(blend) as f:
            b = json.load(f)
    rows = []
    for k, name in enumerate(["short", "long"]):
        held = (b.get("held_out") or [None, None])[k]
        if held:
            rows.append(dict(run=run, kind=name, **held))
    shortest = 17
    for c in b.get("by_length", []):
        longest = c.get("longest")
        label = f"{shortest}-{longest}" if longest else f"{shortest}+"
        shortest = (longest or shortest) + 1
        if c.get("held_out"):
            kind = "own" if c["own"] else "pooled"
            rows.append(dict(run=run, kind=kind, frames=label, **c["held_out"]))
    return rows


def summary(name, rows):
    if not rows:
        return f"| {name} | 0 | – | – | – | – |"
    ratios = [r["chosen"] / r["best_alone"] if r["best_alone"] > 0 else 1.0 for r in rows]
    worst = max(range(len(rows)), key=lambda i: ratios[i])
    w = rows[worst]
    run = os.path.relpath(w["run"])
    run = w["run"] if run.startswith("..") else run
    where = f"{run} {w.get('frames', w['kind'])}"
    geo = math.exp(sum(math.log(max(r, 1e-12)) for r in ratios) / len(ratios))
    above = sum(r > 1.05 for r in ratios)
    return f"| {name} | {len(rows)} | {ratios[worst]:.2f} ({where}) | {above} | {geo:.3f} |"


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folders", nargs="+")
    p.add_argument("--doma", default="doma")
    p.add_argument("--json", help="write every class's figures here")
    a = p.parse_args()
    rows = []
    for folder in a.folders:
        found = runs(folder)
        if not found:
            sys.exit(f"{folder}: no run folder (a config.json) there")
        for run in found:
            rows += classes(a.doma, run)
            print(run, file=sys.stderr, flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    print("| classes | held out | their weights ÷ best filler alone: worst | above 1.05 | geometric mean |")
    print("|---|---|---|---|---|")
    for name, kind in [
        ("short gaps", "short"),
        ("long gaps, pooled", "long"),
        ("a length class, its own weights", "own"),
        ("a length class, the pooled weights", "pooled"),
    ]:
        print(summary(name, [r for r in rows if r["kind"] == kind]))


if __name__ == "__main__":
    main()
