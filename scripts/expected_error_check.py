"""How well `doma fill`'s expected error per gap ranks the true errors (docs/gap-filling.md,
"Expected error per gap"), on the native-rate protocol's hidden gaps
(scripts/native_rate_gaps.py: its draw sets, the same seed).

For each recording and draw set, the set's mask is written as a masked .npz, filled by
`doma.fill_file` (fit-free by default, `--fit` for doma's fill after a fit), and each
hidden event's expected error (the table beside the output) is set against its true
error (the mean Euclidean distance from the truth over its entries). Prints, per recording
and over all: Spearman's rank correlation, and of the events whose true error passes the
threshold (default 5 mm), the share that were flagged, with the share of flagged events
that pass it.

    python scripts/expected_error_check.py MOCAP_DIR [--draws 20] [--recordings A,B]
        [--threshold 5] [--fit]
"""

import argparse
import csv
import pathlib
import sys
import tempfile

import numpy as np

import doma

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import native_rate_gaps as protocol  # noqa: E402


def spearman(a, b):
    """Spearman's rank correlation (average ranks for ties)."""
    def ranks(x):
        order = np.argsort(x, kind="stable")
        r = np.empty(len(x))
        r[order] = np.arange(len(x))
        for v in np.unique(x):
            same = x == v
            r[same] = r[same].mean()
        return r
    ra, rb = ranks(np.asarray(a)), ranks(np.asarray(b))
    return float(np.corrcoef(ra, rb)[0, 1])


def run(path, draws, seed, threshold, fit):
    seq = doma.read_tracks(path)
    truth = seq.tracks.astype(np.float64)
    rate = protocol.rate_of(path)
    pairs = []
    with tempfile.TemporaryDirectory() as work:
        work = pathlib.Path(work)
        for k, (count, events, mask) in enumerate(protocol.masks(seq.observed, rate, draws, seed)):
            data = work / f"set{k}.npz"
            np.savez(data, tracks=np.where(mask[..., None], seq.tracks, np.nan).astype(np.float32), observed=mask)
            out = work / f"set{k}_filled.npz"
            report = doma.fill_file(data, out, fit=fit, flag_above_mm=threshold)
            filled = np.load(out)["tracks"]
            by_gap = {(g["marker"], g["first_frame"]): g for g in report["gaps"]}
            for length, s, g, markers in events:
                for m in markers:
                    row = by_gap.get((f"track {m}", s))
                    if row is None or row["expected_error"] is None:
                        continue
                    true = float(np.linalg.norm(filled[s:s + g, m] - truth[s:s + g, m], axis=1).mean())
                    pairs.append((length, count, row["expected_error"], true, row["flagged"]))
    return pairs


def summary(name, pairs, threshold):
    if len(pairs) < 3:
        return f"{name}: {len(pairs)} events"
    expected = np.array([p[2] for p in pairs])
    true = np.array([p[3] for p in pairs])
    flagged = np.array([p[4] for p in pairs])
    above = true > threshold
    recall = flagged[above].mean() if above.any() else float("nan")
    precision = above[flagged].mean() if flagged.any() else float("nan")
    return (f"{name}: {len(pairs)} events, Spearman {spearman(expected, true):.2f}, "
            f"{above.sum()} above {threshold} mm of which {recall:.0%} flagged, "
            f"{flagged.sum()} flagged of which {precision:.0%} above")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("mocap", type=pathlib.Path)
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--recordings", default=",".join(protocol.RECORDINGS))
    p.add_argument("--threshold", type=float, default=5.0)
    p.add_argument("--fit", action="store_true")
    a = p.parse_args()
    everything = []
    for name in a.recordings.split(","):
        pairs = run(a.mocap / f"{name}.c3d", a.draws, a.seed, a.threshold, a.fit)
        everything += pairs
        print(summary(name, pairs, a.threshold), flush=True)
    print(summary("all", everything, a.threshold))
    for length in protocol.LENGTHS:
        print(summary(f"  {length} s", [q for q in everything if q[0] == length], a.threshold))


if __name__ == "__main__":
    main()
