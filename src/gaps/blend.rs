//! doma's fill: the field's fills ([`field_fill`], with fixed lenders and with lenders
//! chosen frame by frame) blended with the classic fillers ([`Filler`]), each weighted by
//! how well it fills gaps in this very data.
//!
//! No filler wins everywhere. On sparse markers the field's fill beats every baseline in
//! most cases, but a cubic spline wins short gaps of a fast, densely sampled motion; on
//! hundreds or thousands of tracks of one skinned surface the neighbours' motion does
//! better (docs/results.md, gap filling). So the weights are learned per data set: in each
//! of [`VALIDATION_FOLDS`] draws, [`VALIDATION_FRACTION`] of the observed entries are
//! hidden again, in spans as long as the data's own gaps; every filler fills them from
//! what is left, and the convex combination with the least squared error over the draws is
//! found, one for gaps of at most [`SPLINE_CARRY_FRAMES`](super::SPLINE_CARRY_FRAMES) frames and one for longer gaps.
//! It replaces the field's fill only if it also wins cross-fitted (weights learned on the
//! other draws, judged on each draw in turn): a blend that won by chance on a few spans
//! is not used. The real gaps are then filled from every observation (docs/design.md §7).
//!
//! The field was fitted to the validation entries, so its fill is judged where it has seen
//! the answer; that favours the field's fills. The field alone is not blended for that
//! reason: judged on entries it was fitted to, it looks far better than inside a gap.

// Index loops over 6 × 6 matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use super::field_fill::{FieldPrediction, Lending, field_fill};
use super::fillers::{Filler, Marked, PerFiller, Sources};
use super::linalg::{quadratic, simplex_least_squares};
use super::spans::{gap_classes, validation_spans};
use serde::{Deserialize, Serialize};

/// The share of the observed entries hidden in each validation draw.
pub const VALIDATION_FRACTION: f64 = 0.1;

/// The validation draws.
pub const VALIDATION_FOLDS: usize = 3;

/// The number of fillers blended.
const M: usize = Filler::COUNT;

/// The weight of each filler, non-negative, summing to 1.
pub type Weights = PerFiller<f64>;

impl Weights {
    /// The whole weight on `filler`.
    pub fn only(filler: Filler) -> Weights {
        PerFiller::from_fn(|f| if f == filler { 1.0 } else { 0.0 })
    }
}

/// The weights a fill used, and the validation entries that chose them.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Blend {
    /// For gaps of at most [`SPLINE_CARRY_FRAMES`](super::SPLINE_CARRY_FRAMES) frames.
    pub short: Weights,
    /// For longer gaps.
    pub long: Weights,
    /// The validation entries behind `short` and `long`, over the draws (0: that class had
    /// none and took the other's weights, or the field's fill alone if neither had any).
    pub validated: [usize; 2],
    /// Whether each class's blend beat the field's fill cross-fitted; where not, that
    /// class fills with the field's fill alone.
    pub cross_fitted: [bool; 2],
}

/// doma's fill of every unobserved entry of `tracks` from the field's prediction `field`:
/// each gap filled by the blend of the fillers whose weights did best on validation spans
/// drawn with `seed` (module docs). Observed entries are returned as observed; a track
/// never observed is left as it is.
pub fn blended_fill(tracks: &Marked, field: &FieldPrediction, seed: u64) -> (Vec<f32>, Blend) {
    let n = tracks.points;
    let classes = gap_classes(tracks);
    let blend = learn(tracks, field, seed);
    // The entries to fill: every gap of a track observed somewhere.
    let entries: Vec<(usize, usize, bool)> = (0..tracks.frames)
        .flat_map(|k| (0..n).map(move |i| (k, i)))
        .filter_map(|(k, i)| classes[k * n + i].map(|long| (k, i, long)))
        .collect();
    let field_only = Weights::only(Filler::FieldFill);
    if blend.short == field_only && blend.long == field_only {
        return (field_fill(tracks, field, Lending::Fixed), blend);
    }
    let mut out = tracks.positions.to_vec();
    if entries.is_empty() {
        return (out, blend);
    }
    let (fills, _) = blend_at(&Sources::new(*tracks, field), &blend, &entries);
    for (&(k, i, _), v) in entries.iter().zip(fills) {
        let e = 3 * (k * n + i);
        out[e..e + 3].copy_from_slice(&v);
    }
    (out, blend)
}

