//! Learning a blend's weights, in two stages.
//!
//! 1. **The classic fillers** (every filler but the field's two fills), on validation
//!    draws: spans of the observations hidden, every filler filling them from the rest;
//!    per class of gap length, the convex combination with the least mean distance, kept
//!    where it beats every filler alone cross-fitted. These fillers see nothing but the
//!    observations left, so a span hidden from them is a gap to them.
//! 2. **The field's fills** (`blind.rs`), on the blind spans alone, where there are any:
//!    observations the field was fitted without ([`super::blind_spans`]). The field was
//!    fitted to every other observation, so judged on a validation span of stage 1 it
//!    would be judged where it has seen the answer; there it looks far better than inside
//!    a gap. Per class, stage 1's blend and the field's two fills are blended again, three
//!    weights learned and cross-fitted the same way on the blind spans. Without blind
//!    spans the field's fills take no weight: nothing measured them as they fill a gap.
//!
//! The objective is the literature's: the mean Euclidean distance of each gap, averaged
//! over the gaps ([`Residual::weight`]: every validation span counts once, whatever its
//! length). It is minimised by iteratively reweighted least squares ([`mean_distance`]):
//! least squares alone lets a few spans that every filler misses by far set the weights
//! of all of them.

// Index loops over small matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use std::ops::Range;
use std::sync::Arc;

use rayon::prelude::*;

use super::blind::{blind_residuals, judge_field};
use super::lean::track_leans;
use super::{
    Blend, LENGTH_CLASSES, LengthBlend, M, MAX_VALIDATION_DRAWS, VALIDATION_FOLDS,
    VALIDATION_FRACTION, VALIDATION_SPANS, Weights, candidates, class_longest, classic_fillers,
    length_class, span_class,
};
use crate::gaps::field_fill::FieldPrediction;
use crate::gaps::fillers::{Filler, Marked, PerFiller, Sources};
use crate::gaps::linalg::simplex_least_squares;
use crate::gaps::spans::{GapIndex, gaps, validation_spans};
use crate::gaps::window::DrawWindows;

/// The classes whose weights [`learn`] solves for: short gaps, long gaps pooled, then each
/// length class of the long ones.
pub(super) const CLASSES: usize = 2 + LENGTH_CLASSES;

/// The reweighting steps of [`mean_distance`] after its least-squares start.
const REWEIGHTS: usize = 16;

/// The entries [`mean_distance`] solves on, at most: every k-th past that. A minute of
/// capture holds hundreds of thousands per class, each solve builds a Gram matrix of
/// them per step, and a span's neighbouring entries say nearly the same.
const SOLVED_ENTRIES: usize = 1 << 14;

/// The classes a validation entry in a gap of `len` frames counts in.
pub(super) fn classes_of(len: usize) -> impl Iterator<Item = usize> {
    match length_class(len) {
        None => [Some(0), None],
        Some(c) => [Some(1), Some(2 + c)],
    }
    .into_iter()
    .flatten()
}

/// One validation entry: each of `K` candidates' error there, `p − y` (in `f32`, as the
/// fills are: a long recording's draws hold millions), the length of its gap and its track.
pub(super) struct Residual<const K: usize> {
    pub(super) errors: [[f32; 3]; K],
    pub(super) len: usize,
    /// The track whose entry it is.
    pub(super) track: usize,
    /// The frames from it to the nearest observation the fillers saw: 1 beside one. A
    /// validation span that runs into a real gap is judged at the gap's border, however
    /// long the gap.
    pub(super) depth: usize,
}

/// A draw's residuals per class: an entry counts in two (its length class and the pooled
/// long gaps, or the short gaps alone), held once.
pub(super) type Classes<const K: usize> = [Vec<Arc<Residual<K>>>; CLASSES];

impl<const K: usize> Residual<K> {
    /// Its weight in the objective: one over the length of its gap, so that each gap
    /// counts once.
    pub(super) fn weight(&self) -> f64 {
        1.0 / self.len.max(1) as f64
    }

