//! Learning a blend's weights: validation draws, every filler's error on them, and per
//! class of gap length the convex combination with the least mean distance, kept where it
//! beats every filler alone cross-fitted.
//!
//! The objective is the literature's: the mean Euclidean distance of each gap, averaged
//! over the gaps ([`Residual::weight`]: every validation span counts once, whatever its
//! length). It is minimised by iteratively reweighted least squares ([`mean_distance`]):
//! least squares alone lets a few spans that every filler misses by far set the weights
//! of all of them.

// Index loops over small matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use std::sync::Arc;

use rayon::prelude::*;

use super::{
    Blend, LENGTH_CLASSES, LengthBlend, M, VALIDATION_FOLDS, VALIDATION_FRACTION, Weights,
    candidates, class_longest, length_class,
};
use crate::gaps::field_fill::FieldPrediction;
use crate::gaps::fillers::{Filler, Marked, PerFiller, Sources};
use crate::gaps::linalg::simplex_least_squares;
use crate::gaps::spans::{gap_sizes, validation_spans};

/// The classes whose weights [`learn`] solves for: short gaps, long gaps pooled, then each
/// length class of the long ones.
const CLASSES: usize = 2 + LENGTH_CLASSES;

/// The reweighting steps of [`mean_distance`] after its least-squares start.
const REWEIGHTS: usize = 16;

/// The entries [`mean_distance`] solves on, at most: every k-th past that. A minute of
/// capture holds hundreds of thousands per class, each solve builds a Gram matrix of
/// them per step, and a span's neighbouring entries say nearly the same.
const SOLVED_ENTRIES: usize = 1 << 14;

/// The classes a validation entry in a gap of `len` frames counts in.
fn classes_of(len: usize) -> impl Iterator<Item = usize> {
    match length_class(len) {
        None => [Some(0), None],
        Some(c) => [Some(1), Some(2 + c)],
    }
    .into_iter()
    .flatten()
}

/// One validation entry: every filler's error there, `p_m − y` (in `f32`, as the fills
/// are: a long recording's draws hold millions), and its weight in the objective, one over
/// the length of its gap, so that each gap counts once.
pub(super) struct Residual {
    errors: [[f32; 3]; M],
    weight: f64,
}

/// A fold's residuals per class: an entry counts in two (its length class and the pooled
/// long gaps, or the short gaps alone), held once.
type Classes = [Vec<Arc<Residual>>; CLASSES];

impl Residual {
    /// The distance of the blend `w` to the truth.
    fn distance(&self, w: &[f64; M]) -> f64 {
        (0..3)
            .map(|c| {
                (0..M)
                    .map(|m| w[m] * self.errors[m][c] as f64)
                    .sum::<f64>()
                    .powi(2)
            })
            .sum::<f64>()
            .sqrt()
    }
}

/// The objective: `Σ weight · distance` of the blend `w` over `residuals`.
fn cost<'a>(residuals: impl Iterator<Item = &'a Residual>, w: &[f64; M]) -> f64 {
    residuals.map(|r| r.weight * r.distance(w)).sum()
}

/// The convex weights with the least [`cost`] over `all` (at most [`SOLVED_ENTRIES`] of
/// them, evenly spaced): least squares, then
/// [`REWEIGHTS`] steps that weigh each entry by one over its distance (a majorisation of
/// the distance, minimised exactly over the simplex each step, so the cost never rises;
/// the best seen is kept).
fn mean_distance(all: &[&Residual]) -> [f64; M] {
    let stride = all.len().div_ceil(SOLVED_ENTRIES).max(1);
    let residuals: Vec<&Residual> = all.iter().step_by(stride).copied().collect();
    let gram = |scale: &dyn Fn(&Residual) -> f64| {
        let mut e = [[0f64; M]; M];
        for r in &residuals {
            let s = r.weight * scale(r);
            for m in 0..M {
                for l in m..M {
                    e[m][l] += s
                        * (0..3)
                            .map(|c| r.errors[m][c] as f64 * r.errors[l][c] as f64)
                            .sum::<f64>();
                }
            }
        }
        for m in 0..M {
            for l in 0..m {
                e[m][l] = e[l][m];
            }
        }
        e
    };
    let mut w = simplex_least_squares(&gram(&|_| 1.0));
    let mut best = (w, cost(residuals.iter().copied(), &w));
    let total: f64 = residuals.iter().map(|r| r.weight).sum();
    for _ in 0..REWEIGHTS {
        if best.1 <= 0.0 || total <= 0.0 {
            break;
        }
        // Distances below a thousandth of the mean are held there: an entry filled
        // exactly would otherwise take all the weight.
        let floor = 1e-3 * best.1 / total;
        w = simplex_least_squares(&gram(&|r| 1.0 / r.distance(&w).max(floor)));
        let c = cost(residuals.iter().copied(), &w);
        if c < best.1 * (1.0 - 1e-9) {
            best = (w, c);
        } else {
            break;
        }
    }
    best.0
}

