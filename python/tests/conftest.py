"""Shared data of the Python tests: a 20-frame clip of the shipped faerie, and the CLI."""

import os
import pathlib

import numpy as np
import pytest

import doma

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def clip() -> np.ndarray:
    """The faerie's "wave" animation, frames 112..132: [20, 366, 3] float32."""
    seq = doma.read_tracks(ROOT / "data" / "md2_faerie.traj")
    return np.ascontiguousarray(seq.tracks[112:132])


@pytest.fixture(scope="session")
def fitted(clip, tmp_path_factory) -> doma.Field:
    """A short fit of the clip, in a run folder."""
    out = tmp_path_factory.mktemp("fitted") / "run"
    return doma.fit(clip, iters=30, progress=False, out=out)


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The `doma` binary of the Rust build (`cargo test --release` builds it)."""
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    binary = target / "release" / "doma"
    if not binary.is_file():
        message = f"no doma binary at {binary}: run `cargo build --release` first"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    return binary


def assert_published_fill(method, reference, tracks, observed, truth):
    """doma.fill(..., method) against `reference` (the published implementation's fill,
    float64) on the hidden entries: to 1 float32 ulp (doma computes in float64 and
    returns float32, 6e-5 mm at 1 m), the observed entries as given, and better than a
    line against `truth` by half."""
    ours = doma.fill(tracks, observed, method, extrapolate=True)
    gap = ~observed
    np.testing.assert_array_max_ulp(ours[gap], reference[gap].astype(np.float32), maxulp=1)
    assert np.array_equal(ours[observed], tracks[observed])
    error = lambda f: np.linalg.norm(f[gap] - truth[gap], axis=1).mean()
    assert error(ours) < 0.5 * error(doma.fill(tracks, observed, "linear"))
