"""The gap fillers of capture software, without a fit (`doma.fill`), checked against an
independent implementation: `gapfill` (PyPI, Moon Ki Jung's transcriptions of Vicon Nexus's
rigid-body fill and Qualisys's relational fill) on a gap hidden in the shipped right-knee
recording."""

import pathlib

import numpy as np
import pytest

import doma

ROOT = pathlib.Path(__file__).resolve().parents[2]
RIGHT_KNEE = ROOT / "data" / "mocap" / "right_knee.c3d"


def hidden_gap(start=200, length=60):
    """The recording in mm with its most moving marker among those seen at frames
    start - 1 ..= start + length hidden at frames start..start + length (0.6 s)."""
    seq = doma.read_tracks(RIGHT_KNEE)
    tracks, observed = seq.tracks.copy(), seq.observed.copy()
    a, b = start - 1, start + length
    seen = observed[a : b + 1].all(axis=0)
    travel = np.nansum(np.linalg.norm(np.diff(tracks[a : b + 1], axis=0), axis=2), axis=0)
    i = int(np.argmax(np.where(seen, travel, -1)))
    observed[start : start + length, i] = False
    return tracks, observed, i, a, b


def donors(tracks, observed, i, a, b, count):
    """The markers seen at every frame a..=b, nearest to marker i by the mean distance at a
    and b: the donors doma's rigid-body fill takes."""
    seen = observed[a : b + 1].all(axis=0)
    seen[i] = False
    distance = lambda f: np.linalg.norm(tracks[f].astype(np.float64) - tracks[f, i].astype(np.float64), axis=1)
    mean = (distance(a) + distance(b)) / 2
    candidates = [j for j in np.argsort(mean, kind="stable") if seen[j]]
    return candidates[:count]


def assert_is_gapfill_s(method, recover):
    """doma's `method` on the hidden gap equals gapfill's `recover` (named in its module)
    given the same three donors in the same order (the nearest first: the rigid body's
    first marker, the relational frame's origin), to one float32 ulp; observed entries
    stay as given, and the fill is far closer to the truth than a line."""
    gapfill = pytest.importorskip("gapfill.gapfill")
    tracks, observed, i, a, b = hidden_gap()
    ours = doma.fill(tracks, observed, method)
    target = tracks[:, i].astype(np.float64)
    target[~observed[:, i]] = np.nan
    cluster = np.stack([tracks[:, j].astype(np.float64) for j in donors(tracks, observed, i, a, b, 3)])
    updated, _ = getattr(gapfill, recover)(target, cluster)
    assert updated
    gap = slice(a + 1, b)
    np.testing.assert_array_max_ulp(ours[gap, i], target[gap].astype(np.float32), maxulp=1)
    assert np.array_equal(ours[observed], tracks[observed])
    truth = doma.read_tracks(RIGHT_KNEE).tracks[gap, i]
    linear = doma.fill(tracks, observed, "linear")[gap, i]
    error = np.linalg.norm(ours[gap, i] - truth, axis=1).mean()
    linear_error = np.linalg.norm(linear - truth, axis=1).mean()
    assert error < 0.5 * linear_error, (error, linear_error)


def test_rigid_body_fill_is_gapfill_s_to_float32_rounding():
    assert_is_gapfill_s("rigid_body", "fill_marker_gap_rbt")


def test_relational_fill_is_gapfill_s_to_float32_rounding():
    assert_is_gapfill_s("relational", "recover_marker_rel")


def test_every_method_fills_every_gap_and_refuses_what_it_cannot_read():
    tracks, observed, i, a, b = hidden_gap()
    for method in doma.FILLERS:
        filled = doma.fill(tracks, observed, method)
        assert filled.dtype == np.float32 and filled.shape == tracks.shape
        assert np.isfinite(filled[a + 1 : b, i]).all(), method
        assert np.array_equal(filled[observed], tracks[observed]), method
    assert set(doma.FILLERS) >= {"rigid_body", "pattern", "spline", "linear", "iterative_pca", "kalman"}
    kebab = doma.fill(tracks, observed, "rigid-body")
    assert np.array_equal(kebab, doma.fill(tracks, observed, "rigid_body"), equal_nan=True)
    with pytest.raises(ValueError, match="method 'field_fill' is not one of"):
        doma.fill(tracks, observed, "field_fill")
    poisoned = tracks.copy()
    poisoned[3, 5, 1] = np.nan
    with pytest.raises(ValueError, match=r"tracks\[3, 5, 1\] is NaN, and observed"):
        doma.fill(poisoned, observed, "spline")
    with pytest.raises(ValueError, match="bool array"):
        doma.fill(tracks, observed.astype(np.uint8), "spline")


