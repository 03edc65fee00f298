"""Gap filling at the native rate, on the protocol of the gap-filling literature
(docs/gap-filling.md, "At the native rate").

Each recording is read whole from its C3D, at its own rate. For 1 and for 3 markers at once
and each gap length (0.1, 0.25, 0.5, 1 and 2 s), DRAWS events are drawn: a start frame and
the markers (the same start for all of them), such that the markers are seen from the frame
before the gap to the frame after it (so every hidden entry has its truth, and the gap has
observations on both sides). The events of one marker count are drawn into as few draw
sets as they fit (a marker's events in one set at least 0.5 s apart, at most 20 % of the
entries hidden), and each set is fitted once, at `doma fit`'s defaults. Every method fills
the same set's mask: doma's fill (`Field.complete()`), the field's fill alone, and the
classic fillers (`doma.fill`): spline, linear, pattern and rigid-body fill (Vicon Nexus's),
relational fill (Qualisys's), the Kalman smoother (Burke & Lasenby, as pyCGM2 runs it), Gløersen & Federolf's PCA fill
(strategy R2), iterative PCA, and doma's segment and chain fills (the rigid-body fill with
its donors judged on the track's own observations around the gap, and with its donors
handed over where they are lost; not named fillers). The error of an
event is the mean Euclidean distance over its hidden entries, in the file's units (mm);
a case's figure is the mean over its events. With `--imputer` (scikit-learn installed), its
IterativeImputer (frames as samples, coordinates as features: a spatial-only imputer) is one
more reference column. The summary below the table gives the cases met, the worst ratio and
the geometric mean against the best named filler; doma's fill (with a fit) beside the
fit-free chain fill (`doma fill --no-fit`) and the field's fill alone on gaps of 1 s and
longer; and the worst of doma's fill over the best of its own parts measured here.

    python scripts/native_rate_gaps.py MOCAP_DIR [--draws 20] [--recordings A,B] [--out DIR]
        [--add FILLER,...] [--fit-option KEY=VALUE] [--no-blind-validation] [--fits DIR]

Needs the doma wheel (scripts/build_wheel.sh), numpy and `c3d` (for the rate). Writes one
JSON per recording to --out (default results/native) and prints the table. A recording
whose JSON exists is not run again; `--add` fills its draw sets (the same, drawn from the
same seed) with the fillers named and adds their columns, without fitting.
`--fit-option KEY=VALUE` passes a `doma.fit` option over the defaults (`time_scale=1`;
`seed=1` refits with another seed on the same events). `--no-blind-validation` fits with
`blind_validation=False` (every observation fitted, the field's fills left out of doma's
blend). `--fits DIR` keeps each fitted run there and loads it on the next run
instead of fitting: the blend's weights are learned by `complete()`, so a change to the
blend or a filler reruns without a fit.
"""

import argparse
import json
import pathlib
import sys
import time

import numpy as np

import doma

LENGTHS = [0.1, 0.25, 0.5, 1.0, 2.0]
COUNTS = [1, 3]
METHODS = ["spline", "linear", "pattern", "rigid_body", "relational", "kalman", "gloersen", "iterative_pca", "segment",
           "chain"]
# "segment" and "chain" are doma's own: the rigid-body fill with its donors judged around
# the gap, and with its donors handed over where they are lost.
# The named fillers of the literature, and those that give the linear fill where they cannot
# run (Kalman: no two frames see every marker; Gløersen: every marker has a gap).
NAMED = ["spline", "pattern", "rigid_body", "relational", "kalman", "gloersen"]
# The spatial-only imputer users reach for first: scikit-learn's IterativeImputer on the
# frames as samples and the coordinates as features (no time). A reference column, where
# scikit-learn is installed.
IMPUTER = "iterative_imputer"
# The field's fills beside the donors' (`field_chain`, `field_segment`): each alone, as
# `field_fill` is, where the wheel has them.
FIELD_DESIGNS = ["field_chain", "field_segment"]
FALLS_BACK = ["kalman", "gloersen"]
RECORDINGS = ["85_12", "Qualisys", "right_knee", "codamotion_gaitwands_20150204", "Walking_Hybrid_1_5"]
MARGIN_S = 0.5
MAX_HIDDEN = 0.2


def rate_of(path):
    """The frame rate in `path`'s header: read by the `c3d` package, or where it refuses the
    file (it refuses a group's parameter named twice, as Vicon Nexus writes them), from the
    header's own float of an Intel file."""
    import c3d

    with open(path, "rb") as f:
        try:
            return float(c3d.Reader(f).header.frame_rate)
        except (KeyError, ValueError):
            f.seek(0)
            head = f.read(512)
            f.seek(512 * (head[0] - 1) + 3)
            if f.read(1) != bytes([84]):
                raise
            return float(np.frombuffer(head[20:24], "<f4")[0])


