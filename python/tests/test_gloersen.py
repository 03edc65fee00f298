"""Gløersen & Federolf's PCA fill (`doma.fill(..., "gloersen")`) against the published
method: `PredictMissingMarkers.m` (Gløersen Ø, Federolf P (2016), PLoS ONE 11(3):e0152616,
its supplement), strategy R2 with its defaults, transcribed below into numpy statement by
statement. No implementation of it installs from PyPI, so the reference is this
transcription: numpy's SVD (LAPACK) where doma has Jacobi rotations of a Gram matrix, the
MATLAB's matrix algebra where doma folds it into one `[columns, 3]` map per marker."""

import pathlib

import numpy as np
import pytest

import doma
from conftest import assert_published_fill

ROOT = pathlib.Path(__file__).resolve().parents[2]
RIGHT_KNEE = ROOT / "data" / "mocap" / "right_knee.c3d"


def predict_missing_markers(data_gaps, weight_scale=200.0, mm_weight=0.02,
                            distal_threshold=0.5, min_cum_sv=0.99):
    """`PredictMissingMarkers(Data_gaps, 'Algorithm', 2)`: `data_gaps` [frames, 3·markers]
    in mm, NaN where unobserved."""
    data_gaps = np.array(data_gaps, dtype=np.float64)
    columns = data_gaps.shape[1]
    columns_with_gaps = np.flatnonzero(np.isnan(data_gaps).any(axis=0))
    markers_with_gaps = columns_with_gaps[2::3] // 3
    # Subtract the mean trajectory of the markers without gaps.
    without = np.delete(data_gaps, columns_with_gaps, axis=1)
    mean_trajectory = [without[:, a::3].mean(axis=1) for a in range(3)]
    for a in range(3):
        data_gaps[:, a:columns:3] -= mean_trajectory[a][:, None]
    filled = data_gaps.copy()

    def distance2marker(data, cols):
        n, m = data.shape
        gapped = cols[2::3] // 3
        xyz = data.reshape(n, m // 3, 3)
        dist = np.linalg.norm(xyz[:, gapped, None, :] - xyz[:, None, :, :], axis=-1)
        return np.nanmean(dist, axis=0)

    def pca(data):
        _, sqrt_ev, vt = np.linalg.svd(data / np.sqrt(data.shape[0] - 1), full_matrices=False)
        return vt.T, sqrt_ev

    def reconstruct(data2reconstruct):
        cols = np.flatnonzero(np.isnan(data2reconstruct).any(axis=0))
        weights = distance2marker(data_gaps, cols)
        weights = weights.min(axis=0) if weights.shape[0] > 1 else weights[0]
        weights = np.exp(-weights**2 / (2 * weight_scale**2))
        weights[cols[2::3] // 3] = mm_weight
        weights = np.repeat(weights, 3)
        m_zeros = data2reconstruct.copy()
        m_zeros[:, cols] = 0
        n_no_gaps = data2reconstruct[~np.isnan(data2reconstruct).any(axis=1)]
        n_zeros = n_no_gaps.copy()
        n_zeros[:, cols] = 0
        mean_no_gaps = n_no_gaps.mean(axis=0)
        mean_zeros = n_zeros.mean(axis=0)
        stdev = n_no_gaps.std(axis=0)
        stdev[stdev == 0] = 1
        m_zeros = (m_zeros - mean_zeros) / stdev * weights
        n_no_gaps = (n_no_gaps - mean_no_gaps) / stdev * weights
        n_zeros = (n_zeros - mean_zeros) / stdev * weights
        pc_no_gaps, sv_no_gaps = pca(n_no_gaps)
        pc_zeros, sv_zeros = pca(n_zeros)
        n_eig = 1 + max(np.flatnonzero(np.cumsum(sv_no_gaps) >= min_cum_sv * sv_no_gaps.sum())[0],
                        np.flatnonzero(np.cumsum(sv_zeros) >= min_cum_sv * sv_zeros.sum())[0])
        pc_no_gaps, pc_zeros = pc_no_gaps[:, :n_eig], pc_zeros[:, :n_eig]
        # The one departure: the product below changes when a vector of pc_zeros alone
        # changes sign, so its value rests on the SVD's signs, which LAPACK leaves to its
        # algorithm (up to 0.18 mm apart on these fills). doma fixes them, each of
        # pc_zeros along its counterpart of pc_no_gaps; so does the reference.
        pc_zeros = pc_zeros * np.where(np.sum(pc_no_gaps * pc_zeros, axis=0) < 0, -1.0, 1.0)
        transformation = pc_no_gaps.T @ pc_zeros
        reconstructed = m_zeros @ pc_zeros @ transformation @ pc_no_gaps.T
        reconstructed = mean_no_gaps + reconstructed * stdev / weights
        out = data2reconstruct.copy()
        out[:, columns_with_gaps] = reconstructed[:, columns_with_gaps]
        return out

    for i in markers_with_gaps:
        own = slice(3 * i, 3 * i + 3)
        distances = distance2marker(data_gaps, np.arange(3 * i, 3 * i + 3))[0]
        thresh = distal_threshold * distances.mean()
        cols2zero = np.flatnonzero((np.repeat(distances, 3) > thresh) & np.isnan(data_gaps).any(axis=0))
        removed = data_gaps.copy()
        removed[:, cols2zero] = 0
        removed[:, own] = data_gaps[:, own]
        gapped_i = np.flatnonzero(np.isnan(data_gaps[:, 3 * i + 2]))
        for ii in markers_with_gaps[markers_with_gaps != i]:
            if np.isnan(removed[gapped_i, 3 * ii + 2]).any():
                removed[:, 3 * ii : 3 * ii + 3] = 0
        frames_no_gaps = np.flatnonzero(~np.isnan(removed).any(axis=1))
        frames2rec = np.flatnonzero(np.isnan(data_gaps[:, 3 * i + 2]))
        rows = np.concatenate([frames_no_gaps, frames2rec])
        fill_rows = np.arange(len(frames_no_gaps), len(rows))
        filled[frames2rec, own] = reconstruct(removed[rows])[fill_rows, own]
    for a in range(3):
        filled[:, a:columns:3] += mean_trajectory[a][:, None]
    return filled


def hidden(gaps):
    """right_knee (mm, every marker seen in every frame) with `gaps`, (marker, start,
    frames) each, hidden."""
    seq = doma.read_tracks(RIGHT_KNEE)
    tracks, observed = seq.tracks.copy(), seq.observed.copy()
    for marker, start, length in gaps:
        observed[start : start + length, marker] = False
    return tracks, observed


def reference(tracks, observed, scale=1.0):
    raw = tracks.astype(np.float64) * scale
    raw[~observed] = np.nan
    return predict_missing_markers(raw.reshape(len(raw), -1)).reshape(raw.shape)


CASES = {
    # One marker, 1 s at 100 Hz.
    "one": [(40, 300, 100)],
    # Three at once, the same second: each is filled with the other two left out.
    "three_at_once": [(3, 300, 100), (40, 300, 100), (60, 300, 100)],
    # Gaps that do not overlap, near and far markers kept or left out by distance.
    "apart": [(3, 100, 60), (4, 400, 80), (40, 250, 100), (60, 700, 50)],
}


@pytest.mark.parametrize("case", CASES)
def test_gloersen_fill_is_the_published_r2_to_float32_rounding(case):
    tracks, observed = hidden(CASES[case])
    truth = doma.read_tracks(RIGHT_KNEE).tracks
    assert_published_fill("gloersen", reference(tracks, observed), tracks, observed, truth)


def test_gloersen_fill_of_tracks_in_metres_weighs_distances_in_millimetres():
    """σ = 200 mm: tracks in metres (a spread under 20 units) are weighted as the same
    tracks in millimetres."""
    tracks, observed = hidden(CASES["one"])
    metres = (tracks / 1000).astype(np.float32)
    ours = doma.fill(metres, observed, "gloersen", extrapolate=True)
    theirs = reference(metres, observed, scale=1000.0) / 1000.0
    gap = ~observed
    np.testing.assert_array_max_ulp(ours[gap], theirs[gap].astype(np.float32), maxulp=1)


def test_gloersen_fill_where_every_marker_has_a_gap_is_the_linear_fill():
    """The moving frame is the mean of the markers without a gap: with none, the MATLAB
    returns NaN; doma gives the linear fill, as `kalman` does where it cannot run."""
    tracks, observed = hidden([(m, 10 + (m % 5) * 3, 2) for m in range(tracks_count())])
    np.testing.assert_array_equal(
        doma.fill(tracks, observed, "gloersen"), doma.fill(tracks, observed, "linear")
    )


def tracks_count():
    return doma.read_tracks(RIGHT_KNEE).tracks.shape[1]
