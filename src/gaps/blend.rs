//! doma's gap fill: the field's fill ([`transfer_residuals`], with fixed lenders and with
//! lenders chosen frame by frame) blended with the baselines ([`Marked`]), each weighted by
//! how well it fills gaps in this very data.
//!
//! No filler wins everywhere. On sparse markers the field's fill beats every baseline in
//! most cases, but a cubic spline wins short gaps of a fast, densely sampled motion; on
//! hundreds or thousands of tracks of one skinned surface the neighbours' motion does
//! better (docs/results.md, gap filling). So the weights are learned per data set: in each
//! of [`VALIDATION_FOLDS`] draws, [`VALIDATION_FRACTION`] of the observed entries are
//! hidden again, in spans as long as the data's own gaps; every filler fills them from
//! what is left, and the convex combination with the least squared error over the draws is
//! found, one for gaps of at most [`SPLINE_CARRY_FRAMES`] frames and one for longer gaps.
//! It replaces the carried fill only if it also wins cross-fitted (weights learned on the
//! other draws, judged on each draw in turn): a blend that won by chance on a few spans
//! is not used. The real gaps are then filled from every observation (docs/design.md §7).
//!
//! The field was fitted to the validation entries, so its fill is judged where it has seen
//! the answer; that favours the field's fills. The field alone is not blended for that
//! reason: judged on entries it was fitted to, it looks far better than inside a gap.

// Index loops over 6 × 6 matrices and KKT systems read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use super::baselines::Marked;
use super::{
    FieldPrediction, Lending, SPLINE_CARRY_FRAMES, borders, carry_residuals, transfer_carried,
    transfer_residuals,
};
use crate::data::tracks::validation_spans;
use serde::{Deserialize, Serialize};

/// The share of the observed entries hidden in each validation draw.
pub const VALIDATION_FRACTION: f64 = 0.1;

/// The validation draws.
pub const VALIDATION_FOLDS: usize = 3;

/// The fillers blended, in the order of [`Weights`].
pub const FILLERS: [&str; M] = [
    "carried",
    "spline",
    "neighbours",
    "low_rank",
    "linear",
    "framewise",
];

/// Each filler's index in [`FILLERS`] and in [`FillsAt::fillers`].
pub mod at {
    /// The field with the carried residual.
    pub const CARRIED: usize = 0;
    /// The spline.
    pub const SPLINE: usize = 1;
    /// The neighbours' motion (computed per entry, not per array).
    pub const NEIGHBOURS: usize = 2;
    /// The low-rank fill.
    pub const LOW_RANK: usize = 3;
    /// The linear fill.
    pub const LINEAR: usize = 4;
    /// The field's fill with lenders chosen frame by frame.
    pub const FRAMEWISE: usize = 5;
}

/// The number of fillers ([`FILLERS`]).
pub const M: usize = 6;

/// The weight of each filler, non-negative, summing to 1.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Weights {
    /// The field's fill: the field corrected by its neighbours' and the track's own
    /// residuals ([`transfer_residuals`]).
    pub carried: f64,
    /// Each track's natural cubic spline.
    pub spline: f64,
    /// The neighbours' motion.
    pub neighbours: f64,
    /// The low-rank (PCA) reconstruction.
    pub low_rank: f64,
    /// Each track's linear interpolation.
    pub linear: f64,
    /// The field's fill with its lenders chosen frame by frame among the tracks seen there
    /// ([`Lending::FrameByFrame`]; absent, so 0, in reports written before it).
    #[serde(default)]
    pub framewise: f64,
}

impl Weights {
    /// The field's carried fill alone: what is used where nothing could be validated.
    pub const CARRIED: Weights = Weights {
        carried: 1.0,
        spline: 0.0,
        neighbours: 0.0,
        low_rank: 0.0,
        linear: 0.0,
        framewise: 0.0,
    };

    fn from_array(w: [f64; M]) -> Self {
        Weights {
            carried: w[0],
            spline: w[1],
            neighbours: w[2],
            low_rank: w[3],
            linear: w[4],
            framewise: w[5],
        }
    }

    fn as_array(&self) -> [f64; M] {
        [
            self.carried,
            self.spline,
            self.neighbours,
            self.low_rank,
            self.linear,
            self.framewise,
        ]
    }
}