/// The weights: in each draw, validation spans hidden (drawn with `seed`, or the folds of
/// `blind`) and every filler filling them from the rest; per class over the draws, the
/// convex combination with the least mean distance ([`mean_distance`]), kept where it
/// beats every filler alone cross-fitted, else the filler that does best alone. Short gaps
/// and long ones pooled, then each length class of the long ones with validation entries
/// in two draws or more.
pub(super) fn learn(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    blind: &[(usize, usize)],
) -> Blend {
    let (t, n, observed) = (tracks.frames, tracks.points, tracks.observed);
    let field_only = Weights::only(Filler::FieldFill);
    let carried_only = Blend::only(Filler::FieldFill);
    if t < 3 || observed.iter().all(|&o| o) {
        return carried_only;
    }
    // Per draw and class, the validation entries' residuals; the draws are independent,
    // so they run on every core (in order: the result does not depend on the split).
    let folds: Vec<Classes> = draws(tracks, seed, blind)
        .into_par_iter()
        .map(|(hidden, left)| {
            // Each validation entry's gap length in what is left.
            let left_tracks = tracks.with_observed(&left);
            let left_sizes = gap_sizes(&left_tracks);
            let entries: Vec<(usize, usize, usize)> = hidden
                .iter()
                .filter_map(|&(k, i)| left_sizes[k * n + i].map(|len| (k, i, len)))
                .collect();
            residuals(&Sources::new(left_tracks, field), &entries)
        })
        .collect();
    let counts: [usize; CLASSES] = std::array::from_fn(|c| folds.iter().map(|f| f[c].len()).sum());
    // The draws in which each class has a validation entry.
    let drawn: [usize; CLASSES] =
        std::array::from_fn(|c| folds.iter().filter(|f| !f[c].is_empty()).count());
    let solve = |class: usize| -> (Weights, bool) {
        let of = |skip: Option<usize>| -> Vec<&Residual> {
            folds
                .iter()
                .enumerate()
                .filter(|&(fold, _)| Some(fold) != skip)
                .flat_map(|(_, f)| f[class].iter().map(|r| &**r))
                .collect()
        };
        // Cross-fitted: each draw judged with the weights of the others, beside every
        // filler alone on the same draws.
        let (mut blended, mut alone) = (0f64, [0f64; M]);
        for (fold, f) in folds.iter().enumerate() {
            let rest = of(Some(fold));
            if rest.is_empty() || f[class].is_empty() {
                continue;
            }
            let judged = || f[class].iter().map(|r| &**r);
            blended += cost(judged(), &mean_distance(&rest));
            for m in 0..M {
                alone[m] += cost(judged(), &Weights::only(Filler::ALL[m]).0);
            }
        }
        // Ties go to the earlier filler (the field's fill first).
        let single = (0..M)
            .min_by(|&x, &y| alone[x].total_cmp(&alone[y]).then(x.cmp(&y)))
            .unwrap_or(0);
        if blended < alone[single] {
            (PerFiller(mean_distance(&of(None))), true)
        } else {
            (Weights::only(Filler::ALL[single]), false)
        }
    };
    let mut weights = [field_only; 2];
    let mut cross_fitted = [false; 2];
    for class in 0..2 {
        if counts[class] > 0 {
            (weights[class], cross_fitted[class]) = solve(class);
        }
    }
    // A class with no validation entry takes the other's weights.
    match [counts[0], counts[1]] {
        [0, 0] => return carried_only,
        [0, _] => (weights[0], cross_fitted[0]) = (weights[1], cross_fitted[1]),
        [_, 0] => (weights[1], cross_fitted[1]) = (weights[0], cross_fitted[0]),
        _ => {}
    }
    let by_length = if counts[1] == 0 {
        Vec::new()
    } else {
        (0..LENGTH_CLASSES)
            .map(|c| {
                let class = 2 + c;
                let own = drawn[class] >= 2;
                let (w, beat) = if own {
                    solve(class)
                } else {
                    (weights[1], false)
                };
                LengthBlend {
                    longest: class_longest(c),
                    weights: w,
                    validated: counts[class],
                    own,
                    cross_fitted: beat,
                }
            })
            .collect()
    };
    Blend {
        short: weights[0],
        long: weights[1],
        validated: [counts[0], counts[1]],
        cross_fitted,
        by_length,
    }
}

/// One validation draw: the entries hidden, and the `[T, N]` mask of what is left observed.
type Draw = (Vec<(usize, usize)>, Vec<bool>);

