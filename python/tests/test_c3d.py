"""C3D in and out, checked against an independent implementation (PyPI `c3d`): doma reads
a vendor file as it does, and a recording written by it with gaps comes back from
`doma fit` and `doma complete` with its labels, frames, rate and measured markers, and no
marker missing."""

import pathlib
import subprocess

import c3d
import numpy as np
import pytest

import doma

# The independent reader warns about what a points-only file lacks (analog channels).
pytestmark = pytest.mark.filterwarnings("ignore:No analog data:UserWarning")

ROOT = pathlib.Path(__file__).resolve().parents[2]
RIGHT_KNEE = ROOT / "data" / "mocap" / "right_knee.c3d"


def read(path):
    """Points [T, N, 5] (x, y, z, residual, cameras), labels, rate, first frame, units."""
    with open(path, "rb") as h:
        r = c3d.Reader(h)
        points = np.stack([p.copy() for _, p, _ in r.read_frames()])
        labels = [label.strip() for label in r.point_labels]
        units = r.get("POINT:UNITS").string_value.strip()
        return points, labels, float(r.point_rate), int(r.first_frame), units


def measured(points):
    """Where a marker was measured: residual >= 0 and not the origin."""
    return (points[..., 3] >= 0) & ~np.all(points[..., :3] == 0, axis=-1)


def test_a_vendor_file_reads_as_the_independent_reader_reads_it():
    points, labels, rate, first, units = read(RIGHT_KNEE)
    seq = doma.read_tracks(RIGHT_KNEE)
    assert seq.tracks.shape == points.shape[:2] + (3,) == (922, 73, 3)
    assert np.array_equal(seq.tracks, points[..., :3].astype(np.float32))
    assert np.array_equal(seq.observed, measured(points))
    assert (rate, first, units, labels[0]) == (100.0, 100, "mm", "HV")


def test_a_recording_with_gaps_fits_and_completes_to_a_c3d(cli, tmp_path):
    points, labels, rate, first, _ = read(RIGHT_KNEE)
    # 40 frames at a third of the rate, with gaps in the moving right leg's markers and
    # in the still body's, written by the independent writer.
    clip = points[0:120:3].copy()
    moving = [labels.index(name) for name in ("RLEG2", "RLEG3")]
    still = [labels.index(name) for name in ("HV", "OCC")]
    for i, (a, b) in zip(moving + still, [(5, 12), (20, 26), (0, 4), (33, 40)]):
        clip[a:b, i, 3:] = -1
    writer = c3d.Writer(point_rate=rate / 3, point_scale=-0.05, point_units="mm  ")
    writer.set_point_labels(labels)
    writer.set_start_frame(first)
    writer.add_frames([(p, np.zeros((0, 0))) for p in clip])
    source = tmp_path / "markers.c3d"
    with open(source, "wb") as h:
        writer.write(h)
    given, _, given_rate, _, _ = read(source)
    seen = measured(given)
    assert (~seen).sum() == 7 + 6 + 4 + 7

    run, out = tmp_path / "run", tmp_path / "filled.c3d"
    subprocess.run([cli, "fit", source, "--out", run, "--iters", "30", "--quiet"], check=True, capture_output=True)
    subprocess.run([cli, "complete", run, "--out", out, "--extrapolate"], check=True, capture_output=True)

    filled, out_labels, out_rate, out_first, out_units = read(out)
    assert filled.shape == given.shape
    assert (out_labels, out_first, out_units) == (labels, first, "mm")
    assert out_rate == pytest.approx(given_rate)
    # Measured markers unchanged (within 0.01 mm), with their residuals; every gap filled,
    # marked computed (residual 0, no camera), near the truth of the still markers.
    assert np.abs(filled[..., :3][seen] - given[..., :3][seen]).max() < 0.01
    assert np.allclose(filled[..., 3][seen], given[..., 3][seen], atol=0.05)
    assert measured(filled).all() and np.isfinite(filled[..., :3]).all()
    assert (filled[..., 3][~seen] == 0).all() and (filled[..., 4][~seen] == 0).all()
    for i, (a, b) in zip(still, [(0, 4), (33, 40)]):
        error = np.linalg.norm(filled[a:b, i, :3] - clip[a:b, i, :3], axis=-1).max()
        assert error < 20.0, (labels[i], error)
    # doma reads its own output as the independent reader does.
    back = doma.read_tracks(out)
    assert np.array_equal(back.tracks, filled[..., :3].astype(np.float32))
    assert back.observed.all()