/// The weights a fill used, and the validation entries that chose them.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Blend {
    /// For gaps of at most [`SPLINE_CARRY_FRAMES`] frames.
    pub short: Weights,
    /// For longer gaps.
    pub long: Weights,
    /// The validation entries behind `short` and `long`, over the draws (0: that class had
    /// none and took the other's weights, or the carried fill alone if neither had any).
    pub validated: [usize; 2],
    /// Whether each class's blend beat the carried fill cross-fitted; where not, that
    /// class fills with the carried fill alone.
    pub cross_fitted: [bool; 2],
}

/// doma's fill of every unobserved entry of `positions` (`[T, N, 3]`, `observed` `[T, N]`)
/// from the field's prediction `field`: each gap filled by the blend of
/// [`FILLERS`] whose weights did best on validation spans drawn with `seed` (module docs).
/// Observed entries are returned as observed; a track never observed is left as it is.
pub fn blended_fill(
    frames: usize,
    points: usize,
    positions: &[f32],
    observed: &[bool],
    field: &FieldPrediction,
    seed: u64,
) -> (Vec<f32>, Blend) {
    let (t, n) = (frames, points);
    let classes = gap_classes(t, n, observed);
    let blend = learn(t, n, positions, observed, field, seed);
    // The entries to fill: every gap of a track observed somewhere.
    let entries: Vec<(usize, usize, bool)> = (0..t)
        .flat_map(|k| (0..n).map(move |i| (k, i)))
        .filter_map(|(k, i)| classes[k * n + i].map(|long| (k, i, long)))
        .collect();
    if blend.short == Weights::CARRIED && blend.long == Weights::CARRIED {
        return (
            transfer_residuals(t, n, positions, observed, field, Lending::Fixed),
            blend,
        );
    }
    let mut out = positions.to_vec();
    if entries.is_empty() {
        return (out, blend);
    }
    let (fills, _) = blend_at(t, n, positions, observed, field, &blend, &entries);
    for (&(k, i, _), v) in entries.iter().zip(fills) {
        let e = 3 * (k * n + i);
        out[e..e + 3].copy_from_slice(&v);
    }
    (out, blend)
}

/// The blend of every filler at `entries` `(frame, point, long)` by `blend`'s weights for
/// each entry's class, and the fillers' values there.
fn blend_at(
    t: usize,
    n: usize,
    positions: &[f32],
    observed: &[bool],
    field: &FieldPrediction,
    blend: &Blend,
    entries: &[(usize, usize, bool)],
) -> (Vec<[f32; 3]>, Candidates) {
    let candidates = Candidates::new(t, n, positions, observed, field, entries);
    let fills = entries
        .iter()
        .enumerate()
        .map(|(row, &(_, _, long))| blend.combine(long, &candidates.at(row)))
        .collect();
    (fills, candidates)
}

/// doma's fill and every filler's value at `entries` `(frame, point)`, gaps of `observed`:
/// what [`blended_fill`] gives there, without filling the other gaps. For measuring a fill
/// on held-out entries beside its parts.
pub struct FillsAt {
    /// The weights, as [`blended_fill`] learns them.
    pub blend: Blend,
    /// doma's fill at each entry.
    pub doma: Vec<[f32; 3]>,
    /// Each filler's value at each entry, in the order of [`FILLERS`].
    pub fillers: Vec<[[f32; 3]; M]>,
}

/// [`FillsAt`] of the same arguments as [`blended_fill`] and the entries to measure.
pub fn fills_at(
    frames: usize,
    points: usize,
    positions: &[f32],
    observed: &[bool],
    field: &FieldPrediction,
    seed: u64,
    entries: &[(usize, usize)],
) -> FillsAt {
    let (t, n) = (frames, points);
    let classes = gap_classes(t, n, observed);
    let blend = learn(t, n, positions, observed, field, seed);
    let entries: Vec<(usize, usize, bool)> = entries
        .iter()
        .map(|&(k, i)| (k, i, classes[k * n + i] == Some(true)))
        .collect();
    let (doma, candidates) = blend_at(t, n, positions, observed, field, &blend, &entries);
    FillsAt {
        blend,
        doma,
        fillers: candidates.values,
    }
}

impl Blend {
    /// The blend of one entry's filler values `p` by the weights of its class.
    fn combine(&self, long: bool, p: &[[f32; 3]; M]) -> [f32; 3] {
        let w = if long { self.long } else { self.short }.as_array();
        std::array::from_fn(|c| {
            (0..M)
                .filter(|&m| w[m] > 0.0)
                .map(|m| w[m] * p[m][c] as f64)
                .sum::<f64>() as f32
        })
    }
}

