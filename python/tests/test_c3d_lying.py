"""C3D files whose counts lie or pass 16 bits: every frame of a recording longer than
65,535 frames read, filled and written back by each convention writers use; a header that
claims more points than the file holds refused at once, from the CLI and from Python; a
header that disagrees with the parameters read as the file's length confirms; a NaN
residual read and kept as a measured point. Checked with ezc3d and the `c3d` package where
they read the file."""

import pathlib
import re
import subprocess
import sys
import warnings

import c3d
import numpy as np
import pytest

import c3d_bytes as cb
import doma

LABELS = ["M0", "M1", "M2"]


def markers(t):
    """[T, 3, 4]: three markers on smooth paths, residual word 1 (measured)."""
    k = np.arange(t, dtype=np.float64)
    p = np.zeros((t, 3, 4), np.float32)
    for i in range(3):
        p[:, i, 0] = 100 * np.sin(0.01 * k + i) + 10 * i
        p[:, i, 1] = 50 * np.cos(0.013 * (i + 1) * k)
        p[:, i, 2] = 900 + i
    p[..., 3] = 1
    return p


def complete(cli, source, work, frames, *more):
    """A one-iteration fit of `frames` of `source` completed to a .c3d: its path, and the
    number of entries filled."""
    run, out = work / "run", work / "filled.c3d"
    fit = subprocess.run([cli, "fit", source, "--frames", frames, "--iters", "1", "--out", run, *more],
                         capture_output=True, text=True)
    assert fit.returncode == 0, fit.stderr
    done = subprocess.run([cli, "complete", run, "--out", out], check=True, capture_output=True, text=True)
    return out, int(re.search(r"(\d+) filled", done.stderr).group(1)), fit.stderr


def c3d_points(path):
    """Points [T, N, 5] as the `c3d` package reads them; None where it refuses the file."""
    try:
        with open(path, "rb") as h, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return np.stack([p.copy() for _, p, _ in c3d.Reader(h).read_frames()])
    except (IndexError, KeyError, ValueError, AssertionError):
        return None


def ezc3d_points(path):
    """Points [4, N, T] as ezc3d reads them; None where it refuses the file."""
    ezc3d = pytest.importorskip("ezc3d")
    try:
        return ezc3d.c3d(str(path))["data"]["points"]
    except (RuntimeError, ValueError):  # e.g. "FRAMES parameter is not an INT"
        return None


LONG = {
    "a float POINT:FRAMES": lambda t: [cb.f32(1, "FRAMES", float(t))],
    "POINT:LONG_FRAMES": lambda t: [cb.i16(1, "FRAMES", 65535), cb.f32(1, "LONG_FRAMES", float(t))],
    "the TRIAL range": lambda t: [cb.i16(1, "FRAMES", 65535)] + cb.trial(1, t),
    "no longer count": lambda t: [cb.i16(1, "FRAMES", 65535)],
}


@pytest.mark.parametrize("t", [65_536, 70_000])
@pytest.mark.parametrize("convention", list(LONG))
def test_a_recording_past_65535_frames_is_read_filled_and_written_whole(cli, tmp_path, convention, t):
    p = markers(t)
    gap = slice(t - 300, t - 260)
    p[gap, 1, 3] = -1
    source = tmp_path / "long.c3d"
    cb.write(source, p, cb.point_params(LABELS) + LONG[convention](t))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        seq = doma.read_tracks(source)
    # Read by its length where no count says more than 65535, and said so.
    assert [f"read {t}" in str(w.message) for w in said] == ([True] if convention == "no longer count" else [])
    assert seq.tracks.shape == (t, 3, 3) and (~seq.observed).sum() == 40
    out, filled, _ = complete(cli, source, tmp_path, f"{t - 500}..{t}")
    assert filled == 40
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        back = doma.read_tracks(out)
    assert back.observed.all() and back.tracks.shape == (t, 3, 3)
    keep = np.ones(t, bool)
    keep[gap] = False
    assert np.array_equal(back.tracks[keep], seq.tracks[keep])
    # Near the sine the marker follows.
    k = np.arange(t)[gap]
    assert np.abs(back.tracks[gap, 1, 0] - (100 * np.sin(0.01 * k + 1) + 10)).max() < 10
    # The independent readers, where they read the file, see every frame and the fill.
    readers = 0
    q = c3d_points(out)
    if q is not None:
        readers += 1
        assert len(q) == t and (q[gap, 1, 3] == 0).all()
        assert np.array_equal(q[keep][..., :3], p[keep][..., :3])
    q = ezc3d_points(out)
    if q is not None:
        readers += 1
        # ezc3d reads a long file by its length: the last block's padding as frames too.
        assert q.shape[2] >= t and np.isfinite(q[:3, 1, gap]).all()
        assert np.allclose(q[:3, :, :t].transpose(2, 1, 0)[keep], p[keep][..., :3])
    assert readers >= 1


