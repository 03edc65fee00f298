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
