"""`doma fill` on a lab's folder: three C3D trials (Intel integers, DEC floats, force
plates in each) and one OpenSim TRC with gaps, and a broken file, in one command. The C3D
outputs keep every parameter and analog sample (ezc3d); the TRC reads back in OpenSim's
own `TRCFileAdapter` (or, without its wheel, in the `c3d`-free reader below) with the same
markers, rate and units; the broken file is reported and the others written; a second run
skips, `--overwrite` rewrites."""

import csv
import os
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

import doma

ROOT = pathlib.Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data" / "c3d-samples"
TRIALS = [SHARED / "sample_02" / "pc_int.c3d", SHARED / "sample_01" / "Eb015vr.c3d"]
RIGHT_KNEE = ROOT / "data" / "mocap" / "right_knee.c3d"


def write_trc(path, tracks, observed, labels, rate):
    """A .trc as OpenSim documents it, written here without doma: empty fields where a
    marker is missing."""
    t, n, _ = tracks.shape
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:.2f}\t{rate:.2f}\t{t}\t{n}\tmm\t{rate:.2f}\t1\t{t}",
        "Frame#\tTime\t" + "\t\t\t".join(labels),
        "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(n)),
        "",
    ]
    for k in range(t):
        values = [f"{v:.5f}" if observed[k, i] else "" for i in range(n) for v in tracks[k, i]]
        lines.append("\t".join([str(k + 1), f"{k / rate:.5f}", *values]))
    path.write_text("\n".join(lines) + "\n")


def read_trc_independently(path):
    """Markers, rate, units and [T, N, 3] as OpenSim reads the file."""
    osim = pytest.importorskip("opensim")
    table = osim.TimeSeriesTableVec3(str(path))
    labels = list(table.getColumnLabels())
    values = np.array(
        [[[table.getRowAtIndex(k)[i][j] for j in range(3)] for i in range(len(labels))] for k in range(table.getNumRows())]
    )
    return labels, float(table.getTableMetaDataAsString("DataRate")), table.getTableMetaDataAsString("Units"), values


def same_parameters(a, b):
    assert list(a) == list(b)
    for group in a:
        if isinstance(a[group], dict):
            assert list(a[group]) == list(b[group]), group
            for name, value in a[group].items():
                if isinstance(value, dict) and "value" in value:
                    x, y = value["value"], b[group][name]["value"]
                    assert np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y, (group, name)


@pytest.fixture
def folder(tmp_path):
    missing = [p for p in TRIALS if not p.is_file()]
    if missing:
        if os.environ.get("CI"):
            pytest.fail(f"missing {missing}")
        pytest.skip(f"SKIPPED: no {missing}")
    trials = tmp_path / "trials"
    trials.mkdir()
    for p in TRIALS + [RIGHT_KNEE]:
        shutil.copy(p, trials / p.name)
    knee = doma.read_tracks(RIGHT_KNEE)
    tracks, observed = knee.tracks[:200:2].copy(), knee.observed[:200:2].copy()
    observed[30:45, 4] = False
    observed[60:64, 10] = False
    write_trc(trials / "knee.trc", tracks, observed, knee.labels, knee.rate / 2)
    (trials / "broken.c3d").write_bytes(RIGHT_KNEE.read_bytes()[:3000])
    return trials


