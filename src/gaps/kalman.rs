//! Burke & Lasenby's low-dimensional Kalman smoother (J. Biomech. 49(9), 2016), the
//! filler motion-capture users run from pyCGM2: the markers' coordinates are a point in
//! the span of their principal components, which follows a random walk; a Kalman filter
//! and a Rauch–Tung–Striebel smoother estimate it from the coordinates seen at each frame.
//!
//! It follows pyCGM2's `LowDimensionalKalmanFilterProcedure` step by step, with its
//! parameters (`tol = 0.01`, `σ_R = 10⁻³ mm²`, an initial covariance of `10¹² I`), so that
//! its fills match that implementation's. The gain is computed in the information form,
//! `P⁺ = (P⁻¹ + Hᵀ H / σ_R)⁻¹`, the same estimate with `d × d` solves in place of one of
//! the size of the observed coordinates.

// Index loops over small matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use super::marked::Marked;
use crate::numeric::eigen::principal_components;

/// The share of the singular values' sum that the components leave out (pyCGM2's `tol`).
pub const KALMAN_TOLERANCE: f64 = 1e-2;

/// The observation noise `σ_R`, in square millimetres (pyCGM2's `sigR`).
pub const KALMAN_OBSERVATION_NOISE_MM2: f64 = 1e-3;

/// The initial state covariance, `10¹² I` (pyCGM2's).
const INITIAL_COVARIANCE: f64 = 1e12;

/// The largest spread (in the data's units) of tracks read as metres; tracks that spread
/// further are read as millimetres, a C3D's usual unit. The smoother's `σ_R` is a length
/// squared and Gløersen's `σ` a length, so both need the unit.
pub const METRES_UP_TO: f64 = 20.0;