/// For each entry `[T, N]`: `None` if observed or of a track never observed, else whether
/// its gap is long (more than [`SPLINE_CARRY_FRAMES`] frames; a run past either end counts
/// its own length).
fn gap_classes(t: usize, n: usize, observed: &[bool]) -> Vec<Option<bool>> {
    let mut out = vec![None; t * n];
    for i in 0..n {
        let seen = |k: usize| observed[k * n + i];
        for (k, &[before, after]) in borders(seen, t).iter().enumerate() {
            if seen(k) || (before, after) == (None, None) {
                continue;
            }
            let length = match (before, after) {
                (Some(a), Some(b)) => b - a - 1,
                (Some(a), None) => t - 1 - a,
                (None, Some(b)) => b,
                (None, None) => unreachable!("skipped above"),
            };
            out[k * n + i] = Some(length > SPLINE_CARRY_FRAMES);
        }
    }
    out
}

/// The weights: in each draw, validation spans hidden and every filler filling them from
/// the rest; the least-squares convex combination per class over the draws, kept where it
/// beats the carried fill cross-fitted.
fn learn(
    t: usize,
    n: usize,
    positions: &[f32],
    observed: &[bool],
    field: &FieldPrediction,
    seed: u64,
) -> Blend {
    let carried_only = Blend {
        short: Weights::CARRIED,
        long: Weights::CARRIED,
        validated: [0, 0],
        cross_fitted: [false, false],
    };
    if t < 3 || observed.iter().all(|&o| o) {
        return carried_only;
    }
    // Per draw and class, E[m][l] = Σ (p_m − y)·(p_l − y).
    let mut grams = Vec::with_capacity(VALIDATION_FOLDS);
    let mut counts = [0usize; 2];
    for fold in 0..VALIDATION_FOLDS {
        let fold_seed = seed ^ 0x9e37_79b9_7f4a_7c15u64.wrapping_mul(fold as u64 + 1);
        let Ok(hidden) = validation_spans(t, n, observed, VALIDATION_FRACTION, fold_seed) else {
            continue;
        };
        let mut left = observed.to_vec();
        for &(k, i) in &hidden {
            left[k * n + i] = false;
        }
        // Each validation entry's class, by its gap in what is left.
        let left_classes = gap_classes(t, n, &left);
        let entries: Vec<(usize, usize, bool)> = hidden
            .iter()
            .filter_map(|&(k, i)| left_classes[k * n + i].map(|long| (k, i, long)))
            .collect();
        let mut gram = [[[0f64; M]; M]; 2];
        accumulate(
            t,
            n,
            positions,
            &left,
            field,
            &entries,
            &mut gram,
            &mut counts,
        );
        grams.push(gram);
    }
    let mut weights = [Weights::CARRIED; 2];
    let mut cross_fitted = [false; 2];
    for class in 0..2 {
        if counts[class] == 0 {
            continue;
        }
        let sum = |skip: Option<usize>| {
            let mut e = [[0f64; M]; M];
            for (f, g) in grams.iter().enumerate() {
                if Some(f) != skip {
                    for m in 0..M {
                        for l in 0..M {
                            e[m][l] += g[class][m][l];
                        }
                    }
                }
            }
            e
        };
        // Cross-fitted: each draw judged with the weights of the others.
        let (mut blended, mut carried) = (0f64, 0f64);
        for (f, g) in grams.iter().enumerate() {
            let rest = sum(Some(f));
            if rest[0][0] == 0.0 && rest.iter().flatten().all(|&v| v == 0.0) {
                continue;
            }
            let w = simplex_least_squares(&rest);
            blended += quadratic(&w, &g[class]);
            carried += g[class][0][0];
        }
        if blended < carried {
            weights[class] = Weights::from_array(simplex_least_squares(&sum(None)));
            cross_fitted[class] = true;
        }
    }
    // A class with no validation entry takes the other's weights.
    match counts {
        [0, 0] => return carried_only,
        [0, _] => (weights[0], cross_fitted[0]) = (weights[1], cross_fitted[1]),
        [_, 0] => (weights[1], cross_fitted[1]) = (weights[0], cross_fitted[0]),
        _ => {}
    }
    Blend {
        short: weights[0],
        long: weights[1],
        validated: counts,
        cross_fitted,
    }
}