/// The validation draws of [`learn`], each its hidden entries and what is left observed:
/// [`VALIDATION_FOLDS`] draws of spans with `seed`, or, where `blind` holds observed
/// entries, those alone hidden and split into the folds span by span.
pub(super) fn draws(tracks: &Marked, seed: u64, blind: &[(usize, usize)]) -> Vec<Draw> {
    let (n, observed) = (tracks.points, tracks.observed);
    let hide = |hidden: &[(usize, usize)]| {
        let mut left = observed.to_vec();
        for &(k, i) in hidden {
            left[k * n + i] = false;
        }
        left
    };
    let mut blind: Vec<(usize, usize)> = blind
        .iter()
        .copied()
        .filter(|&(k, i)| observed[k * n + i])
        .collect();
    if blind.is_empty() {
        return (0..VALIDATION_FOLDS)
            .filter_map(|fold| {
                let fold_seed = seed ^ 0x9e37_79b9_7f4a_7c15u64.wrapping_mul(fold as u64 + 1);
                let hidden = validation_spans(tracks, VALIDATION_FRACTION, fold_seed).ok()?;
                let left = hide(&hidden);
                Some((hidden, left))
            })
            .collect();
    }
    let left = hide(&blind);
    // Span by span (a track's consecutive frames), so that a fold never judges a span
    // whose other half another fold learned from.
    blind.sort_unstable_by_key(|&(k, i)| (i, k));
    let mut folds = vec![Vec::new(); VALIDATION_FOLDS];
    let mut span = 0;
    for (r, &(k, i)) in blind.iter().enumerate() {
        if r > 0 && blind[r - 1] != (k.wrapping_sub(1), i) {
            span += 1;
        }
        folds[span % VALIDATION_FOLDS].push((k, i));
    }
    folds
        .into_iter()
        .filter(|f| !f.is_empty())
        .map(|f| (f, left.clone()))
        .collect()
}

/// Every filler's error at `entries` `(frame, track, gap length)`, filled from the
/// observations of `sources`, per class; an entry where a filler has no finite value is
/// left out.
fn residuals(sources: &Sources, entries: &[(usize, usize, usize)]) -> Classes {
    let (positions, n) = (sources.marked.positions, sources.marked.points);
    let mut out: Classes = std::array::from_fn(|_| Vec::new());
    for (p, &(k, i, len)) in candidates(sources, entries).iter().zip(entries) {
        let e = 3 * (k * n + i);
        let errors: [[f32; 3]; M] =
            std::array::from_fn(|m| std::array::from_fn(|c| p[m][c] - positions[e + c]));
        if errors.iter().flatten().any(|v| !v.is_finite()) {
            continue;
        }
        let residual = Arc::new(Residual {
            errors,
            weight: 1.0 / len.max(1) as f64,
        });
        for class in classes_of(len) {
            out[class].push(Arc::clone(&residual));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Residuals of 1-D errors: filler 0's `a`, filler 1's `b`, every other filler far off.
    fn residuals_of(a: &[f32], b: &[f32]) -> Vec<Residual> {
        a.iter()
            .zip(b)
            .map(|(&a, &b)| Residual {
                errors: std::array::from_fn(|m| match m {
                    0 => [a, 0.0, 0.0],
                    1 => [b, 0.0, 0.0],
                    _ => [1e3, 0.0, 0.0],
                }),
                weight: 1.0,
            })
            .collect()
    }

    #[test]
    fn the_mean_distance_is_not_led_by_one_far_miss() {
        // Filler 0 exact on four entries and 10 off on the fifth; filler 1 3 off on all.
        // Mean distance, w₀ + w₁ = 1: 4·3w₁ + |10w₀ + 3w₁| = 10 + 5w₁, least at w₁ = 0.
        // Squared: 4·9w₁² + (10 − 7w₁)², least at w₁ = 140/170.
        let r = residuals_of(&[0.0, 0.0, 0.0, 0.0, 10.0], &[3.0; 5]);
        let refs: Vec<&Residual> = r.iter().collect();
        let w = mean_distance(&refs);
        // Reweighting nears a vertex of the simplex slowly: within a few hundredths.
        assert!(w[0] > 0.97 && w[0] + w[1] > 1.0 - 1e-9, "{w:?}");
        assert!(cost(r.iter(), &w) < 10.15, "{w:?}");
        let mut squared = [0.0; M];
        (squared[0], squared[1]) = (30.0 / 170.0, 140.0 / 170.0);
        assert!((cost(r.iter(), &squared) - (10.0 + 5.0 * 140.0 / 170.0)).abs() < 1e-9);
        assert!(cost(r.iter(), &w) < cost(r.iter(), &squared));
    }

    #[test]
    fn a_distance_is_the_norm_of_the_blended_errors() {
        let r = Residual {
            errors: std::array::from_fn(|m| match m {
                0 => [3.0, 0.0, 4.0],
                1 => [-3.0, 8.0, 0.0],
                _ => [0.0; 3],
            }),
            weight: 0.5,
        };
        let mut w = [0.0; M];
        (w[0], w[1]) = (0.5, 0.5);
        // (0, 4, 2): √20, weighed by one half.
        assert!((r.distance(&w) - 20f64.sqrt()).abs() < 1e-12);
        assert!((cost([&r].into_iter(), &w) - 0.5 * 20f64.sqrt()).abs() < 1e-12);
    }
}