    /// The distance of the blend `w` to the truth.
    pub(super) fn distance(&self, w: &[f64; K]) -> f64 {
        // The candidates without weight add nothing: skipped, as most are in a blend and
        // every lean judged on every entry of a minute of capture.
        (0..3)
            .map(|c| {
                (0..K)
                    .filter(|&m| w[m] != 0.0)
                    .map(|m| w[m] * self.errors[m][c] as f64)
                    .sum::<f64>()
                    .powi(2)
            })
            .sum::<f64>()
            .sqrt()
    }
}

/// The objective: `Σ weight · distance` of the blend `w` over `residuals`.
pub(super) fn cost<'a, const K: usize>(
    residuals: impl Iterator<Item = &'a Residual<K>>,
    w: &[f64; K],
) -> f64 {
    residuals.map(|r| r.weight() * r.distance(w)).sum()
}

/// The convex weights, on the candidates whose bits are set in `allowed`, with the least
/// [`cost`] over `all` (at most [`SOLVED_ENTRIES`] of them, evenly spaced): least squares,
/// then [`REWEIGHTS`] steps that weigh each entry by one over its distance (a
/// majorisation of the distance, minimised exactly over the simplex each step, so the
/// cost never rises; the best seen is kept).
fn mean_distance<const K: usize>(all: &[&Residual<K>], allowed: u32) -> [f64; K] {
    let stride = all.len().div_ceil(SOLVED_ENTRIES).max(1);
    let residuals: Vec<&Residual<K>> = all.iter().step_by(stride).copied().collect();
    let gram = |scale: &dyn Fn(&Residual<K>) -> f64| {
        let mut e = [[0f64; K]; K];
        for r in &residuals {
            let s = r.weight() * scale(r);
            for m in 0..K {
                for l in m..K {
                    e[m][l] += s
                        * (0..3)
                            .map(|c| r.errors[m][c] as f64 * r.errors[l][c] as f64)
                            .sum::<f64>();
                }
            }
        }
        for m in 0..K {
            for l in 0..m {
                e[m][l] = e[l][m];
            }
        }
        e
    };
    let mut w = simplex_least_squares(&gram(&|_| 1.0), allowed);
    let mut best = (w, cost(residuals.iter().copied(), &w));
    let total: f64 = residuals.iter().map(|r| r.weight()).sum();
    for _ in 0..REWEIGHTS {
        if best.1 <= 0.0 || total <= 0.0 {
            break;
        }
        // Distances below a thousandth of the mean are held there: an entry filled
        // exactly would otherwise take all the weight.
        let floor = 1e-3 * best.1 / total;
        w = simplex_least_squares(&gram(&|r| 1.0 / r.distance(&w).max(floor)), allowed);
        let c = cost(residuals.iter().copied(), &w);
        if c < best.1 * (1.0 - 1e-9) {
            best = (w, c);
        } else {
            break;
        }
    }
    best.0
}

/// The whole weight on candidate `k`.
pub(super) fn one_hot<const K: usize>(k: usize) -> [f64; K] {
    std::array::from_fn(|m| if m == k { 1.0 } else { 0.0 })
}

/// One class's weights over `draws` (each draw's residuals per class), on the
/// candidates of `allowed`: the blend with the least mean distance if it beats every
/// allowed candidate alone cross-fitted (each group of draws, draw `d` in group
/// `d % groups`, judged with the weights of the others), else the candidate that did
/// best alone; and whether the blend won.
pub(super) fn solve<const K: usize>(
    draws: &[Classes<K>],
    class: usize,
    allowed: u32,
) -> ([f64; K], bool) {
    let groups = draws.len().min(VALIDATION_FOLDS);
    let of = |group: Option<usize>, held: bool| -> Vec<&Residual<K>> {
        draws
            .iter()
            .enumerate()
            .filter(|&(d, _)| group.is_none_or(|g| (d % groups == g) == held))
            .flat_map(|(_, f)| f[class].iter().map(|r| &**r))
            .collect()
    };
    let (mut blended, mut alone) = (0f64, [0f64; K]);
    for group in 0..groups {
        let (rest, judged) = (of(Some(group), false), of(Some(group), true));
        if rest.is_empty() || judged.is_empty() {
            continue;
        }
        blended += cost(judged.iter().copied(), &mean_distance(&rest, allowed));
        for k in 0..K {
            alone[k] += cost(judged.iter().copied(), &one_hot::<K>(k));
        }
    }
    // Ties go to the earlier candidate.
    let single = (0..K)
        .filter(|&k| allowed & (1 << k) != 0)
        .min_by(|&x, &y| alone[x].total_cmp(&alone[y]).then(x.cmp(&y)))
        .unwrap_or(0);
    if blended < alone[single] {
        (mean_distance(&of(None, true), allowed), true)
    } else {
        (one_hot::<K>(single), false)
    }
}

