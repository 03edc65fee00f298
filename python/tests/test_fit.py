"""A fit from NumPy, its warp and Jacobian, and the run folder it shares with the CLI."""

import gc
import json
import pathlib
import subprocess
import threading
import time

import numpy as np
import pytest

import doma


def test_a_short_fit_moves_points_and_reports_the_held_out_error(fitted, clip):
    report = fitted.report
    assert report["iterations"] == 30 and np.isfinite(report["epe_x1e4"])
    assert (fitted.n_frames, fitted.n_tracks, fitted.backend) == (20, 366, "flex")
    moved = fitted.warp(clip[0], 19)
    assert moved.shape == (366, 3) and moved.dtype == np.float32
    # Closer to where the points went than to where they were.
    fit_error = np.abs(moved - clip[19]).sum(1).mean()
    still = np.abs(clip[0] - clip[19]).sum(1).mean()
    assert fit_error < 0.5 * still, (fit_error, still)
    # Several frames at once are the frames one by one, exactly.
    many = fitted.warp(clip[0], [0, 7.5, 19])
    assert many.shape == (3, 366, 3)
    assert np.array_equal(many[2], moved)
    assert np.array_equal(many[1], fitted.warp(clip[0], 7.5))


def test_the_jacobian_matches_finite_differences_of_the_warp(fitted, clip):
    x = clip[0][::7].astype(np.float64)
    jac = fitted.jacobian(x, 11)
    assert jac.shape == (len(x), 3, 3) and jac.dtype == np.float32
    # Central differences of the float32 warp; the faerie is about 52 units tall.
    eps = 0.05
    numeric = np.stack(
        [
            (fitted.warp(x + eps * e, 11).astype(np.float64) - fitted.warp(x - eps * e, 11)) / (2 * eps)
            for e in np.eye(3)
        ],
        axis=-1,
    )
    assert np.abs(numeric - jac).max() < 5e-3 * max(1.0, np.abs(jac).max())
    assert np.array_equal(fitted.jacobian(x, [3, 11])[1], jac)


def test_the_gil_is_released_during_a_fit(clip):
    count = 0
    stop = threading.Event()

    def spin():
        nonlocal count
        while not stop.is_set():
            count += 1

    thread = threading.Thread(target=spin)
    thread.start()
    before = count
    doma.fit(clip, iters=40, progress=False)
    during = count - before
    stop.set()
    thread.join()
    # With the GIL held, the other thread would not run at all while Rust fits.
    assert during > 10_000, during


def test_a_run_saved_and_loaded_warps_the_same(fitted, clip, tmp_path):
    fitted.save(tmp_path / "copy")
    again = doma.load(tmp_path / "copy")
    assert np.array_equal(again.warp(clip[0], 5), fitted.warp(clip[0], 5))
    assert again.evaluate() == fitted.evaluate()
    # The copy carries its own data: removing the original's leaves it whole.
    assert again.config["data"].startswith(str(tmp_path / "copy"))
    with pytest.raises(FileExistsError, match="already holds a run"):
        fitted.save(tmp_path / "copy")


def test_a_temporary_run_is_removed_with_its_field(clip):
    field = doma.fit(clip, iters=2, progress=False)
    assert field.run_dir is None
    run = pathlib.Path(field.config["data"]).parent
    assert (run / "model.bpk").is_file()
    del field
    gc.collect()
    assert not run.exists()


def test_a_cli_run_and_a_python_run_agree_to_the_last_bit(clip, cli, tmp_path):
    data = tmp_path / "clip.npy"
    np.save(data, clip)
    run = tmp_path / "cli_run"
    subprocess.run([cli, "fit", data, "--out", run, "--iters", "25", "--quiet"], check=True, capture_output=True)
    # The CLI's run, opened in Python: the same metrics as `doma eval`.
    cli_eval = json.loads(subprocess.run([cli, "eval", run], check=True, capture_output=True).stdout)
    opened = doma.load(run)
    assert opened.evaluate()["epe_x1e4"] == cli_eval["epe_x1e4"]
    # The same fit from NumPy: the same report, and `doma eval` opens its run.
    py_run = tmp_path / "py_run"
    field = doma.fit(clip, iters=25, progress=False, out=py_run)
    cli_report = json.loads((run / "report.json").read_text())
    assert field.report["epe_x1e4"] == cli_report["epe_x1e4"]
    assert field.report["epe_per_frame_x1e4"] == cli_report["epe_per_frame_x1e4"]
    again = json.loads(subprocess.run([cli, "eval", py_run], check=True, capture_output=True).stdout)
    assert again["epe_x1e4"] == field.evaluate()["epe_x1e4"] == cli_report["epe_x1e4"]