def draw_sets(observed, rate, count, draws, rng):
    """Draw sets, each a list of events (length_s, start, gap_frames, markers): DRAWS events
    per gap length, drawn into a set while one fits (its markers seen from the frame before
    the gap to the frame after it, and not hidden by the set within MARGIN_S of it; the
    set hiding at most MAX_HIDDEN of the entries), else into a new set."""
    t, n = observed.shape
    margin = int(round(MARGIN_S * rate))
    # A gap needs a seen frame on each side: lengths the recording cannot hold are left out.
    left = {length: draws if max(1, round(length * rate)) + 2 <= t else 0 for length in LENGTHS}
    sets = []
    while any(left.values()):
        busy = np.zeros((t, n), bool)
        hidden, events = 0, []
        for length in sorted(LENGTHS, reverse=True):
            g = max(1, int(round(length * rate)))
            while left[length] > 0:
                placed = False
                for _ in range(500):
                    s = int(rng.integers(1, t - g))
                    window = slice(max(0, s - 1 - margin), min(t, s + g + 1 + margin))
                    free = observed[s - 1 : s + g + 1].all(axis=0) & ~busy[window].any(axis=0)
                    candidates = np.flatnonzero(free)
                    if len(candidates) < count or hidden + g * count > MAX_HIDDEN * observed.sum():
                        continue
                    markers = sorted(rng.choice(candidates, size=count, replace=False).tolist())
                    busy[window, markers] = True
                    hidden += g * count
                    events.append((length, s, g, markers))
                    left[length] -= 1
                    placed = True
                    break
                if not placed:
                    break
        if not events:
            raise SystemExit(f"no event of {[l for l, k in left.items() if k]} s fits the recording")
        sets.append(events)
    return sets


def event_errors(filled, truth, event):
    _, s, g, markers = event
    d = np.linalg.norm(filled[s : s + g][:, markers].astype(np.float64) - truth[s : s + g][:, markers], axis=2)
    return float(d.mean())


def masks(observed, rate, draws, seed):
    """(count, events, mask) of every draw set, in the order a run fits them."""
    rng = np.random.default_rng(seed)
    for count in COUNTS:
        for events_of_set in draw_sets(observed, rate, count, draws, rng):
            mask = observed.copy()
            for _, s, g, markers in events_of_set:
                mask[s : s + g, markers] = False
            yield count, events_of_set, mask


def add_fillers(path, report, methods, draws, seed):
    """Adds `methods`' columns to `report` (a run of `path`), on its draw sets."""
    seq = doma.read_tracks(path)
    tracks, observed = seq.tracks, seq.observed
    truth = tracks.astype(np.float64)
    errors = {}
    for set_index, (count, events_of_set, mask) in enumerate(masks(observed, report["rate"], draws, seed)):
        fit = report["fits"][set_index]
        assert (fit["markers_at_once"], fit["events"]) == (count, len(events_of_set)), "not the report's draws"
        for m in methods:
            started = time.time()
            filled = iterative_imputer(tracks, mask) if m == IMPUTER else doma.fill(tracks, mask, m)
            if filled is None:
                raise SystemExit("--add iterative_imputer: scikit-learn is not installed")
            fit["filler_s"][m] = round(time.time() - started, 2)
            for e in events_of_set:
                errors.setdefault(f"{count}x{e[0]}", {}).setdefault(m, []).append(event_errors(filled, truth, e))
        print(f"  {path.stem}: set {set_index + 1} of {len(report['fits'])}", file=sys.stderr, flush=True)
    for key, per in errors.items():
        for m, v in per.items():
            report["cases"][key][m] = float(np.mean(v))
    return report


