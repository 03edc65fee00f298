"""What a tracker's user does in Python: progress outside a terminal, a [N, T, 3] array,
points given at any frame, the canonical positions, evaluation on arrays, and messages
that name this package's arguments."""

import numpy as np
import pytest

import doma


def test_a_progress_callable_sees_every_iteration_and_its_exception_stops_the_fit(clip, tmp_path):
    seen = []
    doma.fit(clip[:6], iters=4, progress=seen.append)
    assert [p.iteration for p in seen] == [1, 2, 3, 4]
    assert all(isinstance(p, doma.FitProgress) and p.iterations == 4 and p.loss > 0 for p in seen)
    assert seen[0].epe is None and seen[-1].seconds >= seen[0].seconds

    class Enough(Exception):
        pass

    def stop(p):
        if p.iteration == 2:
            raise Enough("seen enough")

    run = tmp_path / "run"
    with pytest.raises(Enough, match="seen enough") as raised:
        doma.fit(clip[:6], iters=5, progress=stop, out=run)
    assert any("doma.resume" in note for note in getattr(raised.value, "__notes__", []))
    # The checkpoint was saved as for Ctrl-C: the fit resumes to its end.
    field = doma.resume(run, progress=False)
    assert field.report["iterations"] == 5


def test_progress_outside_a_terminal_is_plain_lines_on_sys_stderr(clip, capsys):
    doma.fit(clip[:6], iters=20, progress=True)
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("doma: iteration")]
    assert [line.split()[2] for line in lines] == [f"{k}/20" for k in range(2, 21, 2)], lines


def test_an_n_t_3_array_is_refused_or_read_with_time_axis(clip):
    # 366 tracks of 20 frames, track-major: neighbouring frames are close, tracks are not.
    n_t = np.ascontiguousarray(clip.transpose(1, 0, 2))
    with pytest.raises(ValueError, match=r"look like \[N, T, 3\].*time_axis=1"):
        doma.fit(n_t, iters=2, progress=False)
    a = doma.fit(n_t, time_axis=1, iters=2, progress=False)
    b = doma.fit(clip, iters=2, progress=False)
    assert (a.n_frames, a.n_tracks) == (20, 366)
    assert np.array_equal(a.warp(clip[0], 5), b.warp(clip[0], 5))
    # The shipped clip itself, as [T, N, 3], is not mistaken for [N, T, 3].
    assert b.n_frames == 20


def test_points_given_at_any_frame_are_brought_back_to_the_reference(fitted, clip):
    k = fitted.reference_frame
    assert fitted.config["reference_frame"] == k == 0
    _, scale = fitted.normalisation
    # Points between the tracks: each vertex moved by 1 % of the scale.
    x = clip[k, :50] + np.random.default_rng(1).normal(scale=0.01 * scale, size=(50, 3)).astype(np.float32)
    at_7 = fitted.warp(x, 7)
    back = fitted.to_reference(at_7, 7)
    assert np.abs(fitted.warp(back, 7) - at_7).max() <= 1e-4 * scale
    moved = fitted.warp(at_7, [3, 12], from_frame=7)
    assert np.abs(moved - fitted.warp(back, [3, 12])).max() < 1e-5 * scale * 100
    assert np.array_equal(fitted.warp(x, 5, from_frame=k), fitted.warp(x, 5))


def test_the_canonical_positions_are_in_the_data_units(fitted, clip):
    canonical = fitted.canonical
    assert canonical.shape == (366, 3) and canonical.dtype == np.float32
    # Complete data: each track's own point at the reference frame, up to the round trip
    # through the normalisation.
    assert np.allclose(canonical, clip[fitted.reference_frame], atol=1e-4)


def test_evaluate_takes_tracks_and_matches_the_report(fitted, clip):
    every = doma.Tracks(tracks=clip, observed=np.ones(clip.shape[:2], bool), faces=None, weights=None)
    on_tracks = fitted.evaluate(every)
    assert on_tracks["epe_x1e4"] == pytest.approx(fitted.report["epe_x1e4"], rel=1e-6)
    # Entries it does not observe are not counted, whatever they hold.
    part = np.ones(clip.shape[:2], bool)
    part[::2, ::2] = False
    garbage = np.where(part[..., None], clip, 1e6).astype(np.float32)
    a = fitted.evaluate(doma.Tracks(tracks=garbage, observed=part, faces=None, weights=None))
    assert a["epe_x1e4"] < 10 * on_tracks["epe_x1e4"]


def test_counts_are_named_as_counts(fitted):
    assert (fitted.n_frames, fitted.n_tracks) == (20, 366)
    with pytest.warns(DeprecationWarning, match="n_frames"):
        assert fitted.frames == 20
    with pytest.warns(DeprecationWarning, match="n_tracks"):
        assert fitted.tracks == 366


def test_messages_name_the_arguments_not_the_command_line_flags(clip):
    observed = np.ones(clip.shape[:2], bool)
    observed[:, 3] = False
    with pytest.raises(ValueError) as raised:
        doma.fit(np.where(observed[..., None], clip, np.nan), observed, iters=1, progress=False)
    message = str(raised.value)
    assert "drop_unobserved=" in message and "--" not in message, message


def test_choices_are_read_in_any_case_everywhere(clip, tmp_path):
    small = clip[:4]
    a = doma.fit(small, iters=1, progress=False, variant="SE3", backend="FLEX", jacobian="Analytic", recipe="Paper")
    b = doma.fit(small, iters=1, progress=False, variant="se3")
    assert a.model == b.model == "SE(3)"
    assert np.array_equal(a.warp(small[0], 2), b.warp(small[0], 2))
    from conftest import ROOT

    seq = doma.read_tracks(ROOT / "data" / "md2_faerie.traj", layout=None, frame=None)
    path = tmp_path / "t.npz"
    np.savez(path, tracks=seq.tracks[:3], observed=np.ones(seq.tracks[:3].shape[:2], bool))
    assert doma.read_tracks(path, layout="MASKED").tracks.shape == (3, 366, 3)
    run = tmp_path / "run"
    doma.fit(small, iters=1, progress=False, out=run)
    assert doma.load(run, backend="Flex").backend == "flex"


def test_anything_numpy_reads_is_taken_as_an_array(clip):
    class Tensorish:
        """What a CPU PyTorch tensor offers NumPy: the __array__ protocol."""

        def __init__(self, a):
            self.a = a

        def __array__(self, dtype=None, copy=None):
            return self.a if dtype is None else self.a.astype(dtype)

    small = clip[:4]
    a = doma.fit(Tensorish(small), iters=1, progress=False)
    b = doma.fit(small, iters=1, progress=False)
    assert np.array_equal(a.warp(Tensorish(small[0]), 3), b.warp(small[0], 3))