/// `wᵀ E w`.
fn quadratic(w: &[f64; M], e: &[[f64; M]; M]) -> f64 {
    (0..M)
        .flat_map(|m| (0..M).map(move |l| (m, l)))
        .map(|(m, l)| w[m] * e[m][l] * w[l])
        .sum()
}

/// Adds to each class's `E[m][l] = Σ (p_m − y)·(p_l − y)` (over the entries and their
/// coordinates) the fillers' errors at `entries`, filled from the observations in `left`.
#[allow(clippy::too_many_arguments)]
fn accumulate(
    t: usize,
    n: usize,
    positions: &[f32],
    left: &[bool],
    field: &FieldPrediction,
    entries: &[(usize, usize, bool)],
    gram: &mut [[[f64; M]; M]; 2],
    counts: &mut [usize; 2],
) {
    let candidates = Candidates::new(t, n, positions, left, field, entries);
    for (row, &(k, i, long)) in entries.iter().enumerate() {
        let p = candidates.at(row);
        let e = 3 * (k * n + i);
        let d: Vec<[f64; 3]> = p
            .iter()
            .map(|pm| std::array::from_fn(|c| pm[c] as f64 - positions[e + c] as f64))
            .collect();
        if d.iter().flatten().any(|v| !v.is_finite()) {
            continue;
        }
        let g = &mut gram[usize::from(long)];
        for m in 0..M {
            for l in 0..M {
                g[m][l] += (0..3).map(|c| d[m][c] * d[l][c]).sum::<f64>();
            }
        }
        counts[usize::from(long)] += 1;
    }
}

/// The weights `w ≥ 0`, `Σ w = 1` that minimise `wᵀ E w`, for `E` the Gram matrix of the
/// fillers' errors: the exact minimum over every support (2⁶ − 1 of them), each solved
/// with its equality constraint by the KKT system `[E_S 1; 1ᵀ 0] [w; λ] = [0; 1]`.
pub(crate) fn simplex_least_squares(e: &[[f64; M]; M]) -> [f64; M] {
    let mut best = ([0f64; M], f64::INFINITY);
    for support in 1u32..(1 << M) {
        let idx: Vec<usize> = (0..M).filter(|&m| support & (1 << m) != 0).collect();
        let s = idx.len();
        // The KKT system, (s + 1) × (s + 1), augmented with its right-hand side.
        let mut a = vec![vec![0f64; s + 2]; s + 1];
        for (r, &m) in idx.iter().enumerate() {
            for (c, &l) in idx.iter().enumerate() {
                a[r][c] = e[m][l];
            }
            a[r][s] = 1.0;
        }
        for c in 0..s {
            a[s][c] = 1.0;
        }
        a[s][s + 1] = 1.0;
        let Some(x) = solve(a) else { continue };
        if x[..s].iter().any(|&w| w < -1e-12 || !w.is_finite()) {
            continue;
        }
        let mut w = [0f64; M];
        for (r, &m) in idx.iter().enumerate() {
            w[m] = x[r].max(0.0);
        }
        let total: f64 = w.iter().sum();
        w.iter_mut().for_each(|v| *v /= total);
        let objective = quadratic(&w, e);
        // Ties go to the support found first (the carried fill before the others).
        if objective < best.1 * (1.0 - 1e-12) {
            best = (w, objective);
        }
    }
    best.0
}

/// Gaussian elimination with partial pivoting on an augmented `m × (m + 1)` system; `None`
/// if it is singular.
fn solve(mut a: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    let m = a.len();
    let scale = a
        .iter()
        .flat_map(|r| r[..m].iter())
        .fold(0f64, |s, v| s.max(v.abs()));
    for col in 0..m {
        let pivot = (col..m).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[pivot][col].abs() <= 1e-12 * scale {
            return None;
        }
        a.swap(col, pivot);
        for r in 0..m {
            if r != col {
                let f = a[r][col] / a[col][col];
                if f != 0.0 {
                    for c in col..=m {
                        a[r][c] -= f * a[col][c];
                    }
                }
            }
        }
    }
    Some((0..m).map(|r| a[r][m] / a[r][r]).collect())
}

/// Every filler's value at a list of entries, filled from the observations in `observed`.
struct Candidates {
    /// Per entry, the fillers' points in the order of [`FILLERS`].
    values: Vec<[[f32; 3]; M]>,
}

