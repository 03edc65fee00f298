//! Gløersen & Federolf's PCA fill (PLoS ONE 11(3):e0152616, 2016), strategy R2 of their
//! `PredictMissingMarkers`, the filler motion-capture users run from the authors' MATLAB
//! and from the toolboxes that ship it. Each marker with gaps is filled on its own, from
//! the principal components of the frames that see it and its neighbours (Federolf 2013,
//! PLoS ONE 8(10):e78689, eq. 1):
//!
//! 1. The coordinates are taken relative to the mean of the markers that have no gap, a
//!    frame moving with the subject.
//! 2. The markers far from the gapped one (beyond half the mean distance to all markers)
//!    that have gaps of their own are left out, and so is every marker with a gap in one of
//!    its gap frames.
//! 3. The frames that see every marker left in give the principal components twice: of
//!    the coordinates as they are (`V`), and with the gapped marker's zeroed (`V₀`). Each
//!    coordinate is standardised, then weighted by `exp(−d² / 2σ²)` for `d` its marker's
//!    mean distance to the gapped one (`σ = 200 mm`), and by 0.02 for the gapped marker.
//!    Both keep as many components as reach 99 % of the singular values' sum.
//! 4. A gap frame, its gapped marker zeroed, is projected on `V₀`, carried into `V` by
//!    `T = Vᵀ V₀`, and read back: `R = M₀ V₀ T Vᵀ`, unweighted and unstandardised.
//!
//! It follows the published MATLAB line by line, with its defaults, so that its fills
//! match that function's. Where the MATLAB returns NaN it does something that can be used:
//! a marker never seen with the gapped one counts as far (its distance is unknown), and a
//! marker whose neighbours share fewer than two fully seen frames is filled linearly.

// Index loops over small matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use super::marked::Marked;
use crate::numeric::eigen::principal_spectrum;

/// `σ` of the distance weights, in millimetres (the MATLAB's `WeightScale`).
pub const GLOERSEN_WEIGHT_SCALE_MM: f64 = 200.0;

/// The weight on the gapped marker's coordinates (`MMweight`).
pub const GLOERSEN_MISSING_WEIGHT: f64 = 0.02;

/// The distance past which a marker with gaps is left out, relative to the gapped
/// marker's mean distance to all markers (`DistalThreshold`).
pub const GLOERSEN_DISTAL_THRESHOLD: f64 = 0.5;

/// The share of the singular values' sum that the components kept reach (`MinCumSV`).
pub const GLOERSEN_MIN_CUMULATIVE: f64 = 0.99;

