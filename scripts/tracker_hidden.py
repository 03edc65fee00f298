#!/usr/bin/env python3
"""The tracker's own hidden entries of a fitted tracker file, filled and scored against the
truth the simulated tracker keeps (examples/tracker_data.rs): split into the entries inside
a track's gaps and those before its first or after its last sighting.

    python3 scripts/tracker_hidden.py RUN_DIR... [--doma BIN] [--methods doma,neighbours,...]

Each RUN_DIR is a `doma fit` of a PointOdyssey or TAPVid-3D file whose hidden entries hold
the true positions (`trajs_3d` / `tracks_XYZ`); the hidden entries are those the fit's
mask leaves unobserved (PointOdyssey's: not valid and visible). Every method fills every point at every
frame (`doma complete RUN --extrapolate [--method M]`). The error is the paper's EPE (L1
over x, y, z) in units of half the longest side of the observed entries' bounding box (the
scale `doma fit` normalises by), ×1e4. Needs numpy.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

KEYS = ["trajs_3d", "tracks_XYZ"]


def truth_of(path):
    d = np.load(path)
    for key in KEYS:
        if key in d.files:
            return d[key].astype(np.float64)
    sys.exit(f"{path}: no trajs_3d or tracks_XYZ: not a tracker file with its truth")


def complete(doma, run, out, method):
    cmd = [doma, "complete", run, "--out", out, "--extrapolate"]
    if method != "doma":
        cmd += ["--method", method]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    d = np.load(out)
    kept = d["kept"] if "kept" in d.files else None
    return d["tracks"].astype(np.float64), d["observed"].astype(bool), kept


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--doma", default=os.path.join(
        os.environ.get("CARGO_TARGET_DIR", "target"), "release", "doma"))
    ap.add_argument("--methods", default="doma,neighbours,field-fill,chain")
    ap.add_argument("--json", help="write the table's numbers here too")
    args = ap.parse_args()
    methods = args.methods.split(",")
    rows = []
    for run in args.runs:
        config = json.load(open(os.path.join(run, "config.json")))
        truth = truth_of(config["data"])
        with tempfile.TemporaryDirectory() as tmp:
            filled = {m: complete(args.doma, run, os.path.join(tmp, f"{m}.npz"), m)
                      for m in methods}
        # The fit's own mask (PointOdyssey's: valid and visible), as the completion keeps it.
        _, seen, kept = next(iter(filled.values()))
        if kept is not None:
            truth = truth[:, kept]
        lo = np.nanmin(truth[seen], axis=0)
        hi = np.nanmax(truth[seen], axis=0)
        scale = 0.5 * float(np.max(hi - lo))
        t = seen.shape[0]
        frames = np.arange(t)[:, None]
        any_seen = seen.any(axis=0)
        first = np.where(any_seen, seen.argmax(axis=0), t)
        last = np.where(any_seen, t - 1 - seen[::-1].argmax(axis=0), -1)
        beyond = (~seen) & ((frames < first) | (frames > last)) & any_seen
        inside = (~seen) & ~beyond & any_seen
        row = {"run": run, "data": os.path.basename(config["data"]),
               "inside": int(inside.sum()), "beyond": int(beyond.sum()), "epe_x1e4": {}}
        for m, (tracks, _, _) in filled.items():
            err = np.abs(tracks - truth).sum(axis=2) / scale * 1e4
            row["epe_x1e4"][m] = {
                "inside": float(np.nanmean(err[inside])),
                "beyond": float(np.nanmean(err[beyond])),
                "unfilled": int(np.isnan(err[inside | beyond]).sum()),
            }
        rows.append(row)
    print("| file | inside entries | beyond entries | " + " | ".join(
        f"{m} inside / beyond" for m in methods) + " |")
    print("|---" * (3 + len(methods)) + "|")
    for r in rows:
        cells = [f"{r['epe_x1e4'][m]['inside']:.1f} / {r['epe_x1e4'][m]['beyond']:.1f}"
                 for m in methods]
        print(f"| {r['data']} | {r['inside']} | {r['beyond']} | " + " | ".join(cells) + " |")
    if args.json:
        json.dump(rows, open(args.json, "w"), indent=2)


if __name__ == "__main__":
    main()