def run_recording(path, draws, seed, blind=True, fits=None, fit_options=None, imputer=False):
    seq = doma.read_tracks(path)
    tracks, observed = seq.tracks, seq.observed
    truth = tracks.astype(np.float64)
    rate = rate_of(path)
    out = {"recording": path.stem, "rate": rate, "frames": int(tracks.shape[0]), "markers": int(tracks.shape[1]),
           "cases": {}, "fits": []}
    errors = {}
    for set_index, (count, events_of_set, mask) in enumerate(masks(observed, rate, draws, seed)):
        saved = None if fits is None else fits / path.stem / f"set{set_index}"
        started = time.time()
        loaded = saved is not None and saved.exists()
        if loaded:
            field = doma.load(saved)
        else:
            options = dict(drop_unobserved=True, seed=seed, progress=False, blind_validation=blind)
            field = doma.fit(tracks, mask, **{**options, **(fit_options or {})})
            if saved is not None:
                field.save(saved)
        fit_s = time.time() - started
        started = time.time()
        done = field.complete()
        fills = {"doma": done.tracks}
        complete_s = time.time() - started
        fills["field_fill"] = field.complete(method="field_fill").tracks
        for design in FIELD_DESIGNS:
            try:
                fills[design] = in_input_order(field.complete(method=design).tracks, done.kept, tracks.shape)
            except ValueError:
                pass  # a wheel without that design
        filler_s = {}
        for m in METHODS:
            started = time.time()
            fills[m] = doma.fill(tracks, mask, m)
            filler_s[m] = time.time() - started
        if imputer:
            imputed = iterative_imputer(tracks, mask)
            if imputed is not None:
                fills[IMPUTER] = imputed
        fills["field_fill"] = in_input_order(fills["field_fill"], done.kept, tracks.shape)
        fills["doma"] = in_input_order(fills["doma"], done.kept, tracks.shape)
        for e in events_of_set:
            key = f"{count}x{e[0]}"
            for name, f in fills.items():
                errors.setdefault(key, {}).setdefault(name, []).append(event_errors(f, truth, e))
        out["fits"].append({"markers_at_once": count, "events": len(events_of_set), "hidden": int((~mask & observed).sum()),
                            "fit_s": None if loaded else round(fit_s, 1), "complete_s": round(complete_s, 1),
                            "filler_s": {k: round(v, 2) for k, v in filler_s.items()}})
        print(f"  {path.stem}: {count} at once, {len(events_of_set)} events, {'loaded' if loaded else f'fit {fit_s:.0f} s'}, complete {complete_s:.0f} s",
              file=sys.stderr, flush=True)
    for key, per in errors.items():
        out["cases"][key] = {name: float(np.mean(v)) for name, v in per.items()}
        out["cases"][key]["events"] = len(per["doma"])
    return out


def iterative_imputer(tracks, mask):
    """scikit-learn's IterativeImputer of `tracks` [T, N, 3] where `mask` hides them (its
    defaults: BayesianRidge, 10 rounds, seed 0), or None without scikit-learn. Markers never
    seen under the mask are left out of its matrix and come back NaN."""
    try:
        from sklearn.experimental import enable_iterative_imputer  # noqa: F401
        from sklearn.impute import IterativeImputer
    except ImportError:
        return None
    t, n, _ = tracks.shape
    seen = mask.any(axis=0)
    x = tracks[:, seen].astype(np.float64).copy()
    x[~mask[:, seen]] = np.nan
    filled = IterativeImputer(random_state=0).fit_transform(x.reshape(t, -1)).reshape(t, -1, 3)
    out = np.full(tracks.shape, np.nan, np.float32)
    out[:, seen] = filled
    return out


def in_input_order(filled, kept, shape):
    """A fit's fill [T, N', 3] in the input's track order [T, N, 3]: a fit drops the
    tracks never seen (`kept`: the input's index of each track it kept; None: none
    dropped), which come back NaN."""
    if kept is None:
        return filled
    full = np.full(shape, np.nan, np.float32)
    full[:, kept] = filled
    return full


def runs(case, method):
    """Whether `method` ran: where it cannot (FALLS_BACK), doma.fill gives the linear
    fill, the same numbers to the last bit."""
    return method not in FALLS_BACK or case[method] != case["linear"]


def table(results):
    extra = [IMPUTER] if all(IMPUTER in c for r in results for c in r["cases"].values()) else []
    designs = [d for d in FIELD_DESIGNS if all(d in c for r in results for c in r["cases"].values())]
    cols = ["doma", "field_fill"] + designs + [m for m in METHODS + extra
                                               if all(m in c for r in results for c in r["cases"].values())]
    lines = ["| recording | rate | at once | gap | " + " | ".join(cols) + " | doma / best named |",
             "|---" * (5 + len(cols)) + "|"]
    named = [m for m in NAMED if m in cols]
    for r in results:
        order = sorted(r["cases"], key=lambda k: (int(k.split("x")[0]), float(k.split("x")[1])))
        for key in order:
            case = r["cases"][key]
            count, length = key.split("x")
            cells = []
            for c in cols:
                v = case[c]
                cells.append("–" if not runs(case, c) else (f"{v:.1f}" if v >= 10 else f"{v:.2f}"))
            best = min(case[c] for c in named if runs(case, c))
            lines.append(f"| `{r['recording']}` | {r['rate']:.0f} Hz | {count} | {length} s | " + " | ".join(cells)
                         + f" | {case['doma'] / best:.2f} |")
    return "\n".join(lines)


