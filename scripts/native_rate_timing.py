"""The cost of a lab's trial (docs/speed.md, "A minute at 200 Hz"): `doma fit` plus
`doma complete` of a 60 s, 200 Hz recording of 60 markers (12,000 frames), with the peak
memory of each, and the fill of the same gaps beside a 5 s excerpt's.

The recording is built from a real one (right_knee.c3d, shipped in data/mocap/): its first
60 markers played forward, backward, forward... (so the motion stays continuous) up to
12,000 frames, and given a rate of 200 Hz. 3 markers at once are hidden for 0.5 s, 20 times
in the excerpt (its first 1,000 frames) and 240 times in the whole (the same density).
Recordings of two and four minutes built the same way (24,000 and 48,000 frames, 480 and
960 gaps) show how the peaks grow with the frame count: the last line gives each peak's
growth from one minute to four against the tracks' own.

With --c3d each recording is a C3D file instead (floats, with 38 analog channels sampled
10 times a frame, a force plate's 2,000 Hz), fitted from the .c3d and completed to a .c3d,
as a lab's trial is. With --unseen no frame sees every marker (marker 0 is hidden for the
first half, marker 1 for the second), as in many real captures: the fit then learns the
canonical positions of the markers that its reference frame misses.

With --subjects K the recording holds K people side by side, 3 m apart, each the same 60
markers from another moment of the source (60·K markers, the events K times as many), as a
capture of several people or of a dense marker set is: what `doma complete` costs against
the marker count.

With --method FILLER `doma complete` fills with that filler alone (`field_fill`, `segment`,
`kalman`, ...) instead of doma's fill, --fits K fits K fields (`doma fit --fits K`; default
doma fit's, one), and --only picks some of the four recordings (`--only 5s,60s`).

    python scripts/native_rate_timing.py [DOMA_BINARY] [--c3d] [--unseen] [--method FILLER] [--fits K]
        [--subjects K] [--only 5s,60s,120s,240s]

Needs numpy and the doma binary (default $CARGO_TARGET_DIR/release/doma); /usr/bin/time
for the peak memory; the `c3d` package for --c3d.
"""

import argparse
import os
import pathlib
import re
import subprocess
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
RATE = 200.0
FRAMES = 12_000
MARKERS = 60
GAP_S = 0.5
ANALOG_CHANNELS = 38
ANALOG_PER_FRAME = 10
SUBJECT_OFFSET = 307  # frames: another moment of the motion for each subject
SUBJECT_SPACING_MM = 3000.0


def source_tracks():
    """right_knee's tracks (mm) and mask: with the doma wheel's reader where it is
    installed, else with the `c3d` package."""
    path = ROOT / "data" / "mocap" / "right_knee.c3d"
    try:
        import doma as py

        seq = py.read_tracks(path)
        return seq.tracks, seq.observed
    except ImportError:
        import c3d

        with open(path, "rb") as f:
            frames = [points for _, points, _ in c3d.Reader(f).read_frames()]
        p = np.stack(frames)
        return p[:, :, :3].astype(np.float32), p[:, :, 3] >= 0


def ping_pong(tracks, frames):
    t = len(tracks)
    order = []
    forward = True
    while len(order) < frames:
        order.extend(range(t) if forward else range(t - 2, 0, -1))
        forward = not forward
    return tracks[np.array(order[:frames])]


def hide(observed, events, rng):
    g = int(GAP_S * RATE)
    mask = observed.copy()
    busy = np.zeros_like(observed)
    hidden = []
    t, n = observed.shape
    while len(hidden) < events:
        s = int(rng.integers(1, t - g))
        seen = observed[s - 1 : s + g + 1].all(axis=0) & ~busy[max(0, s - g - 1) : s + 2 * g + 1].any(axis=0)
        candidates = np.flatnonzero(seen)
        if len(candidates) < 3:
            continue
        markers = sorted(rng.choice(candidates, 3, replace=False).tolist())
        mask[s : s + g, markers] = False
        busy[s : s + g, markers] = True
        hidden.append((s, g, markers))
    return mask, hidden


def timed(cmd):
    """Seconds and peak resident MB of `cmd`."""
    started = time.time()
    done = subprocess.run(["/usr/bin/time", "-v", *cmd], capture_output=True, text=True)
    seconds = time.time() - started
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{done.stderr[-2000:]}")
    peak = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", done.stderr).group(1)) / 1024
    return seconds, peak


def write_c3d(path, tracks, mask):
    """`tracks` where `mask` holds as a float C3D at RATE, an unobserved point written as
    not measured, with ANALOG_CHANNELS smooth analog channels."""
    import c3d

    t, n, _ = tracks.shape
    w = c3d.Writer(point_rate=RATE, analog_rate=RATE * ANALOG_PER_FRAME, point_scale=-1.0)
    w.set_point_labels([f"M{i:02d}" for i in range(n)])
    w.set_analog_labels([f"A{i:02d}" for i in range(ANALOG_CHANNELS)])
    phase = np.arange(ANALOG_CHANNELS)[:, None] * 0.1
    frames = []
    for k in range(t):
        points = np.zeros((n, 5), np.float32)
        points[:, :3] = np.where(mask[k][:, None], tracks[k], 0.0)
        points[:, 3] = np.where(mask[k], 1.0, -1.0)
        s = (k * ANALOG_PER_FRAME + np.arange(ANALOG_PER_FRAME))[None, :] / (RATE * ANALOG_PER_FRAME)
        frames.append((points, (100 * np.sin(2 * np.pi * 3 * s + phase)).astype(np.float32)))
    w.add_frames(frames)
    with open(path, "wb") as f:
        w.write(f)