/// The blend of every filler at `entries` `(frame, track, long)` by `blend`'s weights for
/// each entry's class, and the fillers' values there.
fn blend_at(
    sources: &Sources,
    blend: &Blend,
    entries: &[(usize, usize, bool)],
) -> (Vec<[f32; 3]>, Vec<[[f32; 3]; M]>) {
    let values = candidates(sources, entries);
    let fills = values
        .iter()
        .zip(entries)
        .map(|(p, &(_, _, long))| blend.combine(long, p))
        .collect();
    (fills, values)
}

/// Every filler's value at `entries` `(frame, track, long)`, in the order of
/// [`Filler::ALL`].
fn candidates(sources: &Sources, entries: &[(usize, usize, bool)]) -> Vec<[[f32; 3]; M]> {
    let pairs: Vec<(usize, usize)> = entries.iter().map(|&(k, i, _)| (k, i)).collect();
    let columns = Filler::ALL.map(|f| f.fill_at(sources, &pairs));
    (0..entries.len())
        .map(|row| std::array::from_fn(|m| columns[m][row]))
        .collect()
}

/// doma's fill and every filler's value at `entries` `(frame, track)`, gaps of the tracks:
/// what [`blended_fill`] gives there, without filling the other gaps. For measuring a fill
/// on held-out entries beside its parts.
pub struct FillsAt {
    /// The weights, as [`blended_fill`] learns them.
    pub blend: Blend,
    /// doma's fill at each entry.
    pub doma: Vec<[f32; 3]>,
    /// Each filler's value at each entry, in the order of [`Filler::ALL`].
    pub fillers: Vec<[[f32; 3]; M]>,
}

impl FillsAt {
    /// `filler`'s value at each entry.
    pub fn filler(&self, filler: Filler) -> Vec<[f32; 3]> {
        self.fillers.iter().map(|p| p[filler.index()]).collect()
    }
}

/// [`FillsAt`] of the same arguments as [`blended_fill`] and the entries to measure.
pub fn fills_at(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    entries: &[(usize, usize)],
) -> FillsAt {
    let n = tracks.points;
    let classes = gap_classes(tracks);
    let blend = learn(tracks, field, seed);
    let entries: Vec<(usize, usize, bool)> = entries
        .iter()
        .map(|&(k, i)| (k, i, classes[k * n + i] == Some(true)))
        .collect();
    let (doma, fillers) = blend_at(&Sources::new(*tracks, field), &blend, &entries);
    FillsAt {
        blend,
        doma,
        fillers,
    }
}

impl Blend {
    /// The blend of one entry's filler values `p` by the weights of its class.
    fn combine(&self, long: bool, p: &[[f32; 3]; M]) -> [f32; 3] {
        let w = if long { self.long } else { self.short }.0;
        std::array::from_fn(|c| {
            (0..M)
                .filter(|&m| w[m] > 0.0)
                .map(|m| w[m] * p[m][c] as f64)
                .sum::<f64>() as f32
        })
    }
}

