"""What needs a process of its own: Ctrl-C during a fit, two processes fitting into one
folder, and the peak memory of a warp."""

import os
import pathlib
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np

import doma

CLIP = "doma.read_tracks({data!r}).tracks[112:132]"


def _default_sigint() -> None:
    """SIGINT back to its default in the child: a test run launched in the background of a
    shell inherits SIGINT ignored, and Python then installs no Ctrl-C handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def python(code: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(code), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_default_sigint,
    )


def test_ctrl_c_stops_a_fit_with_its_checkpoint_and_no_lock(tmp_path):
    from conftest import ROOT

    run = tmp_path / "run"
    child = python(
        f"""
        import sys, doma
        clip = {CLIP.format(data=str(ROOT / "data" / "md2_faerie.traj"))}
        try:
            doma.fit(clip, iters=400, checkpoint_every=1, progress=False, out=sys.argv[1])
            sys.exit("the fit ended before Ctrl-C came")
        except KeyboardInterrupt as e:
            print("\\n".join(getattr(e, "__notes__", [])))
        # The same process takes the run's lock again: the interrupted fit let it go.
        field = doma.resume(sys.argv[1], progress=False)
        print("iterations", field.report["iterations"])
        """,
        str(run),
    )
    deadline = time.monotonic() + 120
    while not (run / "resume.ckpt").is_file():
        assert child.poll() is None, child.communicate()
        assert time.monotonic() < deadline, "no checkpoint within two minutes"
        time.sleep(0.01)
    child.send_signal(signal.SIGINT)
    out, err = child.communicate(timeout=120)
    assert child.returncode == 0, (out, err)
    assert "its checkpoint is in" in out and "doma.resume" in out, out
    assert out.strip().endswith("iterations 400"), out


#: A child's reader of its own memory figures (VmRSS, VmHWM), in bytes.
STATUS = """
        import sys, numpy as np, doma
        def status(key):
            for line in open("/proc/self/status"):
                if line.startswith(key):
                    return int(line.split()[1]) * 1024
"""


def test_a_warp_of_two_million_points_holds_no_copy_of_them(tmp_path, fitted):
    measure = python(
        STATUS
        + """
        field = doma.load(sys.argv[1])
        x = (np.random.default_rng(0).normal(size=(2_000_000, 3)) * 10).astype(np.float32)
        field.warp(x[:20_000], 0)  # the first chunk's buffers and the thread pool
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")  # the peak starts again from here
        base = status("VmRSS:")
        y = field.warp(x, 3)
        print(status("VmHWM:") - base, y.nbytes, x.nbytes)
        """,
        fitted.run_dir,
    )
    out, err = measure.communicate(timeout=300)
    assert measure.returncode == 0, err
    growth, output, given = map(int, out.split())
    # The output, plus one chunk's activations (reused), and no copy of the input.
    assert growth < output + given // 2, (growth, output, given)


def test_refusing_a_call_larger_than_memory_costs_under_100_mb(fitted):
    measure = python(
        STATUS
        + """
        field = doma.load(sys.argv[1])
        point = np.zeros((1, 3), np.float32)
        field.warp(point, 0)  # the first call's buffers and the thread pool
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        base = status("VmRSS:")
        times = np.lib.stride_tricks.as_strided(np.zeros(1), (10**9,), (0,))
        huge = np.lib.stride_tricks.as_strided(np.zeros(3, np.float32), (10**11, 3), (0, 4))
        for call in (lambda: field.warp(point, times), lambda: field.jacobian(point, times),
                     lambda: field.warp(huge, 0), lambda: field.to_reference(huge, 3)):
            try:
                call()
                sys.exit("not refused")
            except doma.SizeError:
                pass
        print(status("VmHWM:") - base)
        """,
        fitted.run_dir,
    )
    out, err = measure.communicate(timeout=300)
    assert measure.returncode == 0, err
    assert int(out) < 100 * 2**20, out


def run_example(name, out):
    """Runs python/examples/NAME.py into `out` at 20 iterations without a display; its
    stdout, once it wrote NAME.png."""
    from conftest import ROOT

    env = {**os.environ, "MPLBACKEND": "Agg"}
    env.pop("DISPLAY", None)
    done = subprocess.run(
        [sys.executable, ROOT / "python" / "examples" / f"{name}.py", out, "--iters", "20"],
        env=env, capture_output=True, text=True,
    )
    assert done.returncode == 0, done.stderr
    assert (out / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return done.stdout


def test_the_example_fits_and_plots_without_a_display(tmp_path):
    assert "EPE" in run_example("fit_and_plot", tmp_path)


def test_the_gap_filling_example_runs_and_reports_millimetres(tmp_path):
    out = run_example("fill_gaps", tmp_path)
    assert "mm, linear" in out and "reference frame" in out, out


def test_two_processes_fitting_into_one_folder_one_refused_the_other_whole(tmp_path):
    from conftest import ROOT

    data = str(ROOT / "data" / "md2_faerie.traj")
    for attempt in range(3):
        out = tmp_path / f"race{attempt}"
        children = []
        for reverse in (False, True):
            children.append(
                python(
                    f"""
                    import sys, doma
                    clip = {CLIP.format(data=data)}
                    if sys.argv[2] == "1":
                        clip = clip[::-1].copy()
                    try:
                        doma.fit(clip, iters=15, progress=False, out=sys.argv[1])
                        print("fitted")
                    except OSError as e:
                        print("refused:", e)
                    """,
                    str(out),
                    "1" if reverse else "0",
                )
            )
            time.sleep(0.05)
        outputs = [c.communicate(timeout=300) for c in children]
        assert all(c.returncode == 0 for c in children), outputs
        said = [o.strip() for o, _ in outputs]
        won = [i for i, s in enumerate(said) if s == "fitted"]
        assert len(won) == 1, said
        assert said[1 - won[0]].startswith("refused:"), said
        clip = doma.read_tracks(data).tracks[112:132]
        expected = clip[::-1] if won[0] == 1 else clip
        assert np.array_equal(doma.read_tracks(out / "tracks.npz").tracks, expected)


def test_pip_without_a_rust_toolchain_fails_at_once_saying_what_to_install(tmp_path):
    import time

    from conftest import ROOT

    # Only the interpreter's own folder on PATH: pip and maturin, no cargo or rustc.
    env = {**os.environ, "PATH": os.path.dirname(sys.executable)}
    env.pop("CARGO", None)
    start = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-build-isolation", "--no-deps", "--target", tmp_path / "t",
         ROOT / "python"],
        env=env, capture_output=True, text=True, timeout=300,
    )
    assert done.returncode != 0
    assert "Rust >= 1.95" in done.stderr + done.stdout and "rustup" in done.stderr + done.stdout, done.stderr
    assert time.monotonic() - start < 120
    assert not (tmp_path / "t" / "doma").exists()