impl Candidates {
    fn new(
        t: usize,
        n: usize,
        positions: &[f32],
        observed: &[bool],
        field: &FieldPrediction,
        entries: &[(usize, usize, bool)],
    ) -> Self {
        let marked = Marked::new(t, n, positions, observed);
        let carried = carry_residuals(t, n, positions, observed, field.predicted);
        let lent = |lending| transfer_carried(t, n, positions, observed, field, &carried, lending);
        let whole = [
            lent(Lending::Fixed),
            marked.spline(),
            Vec::new(),
            marked.low_rank(),
            marked.linear(),
            lent(Lending::FrameByFrame),
        ];
        let pairs: Vec<(usize, usize)> = entries.iter().map(|&(k, i, _)| (k, i)).collect();
        let neighbours = marked.neighbours(&pairs);
        let values = entries
            .iter()
            .zip(neighbours)
            .map(|(&(k, i, _), nb)| {
                let e = 3 * (k * n + i);
                std::array::from_fn(|m| {
                    if m == at::NEIGHBOURS {
                        nb
                    } else {
                        [whole[m][e], whole[m][e + 1], whole[m][e + 2]]
                    }
                })
            })
            .collect();
        Candidates { values }
    }

    fn at(&self, row: usize) -> [[f32; 3]; M] {
        self.values[row]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_simplex_minimum_matches_hand_solved_cases() {
        // Independent errors of variances 1, 4 and 100: the weights are the inverse
        // variances, normalised: (1, 1/4, 1/100, 1/100, 1/100, 1/100) / 1.29.
        let mut e = [[0f64; M]; M];
        e[0][0] = 1.0;
        e[1][1] = 4.0;
        for m in 2..M {
            e[m][m] = 100.0;
        }
        let w = simplex_least_squares(&e);
        let want = [1.0, 0.25, 0.01, 0.01, 0.01, 0.01].map(|v| v / 1.29);
        for m in 0..M {
            assert!((w[m] - want[m]).abs() < 1e-12, "{w:?}");
        }
        // A filler that is exact takes the whole weight.
        let mut e = [[1f64; M]; M];
        for m in 0..M {
            e[m][m] = 2.0;
        }
        for l in 0..M {
            e[3][l] = 0.0;
            e[l][3] = 0.0;
        }
        let w = simplex_least_squares(&e);
        assert_eq!(w, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        // Perfectly anti-correlated errors cancel: (1, −1) → (0.5, 0.5) with zero error,
        // which a negative weight elsewhere cannot improve on.
        let mut e = [[0f64; M]; M];
        e[0][0] = 1.0;
        e[1][1] = 1.0;
        e[0][1] = -1.0;
        e[1][0] = -1.0;
        for m in 2..M {
            e[m][m] = 3.0;
        }
        let w = simplex_least_squares(&e);
        assert!(
            (w[0] - 0.5).abs() < 1e-12 && (w[1] - 0.5).abs() < 1e-12,
            "{w:?}"
        );
        assert!(w[2..].iter().all(|&v| v == 0.0), "{w:?}");
    }

    #[test]
    fn where_nothing_can_be_validated_the_fill_is_the_carried_one() {
        // Every track seen at its first and last frame only: no span can be hidden with an
        // observation on both sides.
        let (t, n) = (12usize, 3usize);
        let truth: Vec<f32> = (0..3 * t * n).map(|v| (v as f32 * 0.37).sin()).collect();
        let predicted: Vec<f32> = truth.iter().map(|v| 0.9 * v + 0.05).collect();
        let mut observed = vec![false; t * n];
        for i in 0..n {
            observed[i] = true;
            observed[(t - 1) * n + i] = true;
        }
        let canonical: Vec<f32> = (0..3 * n).map(|v| v as f32).collect();
        let field = FieldPrediction::new(n, &predicted, &canonical, &observed);
        let (filled, blend) = blended_fill(t, n, &truth, &observed, &field, 3);
        assert_eq!(blend.short, Weights::CARRIED);
        assert_eq!(blend.validated, [0, 0]);
        assert_eq!(
            filled,
            transfer_residuals(t, n, &truth, &observed, &field, Lending::Fixed)
        );
    }

    #[test]
    fn gap_classes_and_lengths_follow_the_gaps() {
        // One track of 40 frames: seen at 0, 4, 30, 39 (gaps of 3, 25 and 8), and one never
        // seen.
        let (t, n) = (40, 2);
        let mut observed = vec![false; t * n];
        for k in [0, 4, 30, 39] {
            observed[k * n] = true;
        }
        let classes = gap_classes(t, n, &observed);
        assert_eq!(classes[2 * n], Some(false));
        assert_eq!(classes[10 * n], Some(true));
        assert!(classes.iter().skip(1).step_by(2).all(Option::is_none));
        assert_eq!(
            crate::data::tracks::gap_lengths(t, n, &observed),
            vec![3, 25, 8]
        );
    }

    #[test]
    fn a_jittering_translation_with_a_wrong_field_is_filled_by_the_neighbours() {
        // 20 tracks of a grid that translates by an irregular jump every frame (a camera
        // shake: no spline follows it), over 30 frames; each track has a gap of 4 frames.
        // The "field" is garbage (zeros) and lends no track a neighbour's residual, so its
        // fill is the spline's: the blend must move its weight to the neighbours' motion,
        // which is exact here.
        let (t, n) = (30usize, 20usize);
        let jump = |k: usize| {
            let k = k as f32;
            [
                (1.7 * k * k).sin(),
                (2.3 * k * k + 1.0).cos(),
                0.5 * (0.9 * k * k).sin(),
            ]
        };
        let truth: Vec<f32> = (0..t)
            .flat_map(|k| {
                let d = jump(k);
                (0..n).flat_map(move |i| {
                    let (x, y) = ((i % 5) as f32, (i / 5) as f32);
                    [x + d[0], y + d[1], d[2]]
                })
            })
            .collect();
        let mut observed = vec![true; t * n];
        for i in 0..n {
            for k in 0..4 {
                observed[(3 + i + k) * n + i] = false;
            }
        }
        let predicted = vec![0f32; 3 * t * n];
        let field = FieldPrediction {
            predicted: &predicted,
            neighbours: vec![Vec::new(); n],
        };
        let (filled, blend) = blended_fill(t, n, &truth, &observed, &field, 7);
        assert!(blend.validated[0] > 0 && blend.cross_fitted[0], "{blend:?}");
        assert!(blend.short.neighbours > 0.95, "{blend:?}");
        let total: f64 = blend.short.as_array().iter().sum();
        assert!((total - 1.0).abs() < 1e-9);
        let mut worst = 0f32;
        let mut spline_worst = 0f32;
        let spline = Marked::new(t, n, &truth, &observed).spline();
        for (e, (&f, &y)) in filled.iter().zip(&truth).enumerate() {
            if observed[e / 3] {
                assert_eq!(f, y);
            } else {
                worst = worst.max((f - y).abs());
                spline_worst = spline_worst.max((spline[e] - y).abs());
            }
        }
        assert!(worst < 0.1, "{worst} {blend:?}");
        assert!(
            worst <= spline_worst,
            "{worst} against the spline's {spline_worst}"
        );
    }

    #[test]
    fn an_exact_field_keeps_the_whole_weight() {
        // The field is the truth: its carried fill is exact, so it wins every validation
        // entry and the real gaps are filled exactly.
        let (t, n) = (25usize, 6usize);
        let truth: Vec<f32> = (0..t)
            .flat_map(|k| {
                (0..n).flat_map(move |i| {
                    let s = (0.5 * k as f32 + i as f32).sin();
                    [s, s * s, i as f32 + 0.01 * (k * k) as f32]
                })
            })
            .collect();
        let mut observed = vec![true; t * n];
        for i in 0..n {
            for k in 5..9 {
                observed[(k + i) * n + i] = false;
            }
        }
        let field = FieldPrediction::new(n, &truth, &truth[..3 * n], &observed);
        let (filled, blend) = blended_fill(t, n, &truth, &observed, &field, 1);
        assert_eq!(blend.short, Weights::CARRIED, "{blend:?}");
        for (a, b) in filled.iter().zip(&truth) {
            assert!((a - b).abs() < 1e-5);
        }
    }

    #[test]
    fn nothing_to_fill_is_returned_as_given() {
        let (t, n) = (4usize, 2usize);
        let positions: Vec<f32> = (0..3 * t * n).map(|v| v as f32).collect();
        let observed = vec![true; t * n];
        let field = FieldPrediction::new(n, &positions, &positions[..3 * n], &observed);
        let (filled, blend) = blended_fill(t, n, &positions, &observed, &field, 0);
        assert_eq!(filled, positions);
        assert_eq!(blend.validated, [0, 0]);
    }
}
