"""`doma complete RUN --out F.c3d` writes the input file with only the filled points
changed: checked with two independent readers (PyPI `ezc3d` and `c3d`) on the shared
recordings (force plates among them) and on the C3D.ORG sample files (Intel, SGI/MIPS and
DEC; integer and float; a data start past block 127; a duplicated group), read from
`../shared/data/` where present, and on a file of 70,000 frames written here."""

import os
import pathlib
import re
import subprocess
import warnings

import c3d
import doma
import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"
FILES = sorted((SHARED / "mocap").glob("*.c3d")) + sorted((SHARED / "c3d-samples").glob("*/*.c3d"))


def complete(cli, source, work, frames="0..60"):
    """A one-iteration fit of `frames` of `source`, completed to a .c3d: its path and the
    number of entries filled."""
    run, out = work / "run", work / "filled.c3d"
    subprocess.run(
        [cli, "fit", source, "--frames", frames, "--iters", "1", "--drop-unobserved", "--quiet", "--out", run],
        check=True, capture_output=True,
    )
    done = subprocess.run([cli, "complete", run, "--out", out], check=True, capture_output=True, text=True)
    return out, int(re.search(r"(\d+) filled", done.stderr).group(1))


def ezc3d_or_none(path):
    """The file as ezc3d reads it; None for the processor it does not read (SGI/MIPS)."""
    ezc3d = pytest.importorskip("ezc3d")
    try:
        return ezc3d.c3d(str(path))
    except RuntimeError as e:
        if "MIPS" in str(e):
            return None
        raise


def same_parameters(a, b):
    """Every group and parameter in the same order, with the same values."""
    assert list(a) == list(b)
    for group in a:
        if not isinstance(a[group], dict):
            continue
        assert list(a[group]) == list(b[group]), group
        for name, value in a[group].items():
            if isinstance(value, dict) and "value" in value:
                x, y = value["value"], b[group][name]["value"]
                assert type(x) is type(y) and (np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y), (group, name)


def c3d_frames(path):
    """Points [T, N, 5] and analog samples [T, C, S] as the `c3d` package reads them; None
    where it refuses the file (a duplicated group)."""
    try:
        with open(path, "rb") as h, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            frames = [(p.copy(), a.copy()) for _, p, a in c3d.Reader(h).read_frames()]
    except KeyError:
        return None
    return np.stack([p for p, _ in frames]), np.stack([a for _, a in frames])


@pytest.mark.parametrize("source", FILES, ids=lambda p: p.name)
def test_a_filled_c3d_is_its_input_with_only_the_gaps_written(cli, source, tmp_path):
    out, filled = complete(cli, source, tmp_path)
    given, written = source.read_bytes(), out.read_bytes()
    assert len(written) == len(given)
    # At most the 4 words of each filled point changed.
    assert sum(a != b for a, b in zip(given, written)) <= 16 * filled
    before, after = ezc3d_or_none(source), ezc3d_or_none(out)
    if before is not None:
        assert np.array_equal(before["data"]["analogs"], after["data"]["analogs"], equal_nan=True)
        same_parameters(before["parameters"], after["parameters"])
        p, q = before["data"]["points"], after["data"]["points"]
        changed = ~np.all((p == q) | (np.isnan(p) & np.isnan(q)), axis=0)
        assert changed.sum() <= filled and (changed[:, 60:] == False).all()  # noqa: E712
    read = c3d_frames(source)
    if read is not None:
        (p, a), (q, b) = read, c3d_frames(out)
        assert np.array_equal(a, b)
        # Measured points as they were; the filled ones measured now, residual 0.
        measured = (p[..., 3] >= 0) & ~np.all(p[..., :3] == 0, axis=-1)
        assert np.array_equal(p[measured], q[measured])
        new = ~measured & (q[..., 3] >= 0) & ~np.all(q[..., :3] == 0, axis=-1)
        assert new.sum() == filled and (q[..., 3][new] == 0).all()


def test_the_shared_files_are_there_under_ci():
    if not FILES:
        if os.environ.get("CI"):
            pytest.fail(f"no C3D files under {SHARED}")
        pytest.skip(f"SKIPPED: no C3D files under {SHARED}")


