//! Stage 1 of a blend's learning: the classic fillers (every filler but the field's two
//! fills) weighed on validation draws.
//!
//! In each draw, spans of the observations are hidden in the pattern of the data's own
//! gaps ([`validation_spans`]) and every classic filler fills them from the rest: these
//! fillers see nothing but the observations left, so a span hidden from them is a gap to
//! them. The draws go on until each class of gap length with a gap to fill holds its
//! spans ([`draws`]). Then, per [`GapClass`], the convex combination with the least mean
//! distance, kept where it beats every filler alone cross-fitted ([`solve`]); a class of
//! long gaps whose entries are in fewer than two draws, or whose choice does not clearly
//! beat the pooled long gaps' weights on its held-out draws ([`wider_costs`]), takes the
//! pooled weights.

use std::ops::Range;
use std::sync::Arc;

use rayon::prelude::*;

use super::class::{GapClass, LENGTH_CLASSES, Pool};
use super::residual::{
    Hidden, Pools, Solved, cost, empty_pools, one_hot, residuals, single, solve_judged, wider_costs,
};
use super::validation::Validation;
use super::{Blend, HeldOut, LengthBlend, M, Weights, classic_fillers};
use crate::gaps::fillers::{Filler, PerFiller, Sources};
use crate::gaps::marked::Marked;
use crate::gaps::prediction::FieldPrediction;
use crate::gaps::spans::{gaps, validation_spans};
use crate::gaps::window::DrawWindows;

/// Stage 1 on `tracks` with draws seeded by `seed`: the classic fillers' blend, and each
/// draw's residuals per pool (what the leans are learned on); `None` where no draw holds a
/// validation entry.
pub(super) fn stage_one(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    validation: &Validation,
) -> Option<(Blend, Vec<Pools<M>>)> {
    let n = tracks.points;
    // Per draw and pool, the validation entries' residuals; the draws are independent,
    // so they run on every core (in order: the result does not depend on the split).
    let draws: Vec<Pools<M>> = draws(tracks, seed, validation)
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
            .fold(empty_pools(), |mut pools, r| {
                for pool in Pool::of(r.len) {
                    pools[pool.index()].push(Arc::clone(&r));
                }
                pools
            })
        })
        .collect();
    let blend = classic_blend(&draws, validation)?;
    Some((blend, draws))
}

/// Stage 1's validation draws, each its window of frames ([`DrawWindows`]: the whole
/// recording unless it is long) and its hidden entries in the window's frames: at least
/// [`Validation::min_draws`], then more until every class of gap length with a gap to fill
/// holds [`Validation::spans_per_class`] validation spans, at most
/// [`Validation::max_draws`].
pub(super) fn draws(tracks: &Marked, seed: u64, v: &Validation) -> Vec<(Range<usize>, Hidden)> {
    let stratum = |len: usize| GapClass::of(len).index();
    // The classes of the gaps to fill, and the validation spans drawn in each.
    let mut wanted = [false; GapClass::COUNT];
    for g in gaps(tracks).filter(|g| g.is_interior()) {
        wanted[stratum(g.len())] = true;
    }
    let mut spans = [0usize; GapClass::COUNT];
    let windows = DrawWindows::new(tracks);
    let (mut out, mut failed) = (Vec::new(), 0);
    for draw in 0..v.max_draws {
        let enough = (0..spans.len()).all(|c| !wanted[c] || spans[c] >= v.spans_per_class);
        if draw >= v.min_draws && enough || failed == v.max_failed_draws {
            break;
        }
        let draw_seed = seed ^ 0x9e37_79b9_7f4a_7c15u64.wrapping_mul(draw as u64 + 1);
        let frames = windows.at(draw);
        let window = tracks.window(frames.clone());
        let Ok(hidden) = validation_spans(&window, v.fraction, draw_seed, stratum) else {
            failed += 1;
            continue;
        };
        for len in span_lengths(&hidden) {
            spans[stratum(len)] += 1;
        }
        out.push((frames, hidden));
    }
    out
}

/// The lengths of the spans of `hidden` `(frame, track)`: each track's runs of
/// consecutive frames.
pub(super) fn span_lengths(hidden: &[(usize, usize)]) -> Vec<usize> {
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

/// The blend of the classic fillers on `draws`, per class, cross-fitted over at most
/// [`Validation::cross_fit_groups`] groups of draws; `None` where no draw holds a validation
/// entry. Where [`Validation::fall_back`] holds (off by default: measured, it lost more
/// cases than it saved), a class whose choice does not clearly beat the filler best across
/// the recording ([`recording_best`]) on its held-out groups
/// ([`Validation::clearly_positive`]) takes that filler alone.
fn classic_blend(draws: &[Pools<M>], v: &Validation) -> Option<Blend> {
    let judge = Judge {
        draws,
        v,
        best: recording_best(draws, classic_fillers()),
    };
    let counts: [usize; Pool::COUNT] =
        std::array::from_fn(|c| draws.iter().map(|f| f[c].len()).sum());
    let (short, long) = (Pool::Class(GapClass::Short), Pool::AllLong);
    let mut weights = [Weights::only(Filler::FieldFill); 2];
    let mut cross_fitted = [false; 2];
    let mut held = [None; 2];
    for (slot, pool) in [short, long].into_iter().enumerate() {
        if counts[pool.index()] > 0 {
            let j = judge.judged(pool);
            (weights[slot], cross_fitted[slot]) = (j.weights, j.beat);
            held[slot] = j.held_out(&j.costs);
        }
    }
    // A class with no validation entry takes the other's weights.
    match [counts[short.index()], counts[long.index()]] {
        [0, 0] => return None,
        [0, _] => (weights[0], cross_fitted[0]) = (weights[1], cross_fitted[1]),
        [_, 0] => (weights[1], cross_fitted[1]) = (weights[0], cross_fitted[0]),
        _ => {}
    }
    let by_length = if counts[long.index()] == 0 {
        Vec::new()
    } else {
        (0..LENGTH_CLASSES)
            .map(|c| judge.length_class(GapClass::Long(c), weights[1]))
            .collect()
    };
    Some(Blend {
        short: weights[0],
        long: weights[1],
        validated: [counts[short.index()], counts[long.index()]],
        cross_fitted,
        held_out: held,
        by_length,
        field_validated: 0,
        leans: Vec::new(),
        ends: None,
    })
}

/// What [`classic_blend`] judges its pools with: the draws, the validation's rules, and
/// the classic filler best across the recording ([`recording_best`]).
struct Judge<'a> {
    draws: &'a [Pools<M>],
    v: &'a Validation,
    best: usize,
}