def test_a_recipe_and_a_stop_on_convergence_go_into_the_run_config(clip, tmp_path):
    field = doma.fit(
        clip, reg="h", recipe="fast", iters=6, until_converged=2, progress=False, out=tmp_path / "run"
    )
    fit = json.loads((tmp_path / "run" / "config.json").read_text())["fit"]
    assert fit["recipe"] == "fast"
    assert fit["schedule"]["decay"] == "cosine" and fit["schedule"]["iterations"] == 6
    assert fit["until_converged"]["patience"] == 2
    assert fit["points_per_step"] is not None
    assert field.config["fit"] == fit
    assert np.isfinite(field.report["epe_x1e4"])


def test_soap_goes_into_the_run_config_and_is_refused_without_the_fused_step(clip, tmp_path):
    assert doma.OPTIMIZERS == ("adam", "soap")
    field = doma.fit(clip, recipe="fast", optimizer="SOAP", iters=8, progress=False, out=tmp_path / "run")
    fit = json.loads((tmp_path / "run" / "config.json").read_text())["fit"]
    assert fit["soap"]["every"] == 100 and fit["step"] == "auto"
    assert np.isfinite(field.report["epe_x1e4"])
    with pytest.raises(ValueError, match="SOAP"):
        doma.fit(clip, optimizer="soap", step="composed", iters=2, progress=False)
    with pytest.raises(ValueError, match="optimizer"):
        doma.fit(clip, optimizer="lbfgs", iters=2, progress=False)


def test_a_refused_fit_leaves_every_file_of_the_folder_as_it_was(clip, tmp_path):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "tracks.npz").write_bytes(b"the user's own tracks")
    (folder / "notes.txt").write_text("kept")
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    with pytest.raises(ValueError, match="test_fraction"):
        doma.fit(clip, iters=2, progress=False, out=folder, test_fraction=2.0)
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    # A file a fit would write is refused, naming it, unless the caller says to replace it.
    with pytest.raises(FileExistsError, match="tracks.npz"):
        doma.fit(clip, iters=2, progress=False, out=folder)
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    # With overwrite=True too, a call refused after the data was written (a reference
    # frame the clip does not have) puts the user's file back.
    with pytest.raises(ValueError, match="reference frame 50"):
        doma.fit(clip, iters=2, progress=False, out=folder, overwrite=True, reference_frame=50)
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    field = doma.fit(clip, iters=2, progress=False, out=folder, overwrite=True)
    assert field.n_frames == 20 and (folder / "notes.txt").read_text() == "kept"
    assert not (folder / ".tracks.npz.replaced").exists()
    # A refused fit in a folder it made leaves no folder.
    with pytest.raises(ValueError):
        doma.fit(clip, iters=2, progress=False, out=tmp_path / "new", test_fraction=2.0)
    assert not (tmp_path / "new").exists()


def test_two_fits_into_one_folder_one_refused_the_other_fitted_to_its_own_array(clip, tmp_path):
    for attempt in range(3):
        out = tmp_path / f"race{attempt}"
        arrays = [clip, clip[::-1].copy()]
        results: list = [None, None]

        def go(i: int) -> None:
            try:
                results[i] = doma.fit(arrays[i], iters=15, progress=False, out=out)
            except Exception as e:  # noqa: BLE001 - the refusal is the result
                results[i] = e

        threads = [threading.Thread(target=go, args=(i,)) for i in range(2)]
        threads[0].start()
        time.sleep(0.05)
        threads[1].start()
        for t in threads:
            t.join()
        won = [i for i in range(2) if isinstance(results[i], doma.Field)]
        assert len(won) == 1, results
        lost = results[1 - won[0]]
        assert isinstance(lost, (OSError, FileExistsError)), lost
        assert "being fitted" in str(lost) or "already holds a run" in str(lost), lost
        # The folder holds the winner's array, and its field was fitted to it.
        stored = doma.read_tracks(out / "tracks.npz").tracks
        assert np.array_equal(stored, arrays[won[0]])
        field = results[won[0]]
        mine = np.abs(field.warp(arrays[won[0]][0], 19) - arrays[won[0]][19]).mean()
        other = np.abs(field.warp(arrays[won[0]][0], 19) - arrays[1 - won[0]][19]).mean()
        assert mine < other, (mine, other)