def summary(results):
    """The acceptance (below the best named filler at 0.5 s and beyond, within 5 % below),
    the ratios' worst and geometric mean; with a fit against fit-free on gaps of 1 s and
    longer; and doma's fill over the best of its parts measured here."""
    ratios, met, long_fit, long_field, parts, free = [], 0, [], [], [], []
    part_cols = ["field_fill"] + FIELD_DESIGNS + METHODS
    named_all = [m for m in NAMED]
    for r in results:
        for key, case in r["cases"].items():
            length = float(key.split("x")[1])
            named = [c for c in named_all if c in case and runs(case, c)]
            ratio = case["doma"] / min(case[c] for c in named)
            ratios.append(ratio)
            free.append(case["chain"] / min(case[c] for c in named))
            met += ratio < 1.0 if length >= 0.5 else ratio <= 1.05
            if length >= 1.0:
                long_fit.append(case["doma"] / case["chain"])
                long_field.append({d: case[d] / case["chain"] for d in ["field_fill"] + FIELD_DESIGNS if d in case})
            best_part = min((case[c], c) for c in part_cols if c in case)
            parts.append((case["doma"] / best_part[0], r["recording"], key, best_part[1]))
    geo = lambda v: float(np.exp(np.mean(np.log(v)))) if v else float("nan")
    worst_part = max(parts)
    return "\n".join([
        f"met {met} of {len(ratios)}, below the best named filler in {sum(r < 1 for r in ratios)}, "
        f"{geo(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f}) in geometric mean (range)",
        f"fit-free (the chain fill): below the best named filler in {sum(r < 1 for r in free)}, "
        f"{geo(free):.2f} ({min(free):.2f}-{max(free):.2f})",
        f"gaps of 1 s and longer, {len(long_fit)} cases: with a fit / fit-free (chain) geometric mean {geo(long_fit):.3f}, "
        f"range {min(long_fit):.2f}-{max(long_fit):.2f}; alone / fit-free: "
        + ", ".join(f"{d} {geo([c[d] for c in long_field if d in c]):.2f}"
                    for d in ["field_fill"] + FIELD_DESIGNS if all(d in c for c in long_field)),
        f"doma / best of its parts measured: worst {worst_part[0]:.2f} ({worst_part[1]} {worst_part[2]}, {worst_part[3]}), "
        f"geometric mean {geo([p[0] for p in parts]):.2f}, above 1.05 in {sum(p[0] > 1.05 for p in parts)} cases",
    ])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mocap_dir", type=pathlib.Path)
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--recordings", default=",".join(RECORDINGS))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=pathlib.Path, default=pathlib.Path("results/native"))
    p.add_argument("--add", default="", help="fillers to add to existing reports, comma-separated")
    p.add_argument("--fits", type=pathlib.Path,
                   help="keep each fitted run here, and load it instead of fitting where it is already there "
                        "(the blend's weights are learned by complete(), so a change to the blend reruns in minutes)")
    p.add_argument("--imputer", action="store_true",
                   help="add scikit-learn's IterativeImputer as a reference column (minutes a draw set on a long "
                        "recording; or later, --add iterative_imputer)")
    p.add_argument("--no-blind-validation", dest="blind_validation", action="store_false",
                   help="fit with blind_validation=False: every observation fitted, the field's fills left out of the blend")
    p.add_argument("--fit-option", action="append", default=[], metavar="KEY=VALUE",
                   help="a doma.fit option over the defaults, VALUE read as JSON (time_scale=1, seed=1); repeatable")
    args = p.parse_args()
    fit_options = {}
    for option in args.fit_option:
        key, _, value = option.partition("=")
        fit_options[key] = json.loads(value)
    added = [m for m in args.add.split(",") if m]
    for m in added:
        if m not in METHODS + [IMPUTER]:
            raise SystemExit(f"--add {m}: not one of {', '.join(METHODS + [IMPUTER])}")
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for name in args.recordings.split(","):
        path = args.mocap_dir / f"{name}.c3d"
        report = args.out / f"{name}.json"
        if report.exists():
            r = json.loads(report.read_text())
            if added:
                r = add_fillers(path, r, added, args.draws, args.seed)
                report.write_text(json.dumps(r, indent=1))
            results.append(r)
            continue
        r = run_recording(path, args.draws, args.seed, args.blind_validation, args.fits, fit_options, args.imputer)
        r["blind_validation"] = args.blind_validation
        r["fit_options"] = fit_options
        report.write_text(json.dumps(r, indent=1))
        results.append(r)
    print(table(results))
    print()
    print(summary(results))


if __name__ == "__main__":
    main()