/// The weights (module docs): stage 1 on validation draws with `seed`, stage 2 on the
/// observed entries of `blind`, observations the field was fitted without.
pub(super) fn learn(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    blind: &[(usize, usize)],
) -> Blend {
    let (t, n) = (tracks.frames, tracks.points);
    if t < 3 || tracks.observed.iter().all(|&o| o) {
        return Blend::only(Filler::FieldFill);
    }
    // Per draw and class, the validation entries' residuals; the draws are independent,
    // so they run on every core (in order: the result does not depend on the split).
    let folds: Vec<Classes<M>> = draws(tracks, seed)
        .into_par_iter()
        .map(|(frames, hidden)| {
            let (tracks, field) = (tracks.window(frames.clone()), field.window(frames));
            let mut left = tracks.observed.to_vec();
            for &(k, i) in &hidden {
                left[k * n + i] = false;
            }
            let left_tracks = tracks.with_observed(&left);
            // Stage 1 weighs the classic fillers alone: the field's fills are not computed.
            residuals(
                &Sources::new(left_tracks, &field),
                &hidden,
                classic_fillers(),
            )
            .into_iter()
            .flatten()
            .fold(empty_classes(), |mut classes, r| {
                for class in classes_of(r.len) {
                    classes[class].push(Arc::clone(&r));
                }
                classes
            })
        })
        .collect();
    let Some(mut blend) = classic_blend(&folds) else {
        // Nothing to validate on: the field's fill, as it is fitted.
        return Blend::only(Filler::FieldFill);
    };
    blend.leans = track_leans(&folds, &blend);
    // Stage 1's residuals (up to a window's tenth per draw) are spent: not held through
    // stage 2's fills.
    drop(folds);
    let blind_folds = blind_residuals(tracks, field, blind, &blend);
    if !blind_folds.is_empty() {
        judge_field(&mut blend, &blind_folds);
    }
    blend
}

pub(super) fn empty_classes<const K: usize>() -> Classes<K> {
    std::array::from_fn(|_| Vec::new())
}