def test_counts_that_disagree_are_refused_naming_both(cli, tmp_path):
    p = markers(70_000)
    source = tmp_path / "disagree.c3d"
    params = [cb.i16(1, "FRAMES", 65535), cb.f32(1, "LONG_FRAMES", 70_000.0)] + cb.trial(1, 69_000)
    cb.write(source, p, cb.point_params(LABELS) + params)
    with pytest.raises(ValueError, match="70000.*69000"):
        doma.read_tracks(source)
    fit = subprocess.run([cli, "fit", source, "--out", tmp_path / "run"], capture_output=True, text=True)
    assert fit.returncode != 0 and "70000" in fit.stderr and "69000" in fit.stderr
    assert not (tmp_path / "run").exists()


MEASURE = """
import resource, subprocess, sys, time
start = time.perf_counter()
if sys.argv[1] == "cli":
    done = subprocess.run(sys.argv[2:], capture_output=True, text=True)
    outcome, usage = done.stderr.strip(), resource.RUSAGE_CHILDREN
else:
    import doma
    try:
        doma.read_tracks(sys.argv[2])
        outcome = "read"
    except ValueError as e:
        outcome = "ValueError: " + str(e)
    usage = None
print(time.perf_counter() - start)
# This process's peak from /proc (ru_maxrss would carry the forking parent's over exec);
# the child's from getrusage.
if usage is None:
    print(next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM")))
else:
    print(resource.getrusage(usage).ru_maxrss)
print(outcome)
"""


def test_a_header_claiming_65535_points_is_refused_at_once(cli, tmp_path):
    """65,535 points over 60,000 frames claimed by the header and POINT:USED over a file of
    a few kB: refused in under a second and 100 MB, from the CLI and from Python."""
    source = tmp_path / "claims.c3d"
    params = cb.point_params(LABELS) + [cb.i16(1, "FRAMES", 60_000)]
    params[0] = cb.i16(1, "USED", 65535)
    cb.write(source, markers(60), params, header={2: 65535, 5: 60_000})
    for how, args in [("cli", [str(cli), "fit", str(source), "--out", str(tmp_path / "run")]),
                      ("python", [str(source)])]:
        done = subprocess.run([sys.executable, "-c", MEASURE, how, *args], capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        seconds, kb, outcome = done.stdout.split("\n", 2)
        assert "65535 points" in outcome and "claims.c3d" in outcome, outcome
        assert float(seconds) < 1.0 and int(kb) < 100_000, (how, seconds, kb)
    assert not (tmp_path / "run").exists()


def test_a_header_that_disagrees_with_the_parameters_is_read_as_the_length_says(cli, tmp_path):
    """Header word 3 says no analog words; ANALOG:USED × ANALOG:RATE / POINT:RATE says 64,
    which the file's length holds (force plates): read as the parameters say, and filled
    without a fill past a marker's ends."""
    t = 100
    p = markers(t)
    p[40:50, 0, 3] = -1
    analog = np.random.default_rng(1).normal(size=(t, 64)).astype(np.float32)
    source = tmp_path / "analog.c3d"
    params = cb.point_params(LABELS, analog_used=4, analog_rate=1600.0) + [cb.i16(1, "FRAMES", t)]
    cb.write(source, p, params, header={3: 0}, analog=analog)
    with pytest.warns(UserWarning, match="64 analog words"):
        seq = doma.read_tracks(source)
    assert seq.observed.sum() == 3 * t - 10
    assert np.allclose(seq.tracks[seq.observed], p[..., :3][seq.observed])
    out, filled, said = complete(cli, source, tmp_path, f"0..{t}")
    assert filled == 10 and "64 analog words" in said
    given, written = source.read_bytes(), out.read_bytes()
    assert len(given) == len(written) and sum(a != b for a, b in zip(given, written)) <= 16 * 10


def test_a_nan_residual_is_a_measured_point_kept_as_it_is(cli, tmp_path):
    """ezc3d reads a NaN residual word over finite coordinates as a measured point: so does
    doma, and the fill never writes over it. NaN coordinates (kineticstoolkit's missing
    point) are a gap, filled, and said once."""
    t = 100
    p = markers(t)
    p[10:20, 2, 3] = np.nan
    p[60:70, 1, :3] = np.nan
    p[60:70, 1, 3] = 0
    source = tmp_path / "nan.c3d"
    cb.write(source, p, cb.point_params(LABELS) + [cb.i16(1, "FRAMES", t)])
    with pytest.warns(UserWarning, match="10 points have NaN coordinates"):
        seq = doma.read_tracks(source)
    assert seq.observed[10:20, 2].all() and not seq.observed[60:70, 1].any()
    assert seq.observed.sum() == 3 * t - 10
    q = ezc3d_points(source)
    if q is not None:
        assert np.isfinite(q[:3, 2, 10:20]).all()
    out, filled, said = complete(cli, source, tmp_path, f"0..{t}")
    assert filled == 10 and said.count("NaN coordinates") == 1
    given, written = np.frombuffer(source.read_bytes(), np.uint8), np.frombuffer(out.read_bytes(), np.uint8)
    changed = np.flatnonzero(given != written)
    # Only marker 1's words in frames 60..70 changed: the NaN-residual words are as given.
    start = 512 * (int(written[512 + 2]) + 1)
    frames, points = (changed - start) // 48, (changed - start) % 48 // 16
    assert set(frames) <= set(range(60, 70)) and set(points) == {1}
