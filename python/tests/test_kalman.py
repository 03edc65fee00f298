"""Burke & Lasenby's low-dimensional Kalman smoother (`doma.fill(..., "kalman")`) against
the implementation motion-capture users run: pyCGM2's
`LowDimensionalKalmanFilterProcedure._smooth`, read from pyCGM2's source distribution on
PyPI and run as it is published (pyCGM2 itself does not install on this Python: its
setup.py fails, so only that numpy function is taken from the archive, never copied into
the repository). Skipped where PyPI cannot be reached."""

import ast
import pathlib
import subprocess
import sys
import tarfile
import textwrap
import warnings

import numpy as np
import pytest

import doma
from conftest import assert_published_fill

ROOT = pathlib.Path(__file__).resolve().parents[2]
RIGHT_KNEE = ROOT / "data" / "mocap" / "right_knee.c3d"
PYCGM2 = "pyCGM2==4.2"
CACHE = pathlib.Path.home() / ".cache" / "doma-pycgm2"


@pytest.fixture(scope="module")
def pycgm2_smooth():
    """pyCGM2's `_smooth(rawdata, tol, sigR, keepOriginal)`, from its sdist."""
    CACHE.mkdir(parents=True, exist_ok=True)
    archives = sorted(CACHE.glob("pyCGM2-4.2.tar.gz"))
    if not archives:
        done = subprocess.run(
            [sys.executable, "-m", "pip", "download", "-q", "--no-deps", "--no-binary", ":all:",
             "--disable-pip-version-check", PYCGM2, "-d", str(CACHE)],
            capture_output=True, text=True, timeout=300,
        )
        archives = sorted(CACHE.glob("pyCGM2-4.2.tar.gz"))
        if done.returncode != 0 or not archives:
            pytest.skip(f"{PYCGM2} could not be downloaded: {done.stderr.strip()[-300:]}")
    with tarfile.open(archives[0]) as tar:
        member = next(m for m in tar.getmembers() if m.name.endswith("pyCGM2/Gap/gapFillingProcedures.py"))
        source = tar.extractfile(member).read().decode()
    with warnings.catch_warnings():
        # Its docstrings hold a Windows path ("\\Tests"): an invalid escape to Python 3.12.
        warnings.simplefilter("ignore", DeprecationWarning)
        tree = ast.parse(source)
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "LowDimensionalKalmanFilterProcedure")
    smooth = next(n for n in cls.body if isinstance(n, ast.FunctionDef) and n.name == "_smooth")
    code = textwrap.dedent(ast.get_source_segment(source, smooth).expandtabs(4))

    class Logger:
        def debug(self, *_):
            pass

    namespace = {"np": np, "LOGGER": type("L", (), {"logger": Logger()})()}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        exec(compile(code, "pyCGM2/Gap/gapFillingProcedures.py", "exec"), namespace)
    return lambda raw: namespace["_smooth"](None, raw, tol=1e-2, sigR=1e-3, keepOriginal=True)


def hidden(markers, start=300, length=100):
    """right_knee (mm) with `markers` hidden at frames start..start + length (1 s)."""
    seq = doma.read_tracks(RIGHT_KNEE)
    tracks, observed = seq.tracks.copy(), seq.observed.copy()
    observed[start : start + length, markers] = False
    return tracks, observed


def reference(smooth, tracks, observed, scale=1.0):
    """pyCGM2's fill of tracks (as float64, times `scale`), in those units: its data
    matrix [T, 3N] with NaN where unobserved, as its `_fill` builds it from a C3D."""
    raw = tracks.astype(np.float64) * scale
    raw[~observed] = np.nan
    np.random.seed(0)
    return smooth(raw.reshape(len(raw), -1)).reshape(raw.shape)


@pytest.mark.parametrize("markers", [[40], [3, 40, 60]])
def test_kalman_fill_is_pycgm2_s_to_float32_rounding(pycgm2_smooth, markers):
    tracks, observed = hidden(markers)
    truth = doma.read_tracks(RIGHT_KNEE).tracks
    assert_published_fill("kalman", reference(pycgm2_smooth, tracks, observed), tracks, observed, truth)


def test_kalman_fill_of_tracks_in_metres_runs_in_millimetres(pycgm2_smooth):
    """pyCGM2's σ_R is in mm²: tracks in metres (a spread under 20 units) are filled as
    the same tracks in millimetres."""
    tracks, observed = hidden([40])
    metres = (tracks / 1000).astype(np.float32)
    ours = doma.fill(metres, observed, "kalman", extrapolate=True)
    theirs = reference(pycgm2_smooth, metres, observed, scale=1000.0) / 1000.0
    gap = ~observed
    np.testing.assert_array_max_ulp(ours[gap], theirs[gap].astype(np.float32), maxulp=1)