def test_a_file_of_more_than_65535_frames_completes_in_place(cli, tmp_path):
    ezc3d = pytest.importorskip("ezc3d")
    t, n = 70_000, 4
    k = np.arange(t, dtype=np.float64)
    points = np.zeros((t, n, 5), np.float32)
    for i in range(n):
        points[:, i, 0] = 100 * np.sin(0.01 * k + i) + 10 * i
        points[:, i, 1] = 50 * np.cos(0.013 * (i + 1) * k)
        points[:, i, 2] = 900 + i
    points[30_000:30_040, 1, 3] = -1
    writer = c3d.Writer(point_rate=200.0, point_scale=-0.01, point_units="mm  ")
    writer.set_point_labels([f"M{i}" for i in range(n)])
    writer.add_frames([(p, np.zeros((0, 0))) for p in points])
    source = tmp_path / "long.c3d"
    with open(source, "wb") as h:
        writer.write(h)
    out, filled = complete(cli, source, tmp_path, frames="29900..30200")
    assert filled == 40
    before, after = ezc3d.c3d(str(source)), ezc3d.c3d(str(out))
    assert after["data"]["points"].shape == (4, n, t)
    gap = np.zeros(t, bool)
    gap[30_000:30_040] = True
    p, q = before["data"]["points"], after["data"]["points"]
    assert np.array_equal(p[:, :, ~gap], q[:, :, ~gap], equal_nan=True)
    assert np.isfinite(q[:3, 1, gap]).all() and np.isnan(p[:3, 1, gap]).all()
    # Near the truth: the sine the marker follows, within a few mm.
    assert np.abs(q[0, 1, gap] - (100 * np.sin(0.01 * k[gap] + 1) + 10)).max() < 10
    with open(out, "rb") as h:
        assert sum(1 for _ in c3d.Reader(h).read_frames()) == t


def test_a_models_outputs_are_left_as_they_are_unless_asked_for(cli, tmp_path):
    """Nexus stores joint angles, forces, moments and powers as points, listed by
    POINT:ANGLES, FORCES, ...: a file written by ezc3d with one such point, a gap in it
    and one in a marker. The fit leaves the angle out (it is not a position) and the
    filled file holds it as the input does; `--model-outputs` fits and fills it too."""
    ezc3d = pytest.importorskip("ezc3d")
    t, n = 120, 7
    k = np.arange(t)
    points = np.ones((4, n, t))
    for i in range(n):
        points[0, i] = 100 * np.sin(0.05 * k + 0.3 * i) + 30 * i
        points[1, i] = 80 * np.cos(0.04 * k) + 10 * i
        points[2, i] = 900 + 5 * i + 3 * np.sin(0.1 * k)
    residuals = np.ones((1, n, t))
    for i, gap in [(1, slice(50, 60)), (6, slice(40, 70))]:
        points[:3, i, gap] = np.nan
        residuals[0, i, gap] = -1
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple([f"M{i}" for i in range(n - 1)] + ["LKneeAngles"])
    c["data"]["points"] = points
    c["data"]["meta_points"] = {"residuals": residuals, "camera_masks": np.zeros((7, n, t), bool)}
    c.add_parameter("POINT", "ANGLES", ["LKneeAngles"])
    source = tmp_path / "angles.c3d"
    c.write(str(source))
    given = ezc3d.c3d(str(source))["data"]["points"]
    markers, every = doma.read_tracks(source), doma.read_tracks(source, model_outputs=True)
    assert markers.tracks.shape == (t, n - 1, 3) and list(markers.kept) == list(range(n - 1))
    assert every.tracks.shape == (t, n, 3) and every.kept is None
    for asked, filled in [([], 10), (["--model-outputs"], 40)]:
        run, out = tmp_path / f"run{len(asked)}", tmp_path / f"filled{len(asked)}.c3d"
        fit = subprocess.run([cli, "fit", source, "--iters", "1", "--out", run, *asked],
                             check=True, capture_output=True, text=True)
        assert ("left out the file's 1 model outputs" in fit.stderr) == (not asked)
        done = subprocess.run([cli, "complete", run, "--out", out], check=True, capture_output=True, text=True)
        assert int(re.search(r"(\d+) filled", done.stderr).group(1)) == filled
        q = ezc3d.c3d(str(out))["data"]["points"]
        assert np.isfinite(q[:3, 1, 50:60]).all()
        assert np.isfinite(q[:3, 6, 40:70]).all() == bool(asked)
        assert np.array_equal(q[:3, 6], given[:3, 6], equal_nan=True) == (not asked)