impl Marked<'_> {
    /// The Burke–Lasenby fill `[T, N, 3]` (observed entries as they are), or `None` where
    /// it cannot run: fewer than two frames see every track that is ever seen (its
    /// components come from those frames), or one component already holds all but
    /// [`KALMAN_TOLERANCE`] of the singular values. Tracks never seen keep whatever they
    /// hold.
    pub fn kalman(&self) -> Option<Vec<f32>> {
        let (t, n) = (self.frames, self.points);
        let tracks = self.seen_tracks();
        let cols = 3 * tracks.len();
        let full: Vec<usize> = (0..t)
            .filter(|&k| tracks.iter().all(|&i| self.seen(k, i)))
            .collect();
        if cols == 0 || full.len() < 2 {
            return None;
        }
        let unit = self.millimetres_per_unit();
        let value = |k: usize, c: usize| self.at(k, tracks[c / 3])[c % 3] as f64 * unit;
        let (mean, v) = components(&full, cols, &value)?;
        // v[j][c]: component j's loading on column c.
        let (v, d) = (&v[..], v.len());
        let q = random_walk_covariance(&full, &value, v, cols);
        let sigma = KALMAN_OBSERVATION_NOISE_MM2;

        // Hᵀ H / σ of the coordinates seen at a frame: the same for a run of frames that
        // see the same tracks, so it is summed once per run.
        let seen_at = |k: usize| -> Vec<bool> { tracks.iter().map(|&i| self.seen(k, i)).collect() };
        let information = |seen: &[bool]| information(v, cols, seen, sigma);
        let step = |cov: &[f64], h: &[f64]| covariance_step(cov, &q, h, d);
        // The smoother's gains, `d × d` a frame, would hold many times the data on a long
        // recording: the forward pass keeps the covariance every `block` frames, and the
        // backward pass recomputes a block's gains from it (the same operations, so the
        // same gains to the bit).
        let block = (t as f64).sqrt().ceil().max(1.0) as usize;
        let mut checkpoints = Vec::with_capacity(t.div_ceil(block));
        let mut states = Vec::with_capacity(t);
        let mut state = vec![0f64; d];
        let mut cov = scaled_identity(d, INITIAL_COVARIANCE);
        let (mut seen, mut h) = (Vec::new(), Vec::new());
        for k in 0..t {
            if k % block == 0 {
                checkpoints.push(cov.clone());
            }
            let now = seen_at(k);
            if k == 0 || now != seen {
                h = information(&now);
                seen = now;
            }
            cov = step(&cov, &h)?.0;
            // x += P b, b = Hᵀ (z − H x − m) / σ.
            let mut b = vec![0f64; d];
            for c in (0..cols).filter(|&c| seen[c / 3]) {
                let innovation =
                    value(k, c) - mean[c] - (0..d).map(|j| v[j][c] * state[j]).sum::<f64>();
                for i in 0..d {
                    b[i] += v[i][c] * innovation / sigma;
                }
            }
            for i in 0..d {
                state[i] += (0..d).map(|j| cov[i * d + j] * b[j]).sum::<f64>();
            }
            states.push(state.clone());
        }
        // Backward, block by block from the last, frame by frame from the second-to-last:
        // x_k += G_k (x_{k+1} − x̂_k), the prediction of k + 1 being the filtered x̂_k, with
        // the gain `G_k = P_k P⁻_k⁻¹` as pyCGM2 smooths (the textbook Rauch–Tung–Striebel
        // gain has `P⁻_{k+1}`; the two differ by ~10⁻⁴ mm on the shipped knee recording,
        // and this follows the implementation users run).
        let mut smoothed = states.clone();
        for (b, checkpoint) in checkpoints.iter().enumerate().rev() {
            let frames = b * block..((b + 1) * block).min(t);
            let mut gains = Vec::with_capacity(frames.len());
            let mut cov = checkpoint.clone();
            for k in frames.clone() {
                let now = seen_at(k);
                if k == frames.start || now != seen {
                    h = information(&now);
                    seen = now;
                }
                let (filtered, inverse) = step(&cov, &h)?;
                gains.push(mat_mul(&filtered, &inverse, d));
                cov = filtered;
            }
            for k in frames.clone().rev().filter(|&k| k + 1 < t) {
                let gain = &gains[k - frames.start];
                let step: Vec<f64> = (0..d).map(|j| smoothed[k + 1][j] - states[k][j]).collect();
                for i in 0..d {
                    smoothed[k][i] += (0..d).map(|j| gain[i * d + j] * step[j]).sum::<f64>();
                }
            }
        }
        let mut out = self.positions.to_vec();
        for k in 0..t {
            for c in 0..cols {
                let i = tracks[c / 3];
                if !self.seen(k, i) {
                    let y = mean[c] + (0..d).map(|j| v[j][c] * smoothed[k][j]).sum::<f64>();
                    out[3 * (k * n + i) + c % 3] = (y / unit) as f32;
                }
            }
        }
        Some(out)
    }

    /// Millimetres per unit of the tracks: 1000 when they spread at most
    /// [`METRES_UP_TO`] (metres), else 1.
    pub(super) fn millimetres_per_unit(&self) -> f64 {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for k in 0..self.frames {
            for i in 0..self.points {
                if self.seen(k, i) {
                    for (c, p) in self.at(k, i).into_iter().enumerate() {
                        lo[c] = lo[c].min(p as f64);
                        hi[c] = hi[c].max(p as f64);
                    }
                }
            }
        }
        let spread = (0..3).map(|c| hi[c] - lo[c]).fold(0f64, f64::max);
        if spread <= METRES_UP_TO { 1000.0 } else { 1.0 }
    }
}