impl Marked<'_> {
    /// The Gløersen–Federolf R2 fill `[T, N, 3]` (observed entries as they are), or `None`
    /// where it cannot run: no track is seen in every frame (the moving frame of step 1
    /// is their mean). Tracks never seen keep whatever they hold.
    pub fn gloersen(&self) -> Option<Vec<f32>> {
        let (t, n) = (self.frames, self.points);
        let tracks = self.seen_tracks();
        let complete: Vec<bool> = tracks
            .iter()
            .map(|&i| (0..t).all(|k| self.seen(k, i)))
            .collect();
        let anchors: Vec<usize> = (0..tracks.len()).filter(|&j| complete[j]).collect();
        if anchors.is_empty() {
            return None;
        }
        let unit = self.millimetres_per_unit();
        // Step 1: every coordinate relative to the anchors' mean at its frame.
        let moving = self.anchor_mean(&tracks, &anchors);
        let relative =
            |k: usize, j: usize, a: usize| self.at(k, tracks[j])[a] as f64 - moving[k][a];

        let mut out = self.positions.to_vec();
        let mut linear: Option<Vec<f32>> = None;
        for g in (0..tracks.len()).filter(|&j| !complete[j]) {
            let seen = |k: usize, j: usize| self.seen(k, tracks[j]);
            let distance = self.mean_distances(&tracks, g);
            // Step 2. The mean runs over every marker, the gapped one's own 0 included.
            let known: Vec<f64> = distance.iter().copied().filter(|d| d.is_finite()).collect();
            let threshold =
                GLOERSEN_DISTAL_THRESHOLD * known.iter().sum::<f64>() / known.len() as f64;
            let gap_frames: Vec<usize> = (0..t).filter(|&k| !seen(k, g)).collect();
            let kept: Vec<usize> = (0..tracks.len())
                .filter(|&j| {
                    j == g
                        || complete[j]
                        || (distance[j] <= threshold && gap_frames.iter().all(|&k| seen(k, j)))
                })
                .collect();
            let full: Vec<usize> = (0..t)
                .filter(|&k| kept.iter().all(|&j| seen(k, j)))
                .collect();
            if full.len() < 2 {
                let line = linear.get_or_insert_with(|| self.linear());
                for &k in &gap_frames {
                    let e = 3 * (k * n + tracks[g]);
                    out[e..e + 3].copy_from_slice(&line[e..e + 3]);
                }
                continue;
            }
            // g's place in `kept`, which is in order and holds it.
            let p = kept.iter().filter(|&&j| j < g).count();
            let cols = 3 * kept.len();
            // Step 3: standardise (population deviation, 1 where a column is constant)
            // and weight each coordinate.
            let weight: Vec<f64> = (0..cols)
                .map(|c| match kept[c / 3] {
                    j if j == g => GLOERSEN_MISSING_WEIGHT,
                    j => {
                        let d = distance[j] * unit;
                        (-d * d / (2.0 * GLOERSEN_WEIGHT_SCALE_MM * GLOERSEN_WEIGHT_SCALE_MM)).exp()
                    }
                })
                .collect();
            let value = |k: usize, c: usize| relative(k, kept[c / 3], c % 3);
            let (mean, deviation, scaled) = standardised(&full, cols, &value, &weight);
            let gapped = 3 * p..3 * p + 3;
            // Only the components kept are found: on hundreds of columns the whole
            // eigenvector matrix would be most of the fill's cost.
            let whole = principal_spectrum(&scaled, full.len(), cols, None);
            let without = principal_spectrum(&scaled, full.len(), cols, Some(gapped));
            let kept_components = reaching(&whole.singular).max(reaching(&without.singular));
            let v = &whole.vectors(kept_components);
            let v0 = aligned(&without.vectors(kept_components), v);
            let back = reconstruction(v, &v0, kept_components, cols, p);
            for &k in &gap_frames {
                let mut filled = [0f64; 3];
                for c in (0..cols).filter(|c| c / 3 != p) {
                    let m0 = (value(k, c) - mean[c]) / deviation[c] * weight[c];
                    for a in 0..3 {
                        filled[a] += m0 * back[c][a];
                    }
                }
                let e = 3 * (k * n + tracks[g]);
                for a in 0..3 {
                    let c = 3 * p + a;
                    let y = mean[c] + filled[a] * deviation[c] / weight[c] + moving[k][a];
                    out[e + a] = y as f32;
                }
            }
        }
        Some(out)
    }

    /// Step 1's moving frame: the mean of the `anchors` (places in `tracks`, the tracks
    /// seen in every frame) at each frame.
    fn anchor_mean(&self, tracks: &[usize], anchors: &[usize]) -> Vec<[f64; 3]> {
        (0..self.frames)
            .map(|k| {
                let mut m = [0f64; 3];
                for &j in anchors {
                    for (a, p) in self.at(k, tracks[j]).into_iter().enumerate() {
                        m[a] += p as f64;
                    }
                }
                m.map(|s| s / anchors.len() as f64)
            })
            .collect()
    }

    /// Each of `tracks`' mean Euclidean distance to `tracks[g]` over the frames that see
    /// both (NaN where none does), the MATLAB's `distance2marker`.
    fn mean_distances(&self, tracks: &[usize], g: usize) -> Vec<f64> {
        tracks
            .iter()
            .map(|&j| {
                let (mut sum, mut count) = (0f64, 0usize);
                for k in 0..self.frames {
                    if self.seen(k, tracks[g]) && self.seen(k, j) {
                        let (x, y) = (self.at(k, tracks[g]), self.at(k, j));
                        sum += (0..3)
                            .map(|a| (x[a] as f64 - y[a] as f64).powi(2))
                            .sum::<f64>()
                            .sqrt();
                        count += 1;
                    }
                }
                sum / count as f64
            })
            .collect()
    }
}

