"""doma's fill averaged over several fits, on the native-rate protocol
(docs/gap-filling.md, "At the native rate").

Each FITS folder holds the runs that `native_rate_gaps.py --fits FITS` kept for the same
draw sets (the same events, drawn with the same --seed and --draws), fitted with different
options, e.g. another fit seed (`--fit-option seed=1`). For every draw set, doma's fill
(`Field.complete()`) of each run is scored on the set's events, the fits' events pooled
("pooled": the mean of their errors), and their fills' mean and median, entry by entry
("mean", "median"; the median of two fills is their mean). REPORTS is a `native_rate_gaps.py --out` folder of those draw sets: its
named fillers' columns (spline, pattern, rigid body, Kalman, Gløersen) give the best named
filler each fill is set against. Prints, for each fit and for each combination, the acceptance
(below the best named filler at 0.5 s and beyond, within 5 % at shorter gaps), the worst
and the geometric mean of doma / best named.

    python scripts/native_rate_ensemble.py MOCAP_DIR REPORTS FITS FITS [FITS ...]
        [--draws 20] [--seed 0] [--recordings A,B]

Needs the doma wheel, numpy and `c3d`, as native_rate_gaps.py does.
"""

import argparse
import itertools
import json
import math
import pathlib

import numpy as np

import doma
import native_rate_gaps as nr


def fills_of(fits, name, set_index, shape):
    """doma's fill of draw set `set_index` by the run kept in each of `fits`, as [T, N, 3]
    float64 in the input's track order (NaN where a fit dropped a never-seen track)."""
    out = []
    for base in fits:
        done = doma.load(base / name / f"set{set_index}").complete()
        out.append(nr.in_input_order(done.tracks, done.kept, shape).astype(np.float64))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mocap_dir", type=pathlib.Path)
    p.add_argument("reports", type=pathlib.Path)
    p.add_argument("fits", type=pathlib.Path, nargs="+")
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--recordings", default=",".join(nr.RECORDINGS))
    args = p.parse_args()
    if len(args.fits) < 2:
        raise SystemExit("give two FITS folders or more")
    fitted = [f"fit {k}" for k in range(len(args.fits))]
    # "pooled": every fit's events in one case (the mean of the fits' errors), "mean" and
    # "median": the fits' fills combined entry by entry, then scored.
    # With three fits or more, each pair's mean too: what two fits would have given.
    pairs = list(itertools.combinations(range(len(args.fits)), 2)) if len(args.fits) > 2 else []
    paired = [f"mean {a}+{b}" for a, b in pairs]
    names = fitted + ["pooled", "mean", "median"] + paired
    ratios = {n: [] for n in names}
    met = {n: 0 for n in names}
    for name in args.recordings.split(","):
        path = args.mocap_dir / f"{name}.c3d"
        cases = json.loads((args.reports / f"{name}.json").read_text())["cases"]
        seq = doma.read_tracks(path)
        tracks, observed = seq.tracks, seq.observed
        truth = tracks.astype(np.float64)
        errors = {}
        for set_index, (count, events, _) in enumerate(nr.masks(observed, nr.rate_of(path), args.draws, args.seed)):
            fills = fills_of(args.fits, name, set_index, tracks.shape)
            stacked = np.stack(fills)
            fills += [stacked.mean(axis=0), np.median(stacked, axis=0)]
            fills += [(stacked[a] + stacked[b]) / 2 for a, b in pairs]
            del stacked
            for e in events:
                per = errors.setdefault(f"{count}x{e[0]}", {n: [] for n in names})
                for n, f in zip(fitted + ["mean", "median"] + paired, fills):
                    per[n].append(nr.event_errors(f, truth, e))
                per["pooled"].extend(per[n][-1] for n in fitted)
        for key, per in sorted(errors.items()):
            case = cases[key]
            best = min(case[m] for m in nr.NAMED if nr.runs(case, m))
            long_gap = float(key.split("x")[1]) >= 0.5
            cells = []
            for n in names:
                q = float(np.mean(per[n])) / best
                ratios[n].append(q)
                met[n] += q < 1 if long_gap else q <= 1.05
                cells.append(f"{n} {q:.2f}")
            print(f"{name} {key}: " + ", ".join(cells))
    for n in names:
        r = ratios[n]
        mean = math.exp(sum(map(math.log, r)) / len(r))
        print(f"{n}: met {met[n]} of {len(r)}, worst {max(r):.2f}, geometric mean {mean:.3f}")


if __name__ == "__main__":
    main()