/// `Q = V diag(σ) Vᵀ`, `σ` the standard deviation (`ddof = 0`) of each column's steps
/// between consecutive rows of the fully seen frames, as pyCGM2 has it.
fn random_walk_covariance(
    full: &[usize],
    value: &impl Fn(usize, usize) -> f64,
    v: &[Vec<f64>],
    cols: usize,
) -> Vec<f64> {
    let steps = (full.len() - 1) as f64;
    let deviation: Vec<f64> = (0..cols)
        .map(|c| {
            let diffs: Vec<f64> = full
                .windows(2)
                .map(|w| value(w[1], c) - value(w[0], c))
                .collect();
            let mean = diffs.iter().sum::<f64>() / steps;
            (diffs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / steps).sqrt()
        })
        .collect();
    let d = v.len();
    let mut q = vec![0f64; d * d];
    for i in 0..d {
        for j in 0..d {
            q[i * d + j] = (0..cols).map(|c| v[i][c] * deviation[c] * v[j][c]).sum();
        }
    }
    q
}

fn scaled_identity(d: usize, s: f64) -> Vec<f64> {
    let mut m = vec![0f64; d * d];
    for i in 0..d {
        m[i * d + i] = s;
    }
    m
}

fn mat_mul(a: &[f64], b: &[f64], d: usize) -> Vec<f64> {
    let mut out = vec![0f64; d * d];
    for i in 0..d {
        for k in 0..d {
            let aik = a[i * d + k];
            for j in 0..d {
                out[i * d + j] += aik * b[k * d + j];
            }
        }
    }
    out
}

/// The inverse of a symmetric positive definite `[d, d]`, by Cholesky; `None` if it is
/// not positive definite.
fn spd_inverse(a: &[f64], d: usize) -> Option<Vec<f64>> {
    let mut l = vec![0f64; d * d];
    for i in 0..d {
        for j in 0..=i {
            let s = a[i * d + j] - (0..j).map(|k| l[i * d + k] * l[j * d + k]).sum::<f64>();
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i * d + i] = s.sqrt();
            } else {
                l[i * d + j] = s / l[j * d + j];
            }
        }
    }
    // L⁻¹ by forward substitution, then A⁻¹ = L⁻ᵀ L⁻¹.
    let mut li = vec![0f64; d * d];
    for c in 0..d {
        for i in c..d {
            let s = if i == c { 1.0 } else { 0.0 }
                - (c..i).map(|k| l[i * d + k] * li[k * d + c]).sum::<f64>();
            li[i * d + c] = s / l[i * d + i];
        }
    }
    let mut inv = vec![0f64; d * d];
    for i in 0..d {
        for j in 0..=i {
            let s: f64 = (i..d).map(|k| li[k * d + i] * li[k * d + j]).sum();
            inv[i * d + j] = s;
            inv[j * d + i] = s;
        }
    }
    Some(inv)
}

/// `Hᵀ H / σ` (`[d, d]`) of the coordinates seen at a frame: the columns `c` of `cols`
/// whose track `c / 3` is `seen`, `v` the `d` components' loadings.
fn information(v: &[Vec<f64>], cols: usize, seen: &[bool], sigma: f64) -> Vec<f64> {
    let d = v.len();
    let mut h = vec![0f64; d * d];
    for c in (0..cols).filter(|&c| seen[c / 3]) {
        for i in 0..d {
            for j in 0..d {
                h[i * d + j] += v[i][c] * v[j][c] / sigma;
            }
        }
    }
    h
}

/// The covariance through one frame: the filtered `P` from the last one's `cov`, and the
/// inverse of the predicted `P⁻ = P + Q`, with `h` the frame's information. The gains
/// depend on nothing else.
fn covariance_step(cov: &[f64], q: &[f64], h: &[f64], d: usize) -> Option<(Vec<f64>, Vec<f64>)> {
    let predicted: Vec<f64> = cov.iter().zip(q).map(|(p, q)| p + q).collect();
    let inverse = spd_inverse(&predicted, d)?;
    let a: Vec<f64> = inverse.iter().zip(h).map(|(p, h)| p + h).collect();
    Some((spd_inverse(&a, d)?, inverse))
}

