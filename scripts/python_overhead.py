"""The Python package's overhead over `doma fit`: the same fit, alternated, in one run.

    python scripts/python_overhead.py [--iters 200] [--rounds 3] [--frames 20]

Fits the first frames of data/cdp_male_wave.traj (written once as a .npy for the CLI) with
`doma fit` (the binary under $CARGO_TARGET_DIR/release) and with `doma.fit` from NumPy,
alternating, and prints each side's median wall time (process start, data, fit, report)
and fit-loop time per iteration (`report.json`'s seconds), and their ratios.
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import doma

ROOT = pathlib.Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--iters", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--frames", type=int, default=20)
    args = parser.parse_args()
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    cli = target / "release" / "doma"
    if not cli.is_file():
        sys.exit(f"no doma binary at {cli}: cargo build --release")
    clip = np.ascontiguousarray(doma.read_tracks(ROOT / "data" / "cdp_male_wave.traj").tracks[: args.frames])
    times = {"cli": [], "python": []}
    per_iter = {"cli": [], "python": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        data = tmp / "clip.npy"
        np.save(data, clip)
        for r in range(args.rounds):
            for side in ("cli", "python"):
                out = tmp / f"{side}{r}"
                start = time.perf_counter()
                if side == "cli":
                    cmd = [cli, "fit", data, "--out", out, "--iters", str(args.iters), "--quiet"]
                    subprocess.run(cmd, check=True, capture_output=True)
                    report = json.loads((out / "report.json").read_text())
                else:
                    report = doma.fit(clip, iters=args.iters, progress=False, out=out).report
                times[side].append(time.perf_counter() - start)
                per_iter[side].append(report["seconds"] / report["iterations"])
                print(f"round {r} {side:6}: {times[side][-1]:.2f} s wall, EPE {report['epe_x1e4']:.2f}", flush=True)
    n, t = clip.shape[1], clip.shape[0]
    print(f"\n{n} tracks x {t} frames, {args.iters} iterations, {args.rounds} rounds alternated (medians):")
    for side in ("cli", "python"):
        print(f"  {side:6} wall {statistics.median(times[side]):.2f} s, fit loop {1e3 * statistics.median(per_iter[side]):.2f} ms/iteration")
    wall = statistics.median(times["python"]) / statistics.median(times["cli"])
    loop = statistics.median(per_iter["python"]) / statistics.median(per_iter["cli"])
    print(f"  python / cli: wall {wall:.3f}, fit loop per iteration {loop:.3f}")


if __name__ == "__main__":
    main()