/// Stage 1: the blend of the classic fillers on `folds`, per class; `None` where no draw
/// holds a validation entry.
fn classic_blend(folds: &[Classes<M>]) -> Option<Blend> {
    let classic = classic_fillers();
    let counts: [usize; CLASSES] = std::array::from_fn(|c| folds.iter().map(|f| f[c].len()).sum());
    // The draws in which each class has a validation entry.
    let drawn: [usize; CLASSES] =
        std::array::from_fn(|c| folds.iter().filter(|f| !f[c].is_empty()).count());
    let solved = |class: usize| {
        let (w, beat) = solve(folds, class, classic);
        (PerFiller(w), beat)
    };
    let mut weights = [Weights::only(Filler::FieldFill); 2];
    let mut cross_fitted = [false; 2];
    for class in 0..2 {
        if counts[class] > 0 {
            (weights[class], cross_fitted[class]) = solved(class);
        }
    }
    // A class with no validation entry takes the other's weights.
    match [counts[0], counts[1]] {
        [0, 0] => return None,
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
                    solved(class)
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
    Some(Blend {
        short: weights[0],
        long: weights[1],
        validated: [counts[0], counts[1]],
        cross_fitted,
        by_length,
        field_validated: 0,
        leans: Vec::new(),
    })
}

/// One validation draw's hidden entries, `(frame, track)`.
pub(super) type Hidden = Vec<(usize, usize)>;

/// Stage 1's validation draws, each its window of frames ([`DrawWindows`]: the whole
/// recording unless it is long) and its hidden entries in the window's frames: at least
/// [`VALIDATION_FOLDS`], then more until every class of gap length with a gap to fill
/// holds [`VALIDATION_SPANS`] validation spans, at most [`MAX_VALIDATION_DRAWS`].
pub(super) fn draws(tracks: &Marked, seed: u64) -> Vec<(Range<usize>, Hidden)> {
    // The classes of the gaps to fill, and the validation spans drawn in each.
    let mut wanted = [false; 1 + LENGTH_CLASSES];
    for g in gaps(tracks).filter(|g| g.is_interior()) {
        wanted[span_class(g.len())] = true;
    }
    let mut spans = [0usize; 1 + LENGTH_CLASSES];
    let windows = DrawWindows::new(tracks);
    let (mut out, mut failed) = (Vec::new(), 0);
    for draw in 0..MAX_VALIDATION_DRAWS {
        let enough = (0..spans.len()).all(|c| !wanted[c] || spans[c] >= VALIDATION_SPANS);
        if draw >= VALIDATION_FOLDS && enough || failed == VALIDATION_FOLDS {
            break;
        }
        let draw_seed = seed ^ 0x9e37_79b9_7f4a_7c15u64.wrapping_mul(draw as u64 + 1);
        let frames = windows.at(draw);
        let window = tracks.window(frames.clone());
        let Ok(hidden) = validation_spans(&window, VALIDATION_FRACTION, draw_seed, span_class)
        else {
            failed += 1;
            continue;
        };
        for len in span_lengths(&hidden) {
            spans[span_class(len)] += 1;
        }
        out.push((frames, hidden));
    }
    out
}

/// The lengths of the spans of `hidden` `(frame, track)`: each track's runs of
/// consecutive frames.
fn span_lengths(hidden: &[(usize, usize)]) -> Vec<usize> {
    let mut by_track: Vec<(usize, usize)> = hidden.iter().map(|&(k, i)| (i, k)).collect();
    by_track.sort_unstable();
    let mut out: Vec<usize> = Vec::new();
    for (r, &(i, k)) in by_track.iter().enumerate() {
        match out.last_mut() {
            Some(last) if r > 0 && by_track[r - 1] == (i, k.wrapping_sub(1)) => *last += 1,
            _ => out.push(1),
        }
    }
    out
}

/// Every filler's error at `hidden` `(frame, track)`, entries observed in `tracks` that
/// `sources` lacks, filled from the observations of `sources`, each with the length of
/// its gap there and its depth in it: one per entry of `hidden`, in its order, `None`
/// where the entry is no gap there or a filler has no finite value.
pub(super) fn residuals(
    sources: &Sources,
    hidden: &[(usize, usize)],
    fillers: u32,
) -> Vec<Option<Arc<Residual<M>>>> {
    let (positions, n) = (sources.marked.positions, sources.marked.points);
    let index = GapIndex::new(&sources.marked);
    let gaps: Vec<Option<Range<usize>>> = hidden.iter().map(|&(k, i)| index.gap_at(k, i)).collect();
    let entries: Vec<(usize, usize, usize)> = hidden
        .iter()
        .zip(&gaps)
        .filter_map(|(&(k, i), gap)| gap.as_ref().map(|g| (k, i, g.len())))
        .collect();
    let mut filled = candidates(sources, &entries, fillers)
        .into_iter()
        .zip(&entries);
    hidden
        .iter()
        .zip(gaps)
        .map(|(&(k, i), gap)| {
            let gap = gap?;
            let (p, &(_, _, len)) = filled.next()?;
            let e = 3 * (k * n + i);
            // A filler not computed errs by 0: it takes no weight where it was not asked.
            let errors: [[f32; 3]; M] = std::array::from_fn(|m| {
                let asked = fillers & Filler::ALL[m].bit() != 0;
                std::array::from_fn(|c| {
                    if asked {
                        p[m][c] - positions[e + c]
                    } else {
                        0.0
                    }
                })
            });
            (!errors.iter().flatten().any(|v| !v.is_finite())).then(|| {
                Arc::new(Residual {
                    errors,
                    len,
                    track: i,
                    depth: (k - gap.start + 1).min(gap.end - k),
                })
            })
        })
        .collect()
}

#[cfg(test)]
mod tests;