/// The mean of the `cols` columns over the frames `full` that see every track, and the
/// principal components kept: those whose singular values reach all but
/// [`KALMAN_TOLERANCE`] of their sum (`None` where one component already does).
fn components(
    full: &[usize],
    cols: usize,
    value: &dyn Fn(usize, usize) -> f64,
) -> Option<(Vec<f64>, Vec<Vec<f64>>)> {
    let mut mean = vec![0f64; cols];
    for &k in full {
        for c in 0..cols {
            mean[c] += value(k, c) / full.len() as f64;
        }
    }
    let centred: Vec<f64> = full
        .iter()
        .flat_map(|&k| (0..cols).map(move |c| (k, c)))
        .map(|(k, c)| value(k, c) - mean[c])
        .collect();
    // Householder and QL: to rounding (the components kept reach down to singular
    // values ~10³ times smaller than the first), in a fraction of Jacobi's time on
    // hundreds of columns. numpy's singular values: at most min(frames, columns).
    let pca = principal_components(&centred, full.len(), cols, None);
    let total: f64 = pca.singular.iter().sum();
    let mut held = 0f64;
    let d = pca.singular.iter().position(|s| {
        held += s;
        held / total > 1.0 - KALMAN_TOLERANCE
    })?;
    if d == 0 {
        return None;
    }
    let mut vectors = pca.vectors;
    vectors.truncate(d);
    Some((mean, vectors))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaps::fillers::worst_error;

    #[test]
    fn spd_inverse_inverts_a_hand_solved_matrix() {
        // [[4, 2], [2, 3]]⁻¹ = [[3, −2], [−2, 4]] / 8.
        let inv = spd_inverse(&[4.0, 2.0, 2.0, 3.0], 2).unwrap();
        for (got, want) in inv.iter().zip([0.375, -0.25, -0.25, 0.5]) {
            assert!((got - want).abs() < 1e-15, "{inv:?}");
        }
        assert!(spd_inverse(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }

    /// Four markers share two motions (x and y), a fifth has a small one of its own (z):
    /// pyCGM2's rule keeps the components before the one that crosses 99 % of the
    /// singular values, here the two shared ones, so a hidden marker of the four is
    /// filled from the other three to within millimetres, where a line misses by 7 cm.
    #[test]
    fn a_marker_is_filled_from_the_motion_it_shares() {
        let (t, n) = (60, 5);
        let offsets = [
            [0.0, 0.0, 0.0],
            [0.3, 0.0, 0.0],
            [0.0, 0.2, 0.1],
            [0.1, 0.1, 0.4],
            [0.5, 0.5, 0.5],
        ];
        let mut positions = Vec::new();
        for k in 0..t {
            let s = k as f32 / 10.0;
            for (i, o) in offsets.iter().enumerate() {
                let moved = if i < 4 {
                    [o[0] + 0.5 * s.sin(), o[1] + 0.3 * (0.7 * s).cos(), o[2]]
                } else {
                    [o[0], o[1], o[2] + 0.1 * (1.3 * s).sin()]
                };
                positions.extend(moved);
            }
        }
        let mut observed = vec![true; t * n];
        for k in 20..35 {
            observed[k * n + 2] = false;
        }
        let marked = Marked::new(t, n, &positions, &observed);
        let fill = marked.kalman().unwrap();
        let line = marked.linear();
        let error = |f: &[f32]| worst_error(f, &positions, n, 2, 20..35);
        assert!(error(&fill) < 0.005, "{}", error(&fill));
        assert!(error(&line) > 0.05, "{}", error(&line));
        // Seen entries are kept as they are.
        assert_eq!(fill[..3 * n * 20], positions[..3 * n * 20]);
    }

    #[test]
    fn it_refuses_tracks_with_no_fully_seen_frames() {
        let positions = vec![0.5f32; 3 * 4 * 2];
        let observed = [true, false, false, true, true, false, false, true];
        assert!(Marked::new(4, 2, &positions, &observed).kalman().is_none());
    }
}