def read_c3d(path):
    import c3d

    with open(path, "rb") as f:
        return np.stack([p[:, :3] for _, p, _ in c3d.Reader(f).read_frames()]).astype(np.float64)


def case(doma, work, name, tracks, observed, events, seed, as_c3d, unseen, method=None, fits=None):
    if unseen:
        # No frame sees every marker, as in many real captures: the fit learns the
        # canonical positions of the markers its reference frame misses (before the
        # events are drawn, so that they fall where the markers are seen).
        observed = observed.copy()
        half = len(observed) // 2
        observed[:half, 0] = False
        observed[half:, 1] = False
    mask, hidden = hide(observed, events, np.random.default_rng(seed))
    ext = "c3d" if as_c3d else "npz"
    data = work / f"{name}.{ext}"
    if as_c3d:
        write_c3d(data, tracks, mask)
    else:
        np.savez(data, tracks=np.where(mask[..., None], tracks, np.nan).astype(np.float32), observed=mask)
    run = work / f"{name}-run"
    fits_args = ["--fits", str(fits)] if fits else []
    fit_s, fit_mb = timed([doma, "fit", str(data), "--out", str(run), "--quiet", "--seed", str(seed), *fits_args])
    out = work / f"{name}-filled.{ext}"
    method_args = ["--method", method] if method else []
    complete_s, complete_mb = timed([doma, "complete", str(run), "--out", str(out), *method_args])
    filled = read_c3d(out) if as_c3d else np.load(out)["tracks"].astype(np.float64)
    errors = [np.linalg.norm(filled[s : s + g][:, m] - tracks[s : s + g][:, m], axis=2).mean() for s, g, m in hidden]
    return {
        "frames": len(tracks), "fit_s": fit_s, "fit_mb": fit_mb, "complete_s": complete_s,
        "complete_mb": complete_mb, "events": len(hidden), "error_mm": float(np.mean(errors)),
        "data_mb": tracks.size * 4 / 2**20,  # as the .npz holds them: float32
        "file_mb": data.stat().st_size / 2**20,
    }


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    target = os.environ.get("CARGO_TARGET_DIR", str(ROOT / "target"))
    p.add_argument("doma", nargs="?", default=f"{target}/release/doma")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--c3d", action="store_true", help="C3D recordings with analog channels")
    p.add_argument("--unseen", action="store_true",
                   help="marker 0 hidden for the first half and marker 1 for the second, so that no frame sees every marker")
    p.add_argument("--method", help="fill with this filler alone (doma complete --method)")
    p.add_argument("--fits", type=int, help="doma fit --fits K (default: doma fit's, 1)")
    p.add_argument("--subjects", type=int, default=1, help="K people side by side, 60 markers each")
    p.add_argument("--only", default="5s,60s,120s,240s", help="the recordings to run, of 5s,60s,120s,240s")
    args = p.parse_args()
    if args.subjects < 1:
        raise SystemExit(f"--subjects {args.subjects}: at least 1")
    only = set(args.only.split(","))
    if not only <= {"5s", "60s", "120s", "240s"}:
        raise SystemExit(f"--only {args.only}: not among 5s,60s,120s,240s")
    tracks, observed = source_tracks()
    tracks, observed = tracks[:, :MARKERS], observed[:, :MARKERS]
    # Subject s starts SUBJECT_OFFSET·s frames into the source's motion, SUBJECT_SPACING_MM·s
    # along y from the first.
    whole_t = np.concatenate(
        [ping_pong(tracks, 4 * FRAMES + s * SUBJECT_OFFSET)[s * SUBJECT_OFFSET :] + s * np.array([0.0, SUBJECT_SPACING_MM, 0.0])
         for s in range(args.subjects)], axis=1).astype(np.float64)
    whole_o = np.concatenate(
        [ping_pong(observed, 4 * FRAMES + s * SUBJECT_OFFSET)[s * SUBJECT_OFFSET :] for s in range(args.subjects)], axis=1)
    markers = MARKERS * args.subjects
    with tempfile.TemporaryDirectory() as tmp:
        work = pathlib.Path(tmp)
        at = lambda name, frames, events: case(
            args.doma, work, name, whole_t[:frames], whole_o[:frames], events, args.seed, args.c3d, args.unseen,
            args.method, args.fits,
        )
        plan = [
            ("5s", "5 s excerpt", "excerpt", 1000, 20),
            ("60s", "60 s", "whole", FRAMES, 240),
            ("120s", "120 s", "double", 2 * FRAMES, 480),
            ("240s", "240 s", "quad", 4 * FRAMES, 960),
        ]
        rows = [(label, at(name, frames, events * args.subjects)) for key, label, name, frames, events in plan if key in only]
    print("| recording | frames × markers | fit (s) | fit peak (MB) | complete (s) | complete peak (MB) | data (MB) | file (MB) | 0.5 s gaps, 3 markers | error (mm) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, r in rows:
        print(f"| {name} | {r['frames']} × {markers} | {r['fit_s']:.0f} | {r['fit_mb']:.0f} | {r['complete_s']:.0f} | "
              f"{r['complete_mb']:.0f} | {r['data_mb']:.1f} | {r['file_mb']:.1f} | {r['events']} | {r['error_mm']:.2f} |")
    ran = dict(rows)
    if "60 s" in ran and "240 s" in ran:
        one, four = ran["60 s"], ran["240 s"]
        data = four["data_mb"] - one["data_mb"]
        print(f"\nfrom 60 s to 240 s, per MB more tracks: fit peak +{(four['fit_mb'] - one['fit_mb']) / data:.1f} MB, "
              f"complete peak +{(four['complete_mb'] - one['complete_mb']) / data:.1f} MB")


if __name__ == "__main__":
    main()
