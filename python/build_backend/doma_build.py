"""The package's build backend: maturin's (PEP 517), after a check that the Rust toolchain
it needs is there.

Without one, maturin would download a toolchain and start a cold build that shows only
"still running..." for the better part of an hour; this fails at once instead, saying what
to install. ``doma`` needs Rust >= 1.95 (``rust-version`` in Cargo.toml).
"""

import re
import shutil
import subprocess

import maturin

RUST = (1, 95)


def _check_rust() -> None:
    need = ".".join(map(str, RUST))
    hint = (
        f"doma: installing this package from source compiles its Rust library, which needs "
        f"Rust >= {need} with `cargo` and `rustc` on PATH. Install it with rustup "
        "(https://rustup.rs: `curl https://sh.rustup.rs -sSf | sh`), open a new shell, and run "
        "pip again. The first build takes 10 to 40 minutes on 2 cores (docs/python.md)."
    )
    if shutil.which("cargo") is None or shutil.which("rustc") is None:
        raise RuntimeError(hint + " No `cargo` or `rustc` was found on PATH.")
    try:
        version = subprocess.run(["rustc", "--version"], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError) as e:
        raise RuntimeError(f"{hint} `rustc --version` failed: {e}") from e
    found = re.match(r"rustc (\d+)\.(\d+)", version.stdout)
    if version.returncode != 0 or found is None:
        raise RuntimeError(f"{hint} `rustc --version` said: {(version.stdout + version.stderr).strip()}")
    if tuple(map(int, found.groups())) < RUST:
        raise RuntimeError(f"{hint} This one is {version.stdout.strip()} (`rustup update` updates it).")


def get_requires_for_build_wheel(config_settings=None):
    return maturin.get_requires_for_build_wheel(config_settings)


def get_requires_for_build_sdist(config_settings=None):
    return maturin.get_requires_for_build_sdist(config_settings)


def get_requires_for_build_editable(config_settings=None):
    return maturin.get_requires_for_build_editable(config_settings)


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    _check_rust()
    return maturin.prepare_metadata_for_build_wheel(metadata_directory, config_settings)


def prepare_metadata_for_build_editable(metadata_directory, config_settings=None):
    _check_rust()
    return maturin.prepare_metadata_for_build_editable(metadata_directory, config_settings)


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    _check_rust()
    return maturin.build_wheel(wheel_directory, config_settings, metadata_directory)


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    _check_rust()
    return maturin.build_editable(wheel_directory, config_settings, metadata_directory)


def build_sdist(sdist_directory, config_settings=None):
    _check_rust()
    return maturin.build_sdist(sdist_directory, config_settings)