/// How many of the `singular` values (largest first) reach [`GLOERSEN_MIN_CUMULATIVE`] of
/// their sum.
fn reaching(singular: &[f64]) -> usize {
    let total: f64 = singular.iter().sum();
    let mut held = 0f64;
    singular
        .iter()
        .position(|s| {
            held += s;
            held >= GLOERSEN_MIN_CUMULATIVE * total
        })
        .map_or(singular.len(), |i| i + 1)
}

/// `vectors`, each signed to point along its counterpart in `reference`. The published
/// product `V₀ (Vᵀ V₀) Vᵀ` changes when one vector of `V₀` alone changes sign (not when a
/// vector and its counterpart both do), so its value rests on the SVD's signs, which
/// LAPACK leaves to its algorithm (numpy's move this fill by up to 0.18 mm on the shipped
/// knee recording); doma fixes them.
fn aligned(vectors: &[Vec<f64>], reference: &[Vec<f64>]) -> Vec<Vec<f64>> {
    vectors
        .iter()
        .zip(reference)
        .map(|(v, r)| {
            let dot: f64 = v.iter().zip(r).map(|(a, b)| a * b).sum();
            let sign = if dot < 0.0 { -1.0 } else { 1.0 };
            v.iter().map(|x| sign * x).collect()
        })
        .collect()
}

/// Step 3 over the frames `full`: each of `cols` columns' mean and population deviation
/// (1 where a column is constant), and the frames' rows `[full, cols]` centred, scaled by
/// the deviation and weighted by `weight`.
fn standardised(
    full: &[usize],
    cols: usize,
    value: &dyn Fn(usize, usize) -> f64,
    weight: &[f64],
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let rows = full.len() as f64;
    let mean: Vec<f64> = (0..cols)
        .map(|c| full.iter().map(|&k| value(k, c)).sum::<f64>() / rows)
        .collect();
    let deviation: Vec<f64> = (0..cols)
        .map(|c| {
            let s = full
                .iter()
                .map(|&k| (value(k, c) - mean[c]).powi(2))
                .sum::<f64>();
            let d = (s / rows).sqrt();
            if d == 0.0 { 1.0 } else { d }
        })
        .collect();
    let scaled: Vec<f64> = full
        .iter()
        .flat_map(|&k| (0..cols).map(move |c| (k, c)))
        .map(|(k, c)| (value(k, c) - mean[c]) / deviation[c] * weight[c])
        .collect();
    (mean, deviation, scaled)
}