def test_complete_is_doma_complete_to_the_last_bit_in_the_input_units(cli, clip, tmp_path):
    # A tracker's gaps: spans hidden in a third of the tracks, one track never seen.
    observed = np.ones(clip.shape[:2], dtype=bool)
    rng = np.random.default_rng(0)
    for i in rng.choice(clip.shape[1], 120, replace=False):
        a = rng.integers(0, 15)
        observed[a : a + 5, i] = False
    observed[:, 7] = False
    tracks = np.where(observed[..., None], clip, np.nan).astype(np.float32)
    run = tmp_path / "run"
    field = doma.fit(tracks, observed, iters=20, progress=False, out=run, drop_unobserved=True)
    done = field.complete(extrapolate=True)
    subprocess.run([cli, "complete", run, "--out", tmp_path / "c.npz", "--extrapolate"], check=True, capture_output=True)
    written = np.load(tmp_path / "c.npz")
    # By default only gaps with observations on both sides are filled: the runs before a
    # track's first observation and after its last stay NaN; the rest is the same fill.
    inner = field.complete()
    seen_k = observed[:, done.kept]
    before = np.cumsum(seen_k, axis=0) == 0
    after = np.cumsum(seen_k[::-1], axis=0)[::-1] == 0
    edge = before | after
    assert edge.any() and np.isnan(inner.tracks[edge]).all()
    assert np.array_equal(inner.tracks[~edge], done.tracks[~edge])
    short = field.complete(max_gap=2)
    assert np.isnan(short.tracks[~seen_k & ~edge]).all()  # every hidden span is 5 frames
    with pytest.raises(ValueError, match="max_gap"):
        field.complete(max_gap="half a second")
    with pytest.raises(ValueError, match="no frame rate"):
        field.complete(max_gap="0.5s")
    assert np.array_equal(done.tracks, written["tracks"])
    assert np.array_equal(done.observed, written["observed"])
    assert np.array_equal(done.kept, written["kept"]) and 7 not in done.kept
    kept = done.kept
    # Observed entries as given, in the input's units; every gap filled near the truth.
    seen = observed[:, kept]
    assert np.array_equal(done.tracks[seen], clip[:, kept][seen])
    assert np.isfinite(done.tracks).all()
    gap_error = np.linalg.norm(done.tracks[~seen] - clip[:, kept][~seen], axis=-1).mean()
    assert gap_error < 5.0, gap_error  # the faerie is about 52 units tall
    # The reference frame is the most observed one, and warp takes points given there.
    k = field.reference_frame
    assert observed[:, kept].sum(1)[k] == observed[:, kept].sum(1).max()
    other = 0 if k > 9 else 19
    moved = field.warp(done.tracks[k], other)
    assert np.abs(moved - clip[other, kept]).mean() < 0.5 * np.abs(done.tracks[k] - clip[other, kept]).mean()


def test_the_doma_command_of_the_package_is_the_binary_s(cli, fitted):
    import shutil
    import sys

    command = shutil.which("doma", path=str(pathlib.Path(sys.executable).parent))
    assert command is not None, "pip install put no doma command beside the interpreter"
    run = fitted.run_dir
    ours = subprocess.run([command, "info", run], capture_output=True, text=True)
    theirs = subprocess.run([cli, "info", run], capture_output=True, text=True)
    assert (ours.returncode, ours.stdout) == (theirs.returncode, theirs.stdout) == (0, theirs.stdout)
    # Errors and bad flags exit as the binary's do, with its message.
    for args in (["info", "/nonexistent/run"], ["fit", "--iters", "0"], ["--help"], ["fit", "--help"], ["--version"]):
        ours = subprocess.run([command, *args], capture_output=True, text=True)
        theirs = subprocess.run([cli, *args], capture_output=True, text=True)
        assert (ours.returncode, ours.stdout, ours.stderr) == (theirs.returncode, theirs.stdout, theirs.stderr), args
    module = subprocess.run([sys.executable, "-m", "doma", "--version"], capture_output=True, text=True)
    assert module.stdout == theirs.stdout and module.returncode == 0
