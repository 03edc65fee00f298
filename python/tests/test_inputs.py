"""What the package accepts (dtypes, layouts, masks) and what it refuses, with the message."""

import numpy as np
import pytest

import doma


def test_any_float_layout_warps_as_float32_in_c_order(fitted, clip):
    x = clip[0]
    reference = fitted.warp(x, 4)
    for variant in (
        x.astype(np.float64),
        np.asfortranarray(x),
        np.repeat(x, 2, axis=0)[::2],  # a strided view
        x.astype(np.float16).astype(np.float32),
    ):
        got = fitted.warp(variant, 4)
        if variant.dtype == np.float32 and np.array_equal(variant, x):
            assert np.array_equal(got, reference)
        else:
            np.testing.assert_allclose(got, reference, atol=0.05)
    assert fitted.warp(np.empty((0, 3)), 4).shape == (0, 3)


def test_tracks_with_a_mask_fit_and_read_back(clip, tmp_path):
    rng = np.random.default_rng(1)
    observed = rng.random(clip.shape[:2]) > 0.3
    observed[:, :] |= np.arange(clip.shape[1]) % 5 == 0  # every track seen somewhere
    tracks = np.where(observed[..., None], clip, np.nan)
    field = doma.fit(tracks, observed, iters=5, progress=False, out=tmp_path / "run")
    assert field.config["tracks"]["layout"] == "masked"
    back = doma.read_tracks(field.config["data"])
    assert np.array_equal(back.observed, observed)
    assert np.array_equal(np.isnan(back.tracks[..., 0]), ~observed)
    assert np.array_equal(back.tracks[observed], clip[observed])


def test_read_tracks_reads_every_shipped_format(tmp_path):
    from conftest import ROOT

    seq = doma.read_tracks(ROOT / "data" / "md2_faerie.traj")
    assert seq.tracks.shape == (198, 366, 3) and seq.observed.all()
    assert seq.faces is None and seq.weights is None
    np.save(tmp_path / "a.npy", seq.tracks[:3])
    assert np.array_equal(doma.read_tracks(tmp_path / "a.npy").tracks, seq.tracks[:3])


@pytest.mark.parametrize(
    "call, error, message",
    [
        (lambda c: doma.fit(c.astype(np.int32)), ValueError, "float array"),
        (lambda c: doma.fit(c[..., :2]), ValueError, r"shape \[20, 366, 2\], not \[any, any, 3\]"),
        (lambda c: doma.fit(c, np.ones((20, 366), np.uint8)), ValueError, "bool array"),
        (lambda c: doma.fit(c, np.ones((20, 365), bool)), ValueError, r"observed has shape \[20, 365\]"),
        (lambda c: doma.fit(np.where(np.arange(366)[:, None] == 9, np.nan, c)), ValueError, r"tracks\[0, 9, 0\] is NaN"),
        (lambda c: doma.fit(c, variant="affine"), ValueError, "variant: unknown variant `affine`, expected one of"),
        (lambda c: doma.fit(c, backend="cuda"), ValueError, "backend: unknown variant `cuda`, expected one of `flex`"),
        (lambda c: doma.fit(c, iters=0), ValueError, "iterations: 0 is not at least 1"),
        (lambda c: doma.fit(c, iters=10**30), ValueError, "iters: 1000000000000000000000000000000 is out of range"),
        (lambda c: doma.fit(c, iters="5"), TypeError, "iters: invalid type: string"),
        (lambda c: doma.fit(c, iter=5), TypeError, "unexpected keyword argument 'iter'"),
        (lambda c: doma.fit(c, layout="masked"), TypeError, "does not take 'layout'"),
        (lambda c: doma.fit(c, reg="e"), ValueError, "reg 'e'"),
        (lambda c: doma.fit(c, recipe="fastest"), ValueError, "recipe: unknown variant `fastest`, expected one of `paper`, `fast`, `soap`"),
        (lambda c: doma.fit(c, until_converged=0), ValueError, "until_converged: 0 is not at least 1"),
        (lambda c: doma.fit(c, robust="l2"), ValueError, "robust: `l2` is not l1"),
        (lambda c: doma.fit(c, test_fraction=1.0), ValueError, "test_fraction: `1` must be at least 0 and below 1"),
        (lambda c: doma.fit(c, test_fraction=float("nan")), ValueError, "test_fraction: nan is not a finite number"),
        (lambda c: doma.fit(c[:, :1], test_fraction=0.5), ValueError, "does not split 1 points"),
        (lambda c: doma.read_tracks("/nonexistent/x.traj"), FileNotFoundError, "/nonexistent/x.traj"),
        (lambda c: doma.read_tracks("x.npz", layout="po"), ValueError, "layout `po` is not one of plain, pointodyssey"),
        (lambda c: doma.load("/nonexistent/run", backend="cuda"), ValueError, "backend `cuda` is not one of flex, ndarray, wgpu"),
        (lambda c: doma.load("/nonexistent/run"), FileNotFoundError, "/nonexistent/run: no such run folder"),
        (lambda c: doma.load("/"), ValueError, "not a doma run folder"),
    ],
)
def test_bad_input_is_refused_with_a_clear_message(clip, call, error, message):
    with pytest.raises(error, match=message):
        call(clip)