def test_complete_with_one_method_is_that_filler_through_the_field_s_coordinates(tmp_path):
    """`Field.complete(method=...)` writes one filler alone: a classic one equals
    `doma.fill` (up to the round trip through the fit's normalised coordinates), the
    field's fill differs from doma's blend only where the blend moved away from it."""
    tracks, observed, i, a, b = hidden_gap()
    clip = slice(a - 40, b + 40)
    tracks, observed = tracks[clip], observed[clip]
    field = doma.fit(tracks, observed, iters=2, progress=False, out=tmp_path / "run", drop_unobserved=True)
    gap = ~observed & observed.any(axis=0)
    for method in ["rigid_body", "kalman", "spline"]:
        ours = field.complete(method=method).tracks
        np.testing.assert_allclose(ours[gap], doma.fill(tracks, observed, method)[gap], atol=1e-3)
        assert np.array_equal(ours[observed], tracks[observed])
    assert np.isfinite(field.complete(method="field_fill").tracks[gap]).all()
    with pytest.raises(ValueError, match="not a filler"):
        field.complete(method="nearest")


def test_a_blind_validation_fit_completes_with_every_observation_as_given(tmp_path):
    """`blind_validation=True` hides validation spans from the fit, not from the output:
    the completion gives every observation as the input holds it and fills the gap."""
    tracks, observed, i, a, b = hidden_gap()
    clip = slice(a - 40, b + 40)
    tracks, observed = tracks[clip], observed[clip]
    field = doma.fit(tracks, observed, iters=2, progress=False, drop_unobserved=True, blind_validation=True)
    done = field.complete()
    assert np.array_equal(done.tracks[observed], tracks[observed])
    gap = ~observed & observed.any(axis=0)
    assert np.isfinite(done.tracks[gap]).all()
    # The weights it used, each class's summing to 1, and what the short and the pooled
    # long gaps' weights gave held out of their choice: never worse than their best
    # filler alone there.
    blend = done.blend
    for weights in [blend["short"], blend["long"]] + [c["weights"] for c in blend.get("by_length", [])]:
        assert abs(sum(weights.values()) - 1.0) < 1e-9, blend
    held = [h for h in blend.get("held_out", []) if h is not None]
    assert held and sum(blend["validated"]) > 0, blend
    for h in held:
        assert h["best"] in doma.FILLERS and h["chosen"] <= h["best_alone"] * (1 + 1e-9), h
    alone = field.complete(method="spline").blend
    assert alone["short"]["spline"] == 1.0 and "held_out" not in alone, alone
    with pytest.raises(TypeError, match="blind_validation"):
        doma.fit(tracks, observed, iters=2, progress=False, blind_validation=0.5)


def test_three_fits_complete_with_the_median_of_their_fills(tmp_path):
    """`fits=3` fits three fields into the run folder (the others under `fits/`), and the
    completion fills each gap with the median of their fills, between theirs."""
    tracks, observed, i, a, b = hidden_gap()
    clip = slice(a - 40, b + 40)
    tracks, observed = tracks[clip], observed[clip]
    out = tmp_path / "run"
    field = doma.fit(tracks, observed, iters=2, progress=False, drop_unobserved=True, fits=3, out=out)
    assert (out / "fits" / "2" / "model.bpk").is_file() and (out / "fits" / "3" / "model.bpk").is_file()
    done = field.complete()
    assert np.array_equal(done.tracks[observed], tracks[observed])
    gap = ~observed & observed.any(axis=0)
    each = [doma.load(d).complete().tracks[gap] for d in (out / "fits" / "2", out / "fits" / "3")]
    ours = done.tracks[gap]
    assert np.isfinite(ours).all()
    # The median of three lies between the other two fits' values, whatever the third's.
    assert ((np.minimum(*each) <= ours) & (ours <= np.maximum(*each))).all()
    assert not np.array_equal(each[0], each[1])
    with pytest.raises(ValueError, match="fits"):
        doma.fit(tracks, observed, iters=2, progress=False, fits=0)


def test_fillers_are_the_command_line_s_less_the_field_s(cli):
    """`doma.FILLERS` is every filler of `doma fill -h` (made from `Filler::ALL`) but the
    field's fills, which need a fit."""
    import re
    import subprocess

    help_text = subprocess.run([str(cli), "fill", "-h"], capture_output=True, text=True, check=True).stdout
    listed = re.search(r"--method <FILLER>.*?\[possible values: ([^\]]*)\]", help_text, re.S).group(1)
    flags = [v.strip() for v in listed.split(",")]
    assert "field-fill" in flags and "field-fill-framewise" in flags
    want = [f.replace("-", "_") for f in flags if not f.startswith("field-")]
    assert list(doma.FILLERS) == want