/// A pool's choice: its weights, whether its blend beat every filler alone, its cost on
/// each held-out group, and what it solved.
struct Judged {
    weights: Weights,
    beat: bool,
    costs: Vec<f64>,
    solved: Solved<M>,
}

impl Judged {
    /// `costs` (one per held-out group of this pool) beside the best classic filler alone
    /// on the same spans, per span.
    fn held_out(&self, costs: &[f64]) -> Option<HeldOut> {
        let s = &self.solved;
        s.held_out(costs, classic_fillers())
            .map(|(chosen, k, best_alone)| HeldOut {
                chosen,
                best: Filler::ALL[k],
                best_alone,
                spans: s.spans,
            })
    }
}

impl Judge<'_> {
    /// `pool`'s choice, cross-fitted; with [`Validation::fall_back`], the recording's best
    /// filler where the choice does not clearly beat it.
    fn judged(&self, pool: Pool) -> Judged {
        let (v, best) = (self.v, self.best);
        let s = solve_judged(self.draws, pool, classic_fillers(), v.cross_fit_groups);
        let costs = s.chosen_costs();
        let gains: Vec<f64> = s
            .groups
            .iter()
            .zip(&costs)
            .map(|((_, alone), chosen)| alone[best] - chosen)
            .collect();
        if v.fall_back && s.weights != one_hot::<M>(best) && !v.clearly_positive(&gains) {
            let alone = s.groups.iter().map(|(_, alone)| alone[best]).collect();
            let weights = PerFiller(one_hot::<M>(best));
            Judged {
                weights,
                beat: false,
                costs: alone,
                solved: s,
            }
        } else {
            let (weights, beat) = (PerFiller(s.weights), s.beat);
            Judged {
                weights,
                beat,
                costs,
                solved: s,
            }
        }
    }

    /// The weights of `class`, a class of long gaps, beside the pooled long gaps' `pooled`.
    /// A class's own weights are kept where they clearly beat the pooled ones on its
    /// held-out groups: a class of a few spans cannot tell its parts apart, and a choice it
    /// cannot tell from the pooled one is the draws' noise.
    fn length_class(&self, class: GapClass, pooled: Weights) -> LengthBlend {
        let pool = Pool::Class(class);
        let validated = self.draws.iter().map(|f| f[pool.index()].len()).sum();
        let drawn = self
            .draws
            .iter()
            .filter(|f| !f[pool.index()].is_empty())
            .count();
        let mut out = LengthBlend {
            longest: class.longest(),
            weights: pooled,
            validated,
            own: false,
            cross_fitted: false,
            held_out: None,
        };
        if drawn < 2 {
            return out;
        }
        let j = self.judged(pool);
        // The pooled weights as the long gaps use them: one filler alone judged alone, a
        // blend cross-fitted (a blend learned on the other groups can lean on a filler
        // that the weights learned on every draw do not use).
        let groups = self.v.cross_fit_groups;
        let pooled_costs: Vec<f64> = match single(&pooled.0) {
            Some(k) => j.solved.groups.iter().map(|(_, alone)| alone[k]).collect(),
            None => wider_costs(
                self.draws,
                pool,
                Pool::AllLong,
                classic_fillers(),
                groups,
                &j.solved.held,
            ),
        };
        out.own = j.weights == pooled || {
            let gains: Vec<f64> = pooled_costs
                .iter()
                .zip(&j.costs)
                .map(|(p, c)| p - c)
                .collect();
            self.v.clearly_positive(&gains)
        };
        if out.own {
            (out.weights, out.cross_fitted) = (j.weights, j.beat);
            out.held_out = j.held_out(&j.costs);
        } else {
            out.held_out = j.held_out(&pooled_costs);
        }
        out
    }
}

/// The classic filler (of `allowed`) with the least cost over every validation entry of
/// `draws`, each counted once (the short gaps and the long ones pooled); ties go to the
/// earlier.
fn recording_best(draws: &[Pools<M>], allowed: u32) -> usize {
    let every = || {
        draws.iter().flat_map(|d| {
            [Pool::Class(GapClass::Short), Pool::AllLong]
                .into_iter()
                .flat_map(move |p| d[p.index()].iter().map(|r| &**r))
        })
    };
    (0..M)
        .filter(|&k| allowed & (1 << k) != 0)
        .map(|k| (cost(every(), &one_hot::<M>(k)), k))
        .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
        .map_or(0, |(_, k)| k)
}

#[cfg(test)]
mod tests;