def test_a_bad_frame_or_points_are_refused(fitted, clip):
    with pytest.raises(ValueError, match=r"frame 20 is outside the field's frames, 0 to 19"):
        fitted.warp(clip[0], 20)
    with pytest.raises(ValueError, match="t must be a frame index"):
        fitted.warp(clip[0], "3")
    with pytest.raises(ValueError, match=r"points has shape \[366\], not \[any, 3\]"):
        fitted.jacobian(clip[0, :, 0], 3)
    bad = clip[0].copy()
    bad[4, 1] = np.inf
    with pytest.raises(ValueError, match=r"points\[4, 1\] is inf"):
        fitted.warp(bad, 3)


def test_a_file_that_is_not_a_sequence_names_itself(tmp_path):
    path = tmp_path / "broken.traj"
    path.write_bytes(b"TRAJ\x01\x00")
    with pytest.raises(ValueError, match="broken.traj"):
        doma.read_tracks(path)


def test_a_fit_into_a_run_folder_is_refused(fitted, clip):
    with pytest.raises(FileExistsError, match="already holds a run"):
        doma.fit(clip, iters=1, progress=False, out=fitted.run_dir)


def test_an_option_reaches_the_run_config_as_the_cli_writes_it(clip, tmp_path):
    field = doma.fit(
        clip,
        iters=3,
        variant="se3",
        reg="h",
        robust="huber:0.02",
        seed=4,
        learning_rate=3e-4,
        progress=False,
        out=tmp_path / "r",
    )
    fit = field.config["fit"]
    assert fit["schedule"]["iterations"] == 3 and fit["seed"] == 4
    assert fit["schedule"]["learning_rate"] == 3e-4
    assert fit["model"]["doma"]["variant"] == "se3"
    assert fit["loss"]["smoothness_weight"] == 0.1
    assert fit["loss"]["data_penalty"] == {"huber": {"delta": 0.02}}
    assert doma.VARIANTS == ("trans", "se3", "scaled-se3", "affinity", "dpf")


def test_a_fit_reads_its_data_once(clip, tmp_path):
    before = doma._native.sequence_reads()
    doma.fit(clip, iters=1, progress=False, out=tmp_path / "r")
    assert doma._native.sequence_reads() - before == 1


def test_reg_is_read_like_variant_whatever_its_case(clip):
    field = doma.fit(clip, reg="H", iters=1, progress=False)
    assert field.config["fit"]["loss"]["smoothness_weight"] == 0.1


def test_a_warp_larger_than_memory_is_refused_before_it_is_copied(fitted):
    # A stride-0 view: 10^11 points that take 12 bytes of memory until copied.
    huge = np.lib.stride_tricks.as_strided(np.zeros(3, np.float32), (10**11, 3), (0, 4))
    with pytest.raises(MemoryError, match="warp of 100000000000 points at 1 frame"):
        fitted.warp(huge, 0)
    with pytest.raises(MemoryError, match="jacobian of 100000000000 points"):
        fitted.jacobian(huge, [0, 1])


def test_frame_times_larger_than_memory_are_refused_before_they_are_listed(fitted):
    # A stride-0 view: 10^9 frame times in 8 bytes, 48 GB once listed and sent to Rust.
    times = np.lib.stride_tricks.as_strided(np.zeros(1), (10**9,), (0,))
    point = np.zeros((1, 3), np.float32)
    for name, call in (("warp", fitted.warp), ("jacobian", fitted.jacobian)):
        with pytest.raises(ValueError, match=rf"{name} of 1 points at 1000000000 frame\(s\) needs \d+\.\d GiB"):
            call(point, times)
    huge = np.lib.stride_tricks.as_strided(np.zeros(3, np.float32), (10**11, 3), (0, 4))
    with pytest.raises(doma.SizeError, match="to_reference of 100000000000 points at 1 frame"):
        fitted.to_reference(huge, 3)
    with pytest.raises(ValueError, match="one frame index"):
        fitted.to_reference(point, [3, 4])


def test_a_reference_frame_where_no_track_is_seen_is_refused_and_leaves_no_folder(clip, tmp_path):
    observed = np.ones(clip.shape[:2], bool)
    observed[5] = False
    with pytest.raises(ValueError, match="reference frame 5: no track is observed there"):
        doma.fit(clip, observed, reference_frame=5, iters=1, progress=False, out=tmp_path / "run")
    assert not (tmp_path / "run").exists()
    # Frame 5 is never the default reference: the fit goes on from the most observed frame.
    field = doma.fit(clip, observed, iters=1, progress=False)
    assert field.reference_frame != 5