/// Step 4: B = V₀ T V_gᵀ (`[cols, 3]`), with T = Vᵀ V₀ and V_g the gapped marker's rows
/// of V (the marker at place `p`), both of `k` components, so that a frame's fill is its
/// row of M₀ times B. T's first index meets V₀'s components, as the published product has
/// it.
fn reconstruction(
    v: &[Vec<f64>],
    v0: &[Vec<f64>],
    k: usize,
    cols: usize,
    p: usize,
) -> Vec<[f64; 3]> {
    let mut transfer = vec![0f64; k * k];
    for u in 0..k {
        for w in 0..k {
            transfer[u * k + w] = (0..cols).map(|c| v[u][c] * v0[w][c]).sum();
        }
    }
    // y = T V_gᵀ (`[k, 3]`) first, then B = V₀ y.
    let y: Vec<[f64; 3]> = (0..k)
        .map(|u| {
            std::array::from_fn(|a| (0..k).map(|w| transfer[u * k + w] * v[w][3 * p + a]).sum())
        })
        .collect();
    (0..cols)
        .map(|c| std::array::from_fn(|a| (0..k).map(|u| v0[u][c] * y[u][a]).sum()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaps::fillers::worst_error;

    /// Five markers on one rigid body turning about z, a sixth (far) with a motion of its
    /// own: a hidden marker of the body is filled from the others to a few hundredths of
    /// a millimetre, where a line misses by centimetres.
    #[test]
    fn a_marker_of_a_rigid_body_is_filled_from_the_body() {
        let (t, n) = (80, 6);
        let body = [
            [0.0, 0.0, 0.0],
            [120.0, 0.0, 10.0],
            [0.0, 90.0, 40.0],
            [60.0, 60.0, 100.0],
            [-50.0, 30.0, 70.0],
        ];
        let mut positions = Vec::new();
        for k in 0..t {
            let s = k as f32 / 12.0;
            let (sin, cos) = (0.6 * s).sin_cos();
            for o in &body {
                positions.extend([
                    cos * o[0] - sin * o[1] + 300.0 * s.sin(),
                    sin * o[0] + cos * o[1],
                    o[2] + 20.0 * (1.3 * s).cos(),
                ]);
            }
            positions.extend([2000.0, 1500.0 + 40.0 * (2.0 * s).sin(), 900.0]);
        }
        let mut observed = vec![true; t * n];
        for k in 30..50 {
            observed[k * n + 3] = false;
        }
        let marked = Marked::new(t, n, &positions, &observed);
        let fill = marked.gloersen().unwrap();
        let line = marked.linear();
        let error = |f: &[f32]| worst_error(f, &positions, n, 3, 30..50);
        // The published method with its defaults: 0.03 mm here (numpy's transcription of
        // the MATLAB agrees), where the line misses by 33 mm.
        assert!(error(&fill) < 0.1, "{}", error(&fill));
        assert!(error(&line) > 30.0, "{}", error(&line));
        assert_eq!(fill[..3 * n * 30], positions[..3 * n * 30]);
    }

    #[test]
    fn it_refuses_tracks_that_all_have_gaps() {
        let positions = vec![0.5f32; 3 * 4 * 2];
        let observed = [true, false, false, true, true, false, false, true];
        assert!(
            Marked::new(4, 2, &positions, &observed)
                .gloersen()
                .is_none()
        );
    }

    /// The components keep the first that reach 99 % of the singular values' sum.
    #[test]
    fn components_keep_99_percent_of_the_singular_values() {
        // A diagonal matrix of 3 rows, Gram matrix g: singular values √(g / 2) = 10, 0.09, 0.01
        // (sum 10.1, 99 % 9.999): the first alone holds 10 ≥ 9.999.
        let x = diagonal([200.0, 0.0162, 0.0002]);
        let c = principal_spectrum(&x, 3, 3, None);
        assert_eq!(reaching(&c.singular), 1);
        // 0.5, 0.4, 0.1 (sum 1): 0.9 < 0.99 ≤ 1.0, so all three.
        let x = diagonal([0.5, 0.32, 0.02]);
        let c = principal_spectrum(&x, 3, 3, None);
        for (got, want) in c.singular.iter().zip([0.5, 0.4, 0.1]) {
            assert!((got - want).abs() < 1e-12, "{:?}", c.singular);
        }
        assert_eq!(reaching(&c.singular), 3);
    }

    /// `diag(√g)`, whose Gram matrix is `diag(g)`.
    fn diagonal(g: [f64; 3]) -> Vec<f64> {
        let mut x = vec![0f64; 9];
        for i in 0..3 {
            x[i * 4] = g[i].sqrt();
        }
        x
    }
}