def test_a_folder_is_filled_in_one_command(cli, folder, tmp_path):
    ezc3d = pytest.importorskip("ezc3d")
    out = tmp_path / "filled"
    args = [cli, "fill", folder, "--out", out, "--fit", "--iters", "20", "--jobs", "2"]
    done = subprocess.run(args, capture_output=True, text=True)
    # The broken file fails the command, named; the others are written.
    assert done.returncode == 1, done.stderr
    assert "broken.c3d: failed" in done.stderr and "the parameter section ends" in done.stderr
    assert "4 recordings filled" in done.stderr and "1 failed" in done.stderr
    names = sorted(p.name for p in out.iterdir())
    stems = ["Eb015vr", "knee", "pc_int", "right_knee"]
    assert names == sorted([f"{s}.{e}" for s in stems for e in ["gaps.csv", "gaps.html"]]
                           + ["Eb015vr.c3d", "knee.trc", "pc_int.c3d", "right_knee.c3d"])
    for source in TRIALS:
        before, after = ezc3d.c3d(str(source)), ezc3d.c3d(str(out / source.name))
        assert np.array_equal(before["data"]["analogs"], after["data"]["analogs"])
        same_parameters(before["parameters"], after["parameters"])
        given, written = source.read_bytes(), (out / source.name).read_bytes()
        rows = list(csv.DictReader((out / source.name).with_suffix(".gaps.csv").open()))
        filled = sum(int(r["length_frames"]) for r in rows)
        assert len(given) == len(written) and filled > 0
        assert sum(a != b for a, b in zip(given, written)) <= 16 * filled
        line = next(l for l in done.stderr.splitlines() if l.startswith(str(folder / source.name)))
        assert f"{len(rows)} gaps filled" in line and "markers" in line
    # The TRC reads back in OpenSim: the same markers, rate and units, its gaps filled.
    labels, rate, units, values = read_trc_independently(out / "knee.trc")
    knee = doma.read_tracks(folder / "knee.trc")
    assert labels == list(knee.labels) and rate == knee.rate and units == "mm"
    assert np.isfinite(values[30:45, 4]).all() and np.isfinite(values[60:64, 10]).all()
    seen = knee.observed
    np.testing.assert_allclose(values[seen], knee.tracks[seen], atol=1e-3)
    rows = list(csv.DictReader((out / "knee.gaps.csv").open()))
    assert {(r["marker"], r["first_frame"], r["last_frame"]) for r in rows} == {
        (knee.labels[4], "30", "44"), (knee.labels[10], "60", "63")}
    # Each gap's expected error in mm, the flagged ones (past 5 mm) first.
    assert all(r["units"] == "mm" and float(r["expected_error"]) >= 0 for r in rows)
    flags = [r["flagged"] == "true" for r in rows]
    assert flags == sorted(flags, reverse=True)
    assert flags == [float(r["expected_error"]) > 5 for r in rows]
    # A second run skips what exists; --overwrite writes again.
    stamps = {p: p.stat().st_mtime_ns for p in out.iterdir()}
    again = subprocess.run([cli, "fill", folder / "knee.trc", folder / "pc_int.c3d", "--out", out, "--no-fit"],
                           capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert sum(": skipped" in l for l in again.stderr.splitlines()) == 2 and "2 skipped" in again.stderr
    assert all(p.stat().st_mtime_ns == stamps[p] for p in out.iterdir())
    over = subprocess.run([cli, "fill", folder / "knee.trc", "--out", out, "--no-fit", "--overwrite"],
                          capture_output=True, text=True)
    assert over.returncode == 0 and "by chain" in over.stderr, over.stderr
    assert (out / "knee.trc").stat().st_mtime_ns != stamps[out / "knee.trc"]


def test_one_file_to_another_format_and_bad_outputs_refused(cli, folder, tmp_path):
    trc = tmp_path / "one.trc"
    done = subprocess.run([cli, "fill", folder / "right_knee.c3d", "--out", trc, "--no-fit", "--quiet"],
                          capture_output=True, text=True)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    labels, rate, units, values = read_trc_independently(trc)
    knee = doma.read_tracks(RIGHT_KNEE)
    assert labels == list(knee.labels) and rate == 100.0 and units == "mm"
    np.testing.assert_allclose(values, knee.tracks, atol=1e-3)
    # A TRC to a new C3D: its markers, rate and units; measured residual 0, filled −0.0.
    ezc3d = pytest.importorskip("ezc3d")
    made = tmp_path / "from_trc.c3d"
    done = subprocess.run([cli, "fill", folder / "knee.trc", "--out", made, "--no-fit"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    c = ezc3d.c3d(str(made))
    seq = doma.read_tracks(folder / "knee.trc")
    assert list(c["parameters"]["POINT"]["LABELS"]["value"]) == list(seq.labels)
    assert c["parameters"]["POINT"]["RATE"]["value"][0] == seq.rate
    points = c["data"]["points"][:3].transpose(2, 1, 0)
    np.testing.assert_allclose(points[seq.observed], seq.tracks[seq.observed], atol=1e-3)
    assert np.isfinite(points[30:45, 4]).all()
    # The residual words as stored (readers turn −0.0 into residual 0).
    raw = made.read_bytes()
    t, n = seq.observed.shape
    start = 512 * (int.from_bytes(raw[16:18], "little") - 1)
    residual = np.frombuffer(raw[start : start + 16 * t * n], "<f4").reshape(t, n, 4)[..., 3]
    assert (residual == 0).all()
    assert np.array_equal(np.signbit(residual), ~seq.observed)
    back = doma.read_tracks(made)
    assert back.observed.all() and back.labels == seq.labels
    npz = tmp_path / "plain.npz"
    np.savez(npz, tracks=seq.tracks, observed=seq.observed)
    for source, bad, why in [(folder / "right_knee.c3d", tmp_path / "x.csv", "extension"),
                             (npz, tmp_path / "y.c3d", "marker names")]:
        refused = subprocess.run([cli, "fill", source, "--out", bad], capture_output=True, text=True)
        assert refused.returncode != 0 and why in refused.stderr and str(bad) in refused.stderr
        assert not bad.exists()


def test_fill_file_from_python_returns_the_report(folder, tmp_path):
    out = tmp_path / "knee_filled.trc"
    report = doma.fill_file(folder / "knee.trc", out, fit=False)
    assert report["filled_by"] == "chain" and report["markers"] == 73 and report["units"] == "mm"
    assert report["calibration"]["spans"] >= 8 and report["calibration"]["factor"] > 0
    assert {(g["first_frame"], g["last_frame"]) for g in report["gaps"]} == {(30, 44), (60, 63)}
    assert pathlib.Path(report["csv"]).is_file()
    page = pathlib.Path(report["html"]).read_text()
    assert page.count("<svg") == 3 * len(report["gaps"]) and "</html>" in page
    back = doma.read_tracks(out)
    assert back.observed.all() and back.labels == doma.read_tracks(folder / "knee.trc").labels
    with pytest.raises(FileExistsError):
        doma.fill_file(folder / "knee.trc", out, fit=False)
    # doma.fill on Tracks with the CLI's defaults: the same fill.
    seq = doma.read_tracks(folder / "knee.trc")
    np.testing.assert_allclose(doma.fill(seq), back.tracks, atol=1e-3)
    short = doma.fill(seq, max_gap="0.1s")  # 5 frames at 50 Hz: the 15-frame gap left
    assert np.isnan(short[30:45, 4]).all() and np.isfinite(short[60:64, 10]).all()
