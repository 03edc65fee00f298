"""The throughput of `doma fill` on a lab's folder (docs/speed.md, "A folder of trials"):
TRIALS one-minute C3D trials of 60 markers (alternately at 100 and 200 Hz, floats, with
38 analog channels), each with 0.5 s gaps hidden in 3 markers at once at the density of
scripts/native_rate_timing.py, filled with `--jobs JOBS`, without a fit and with one.
Prints the wall time of each run and the trials per minute.

The trials are built as native_rate_timing.py builds its minute: right_knee.c3d's first
60 markers played forward and backward up to a minute, each trial from another start.

    python scripts/fill_folder_bench.py [DOMA_BINARY] [--trials 20] [--jobs 2]
        [--fit-trials K]

`--fit-trials K` times the fit on the first K trials only (a fit is about a minute a
trial on 2 cores); needs numpy and the `c3d` package.
"""

import argparse
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import native_rate_timing as timing  # noqa: E402


def build(folder, trials):
    tracks, observed = timing.source_tracks()
    rng = np.random.default_rng(0)
    for k in range(trials):
        rate = 100.0 if k % 2 == 0 else 200.0
        frames = int(60 * rate)
        shift = int(rng.integers(0, len(tracks)))
        order = np.roll(np.arange(len(tracks)), -shift)
        t = timing.ping_pong(tracks[order], frames)
        o = timing.ping_pong(observed[order], frames)
        timing.RATE = rate
        mask, _ = timing.hide(o, 240 * frames // 12_000, np.random.default_rng(k))
        timing.write_c3d(folder / f"trial{k:02d}.c3d", t, mask)


def run(doma, args):
    start = time.perf_counter()
    done = subprocess.run([doma, "fill", *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(done.stderr)
    return time.perf_counter() - start


def main():
    p = argparse.ArgumentParser()
    p.add_argument("doma", nargs="?", default=pathlib.Path(os.environ.get("CARGO_TARGET_DIR", "target")) / "release" / "doma")
    p.add_argument("--trials", type=int, default=20)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--fit-trials", type=int, default=None)
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as work:
        work = pathlib.Path(work)
        folder = work / "trials"
        folder.mkdir()
        build(folder, a.trials)
        seconds = run(a.doma, [folder, "--out", work / "nofit", "--no-fit", "--jobs", str(a.jobs), "--quiet"])
        print(f"--no-fit: {a.trials} trials in {seconds:.1f} s, {60 * a.trials / seconds:.1f} trials per minute")
        k = a.fit_trials or a.trials
        subset = work / "subset"
        subset.mkdir()
        for f in sorted(folder.glob("*.c3d"))[:k]:
            (subset / f.name).symlink_to(f)
        seconds = run(a.doma, [subset, "--out", work / "fit", "--fit", "--jobs", str(a.jobs), "--quiet"])
        print(f"with a fit: {k} trials in {seconds:.1f} s, {60 * k / seconds:.2f} trials per minute")


if __name__ == "__main__":
    main()