/// The weights: in each draw, validation spans hidden and every filler filling them from
/// the rest; the least-squares convex combination per class over the draws, kept where it
/// beats the field's fill cross-fitted.
fn learn(tracks: &Marked, field: &FieldPrediction, seed: u64) -> Blend {
    let (t, n, observed) = (tracks.frames, tracks.points, tracks.observed);
    let field_only = Weights::only(Filler::FieldFill);
    let carried_only = Blend {
        short: field_only,
        long: field_only,
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
        let Ok(hidden) = validation_spans(tracks, VALIDATION_FRACTION, fold_seed) else {
            continue;
        };
        let mut left = observed.to_vec();
        for &(k, i) in &hidden {
            left[k * n + i] = false;
        }
        // Each validation entry's class, by its gap in what is left.
        let left_tracks = tracks.with_observed(&left);
        let left_classes = gap_classes(&left_tracks);
        let entries: Vec<(usize, usize, bool)> = hidden
            .iter()
            .filter_map(|&(k, i)| left_classes[k * n + i].map(|long| (k, i, long)))
            .collect();
        let mut gram = [[[0f64; M]; M]; 2];
        accumulate(
            &Sources::new(left_tracks, field),
            &entries,
            &mut gram,
            &mut counts,
        );
        grams.push(gram);
    }
    let mut weights = [field_only; 2];
    // The field's fill's row and column of each Gram matrix.
    let f = Filler::FieldFill.index();
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
        let (mut blended, mut alone) = (0f64, 0f64);
        for (fold, g) in grams.iter().enumerate() {
            let rest = sum(Some(fold));
            if rest[f][f] == 0.0 && rest.iter().flatten().all(|&v| v == 0.0) {
                continue;
            }
            let w = simplex_least_squares(&rest);
            blended += quadratic(&w, &g[class]);
            alone += g[class][f][f];
        }
        if blended < alone {
            weights[class] = PerFiller(simplex_least_squares(&sum(None)));
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

/// Adds to each class's `E[m][l] = Σ (p_m − y)·(p_l − y)` (over the entries and their
/// coordinates) the fillers' errors at `entries`, filled from the observations of `sources`.
fn accumulate(
    sources: &Sources,
    entries: &[(usize, usize, bool)],
    gram: &mut [[[f64; M]; M]; 2],
    counts: &mut [usize; 2],
) {
    let (positions, n) = (sources.marked.positions, sources.marked.points);
    for (p, &(k, i, long)) in candidates(sources, entries).iter().zip(entries) {
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

#[cfg(test)]
mod tests {
    use super::*;

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
        let (filled, blend) = blended_fill(&Marked::new(t, n, &truth, &observed), &field, 3);
        assert_eq!(blend.short, Weights::only(Filler::FieldFill));
        assert_eq!(blend.validated, [0, 0]);
        assert_eq!(
            filled,
            field_fill(
                &Marked::new(t, n, &truth, &observed),
                &field,
                Lending::Fixed
            )
        );
    }

    #[test]
    fn a_jittering_translation_with_a_wrong_field_is_filled_by_the_neighbours() {
        // 20 tracks of a grid that translates by an irregular jump every frame (a camera
        // shake: no spline follows it), over 30 frames; each track has a gap of 4 frames.
        // The "field" is garbage (zeros) and lends no track a neighbour's residual, so its
        // fill is the spline's: the blend must move its weight to the fillers that follow
        // the other tracks' motion, which are exact here.
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
        let (filled, blend) = blended_fill(&Marked::new(t, n, &truth, &observed), &field, 7);
        assert!(blend.validated[0] > 0 && blend.cross_fitted[0], "{blend:?}");
        // The neighbours' motion, pattern and rigid-body fill are all exact for a
        // translation: the weight goes to them, split as the least squares' ties fall.
        let exact = [Filler::Neighbours, Filler::Pattern, Filler::RigidBody];
        let on_exact: f64 = exact.iter().map(|&f| blend.short[f]).sum();
        assert!(on_exact > 0.95, "{blend:?}");
        let total: f64 = blend.short.0.iter().sum();
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
        let (filled, blend) = blended_fill(&Marked::new(t, n, &truth, &observed), &field, 1);
        assert_eq!(blend.short, Weights::only(Filler::FieldFill), "{blend:?}");
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
        let (filled, blend) = blended_fill(&Marked::new(t, n, &positions, &observed), &field, 0);
        assert_eq!(filled, positions);
        assert_eq!(blend.validated, [0, 0]);
    }
}
