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
    Hidden, Pools, Solved, cost, empty_pools, one_hot, residuals, solve_judged, wider_costs,
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
    let classic = classic_fillers();
    let counts: [usize; Pool::COUNT] =
        std::array::from_fn(|c| draws.iter().map(|f| f[c].len()).sum());
    // The draws in which each pool has a validation entry.
    let drawn: [usize; Pool::COUNT] =
        std::array::from_fn(|c| draws.iter().filter(|f| !f[c].is_empty()).count());
    let best = recording_best(draws, classic);
    let held_out = |s: &Solved<M>, costs: &[f64]| {
        s.held_out(costs, classic)
            .map(|(chosen, k, best_alone)| HeldOut {
                chosen,
                best: Filler::ALL[k],
                best_alone,
                spans: s.spans,
            })
    };
    // A pool's choice, its cost on each held-out group, and what it solved.
    let judged = |pool: Pool| {
        let s = solve_judged(draws, pool, classic, v.cross_fit_groups);
        let costs = s.chosen_costs();
        let gains: Vec<f64> = s
            .groups
            .iter()
            .zip(&costs)
            .map(|((_, alone), chosen)| alone[best] - chosen)
            .collect();
        if v.fall_back && s.weights != one_hot::<M>(best) && !v.clearly_positive(&gains) {
            let alone = s.groups.iter().map(|(_, alone)| alone[best]).collect();
            (PerFiller(one_hot::<M>(best)), false, alone, s)
        } else {
            (PerFiller(s.weights), s.beat, costs, s)
        }
    };
    let (short, long) = (Pool::Class(GapClass::Short), Pool::AllLong);
    let mut weights = [Weights::only(Filler::FieldFill); 2];
    let mut cross_fitted = [false; 2];
    let mut held = [None; 2];
    for (slot, pool) in [short, long].into_iter().enumerate() {
        if counts[pool.index()] > 0 {
            let (w, beat, costs, s) = judged(pool);
            (weights[slot], cross_fitted[slot]) = (w, beat);
            held[slot] = held_out(&s, &costs);
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
            .map(|c| {
                let class = GapClass::Long(c);
                let pool = Pool::Class(class);
                let validated = counts[pool.index()];
                if drawn[pool.index()] < 2 {
                    return LengthBlend {
                        longest: class.longest(),
                        weights: weights[1],
                        validated,
                        own: false,
                        cross_fitted: false,
                        held_out: None,
                    };
                }
                // A class's own weights are kept where they clearly beat the pooled
                // long gaps' on its held-out groups: a class of a few spans cannot tell
                // its parts apart, and a choice it cannot tell from the pooled one is
                // the draws' noise.
                let (w, beat, costs, s) = judged(pool);
                // The pooled weights as the long gaps use them: one filler alone judged
                // alone, a blend cross-fitted (a blend learned on the other groups can
                // lean on a filler that the weights learned on every draw do not use).
                let pooled = match single(&weights[1]) {
                    Some(k) => s.groups.iter().map(|(_, alone)| alone[k]).collect(),
                    None => wider_costs(draws, pool, long, classic, v.cross_fit_groups, &s.held),
                };
                let own = w == weights[1] || {
                    let gains: Vec<f64> = pooled.iter().zip(&costs).map(|(p, c)| p - c).collect();
                    v.clearly_positive(&gains)
                };
                let (w, beat, costs) = if own {
                    (w, beat, costs)
                } else {
                    (weights[1], false, pooled)
                };
                LengthBlend {
                    longest: class.longest(),
                    weights: w,
                    validated,
                    own,
                    cross_fitted: beat,
                    held_out: held_out(&s, &costs),
                }
            })
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

/// The filler that holds the whole of `w`, if one does.
fn single(w: &Weights) -> Option<usize> {
    (0..M).find(|&k| w.0[k] == 1.0)
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
mod tests {
    use super::*;
    use crate::gaps::blend::residual::Residual;

    /// A validation entry of track 0 in a gap of `len` frames where `spline` and `chain`
    /// err by these (1-D) and every other filler far off.
    fn entry(len: usize, spline: f32, chain: f32) -> Arc<Residual<M>> {
        Arc::new(Residual {
            errors: std::array::from_fn(|m| match Filler::ALL[m] {
                Filler::Spline => [spline, 0.0, 0.0],
                Filler::Chain => [chain, 0.0, 0.0],
                _ => [1e3, 0.0, 0.0],
            }),
            len,
            track: 0,
            depth: 1,
        })
    }

    /// Six draws of long gaps: 100-frame gaps where the chain fill is far better, and
    /// 20-frame gaps where the spline beats it by `spline_20` in each draw. Where that gain
    /// is steady the 20-frame class keeps its own choice (the spline); where it swings
    /// from draw to draw (the validation cannot tell the two apart) the class takes the
    /// pooled long gaps' weights.
    #[test]
    fn a_length_class_keeps_its_own_weights_only_where_they_clearly_beat_the_pooled_ones() {
        let class_of = |spline_20: [f32; 6]| {
            let draws: Vec<Pools<M>> = spline_20
                .iter()
                .map(|&s| {
                    let mut pools = empty_pools();
                    for (len, spline, chain) in [(20, s, 1.0), (100, 5.0, 0.1)] {
                        for _ in 0..4 {
                            let long = entry(len, spline, chain);
                            pools[Pool::Class(GapClass::of(len)).index()].push(Arc::clone(&long));
                            pools[Pool::AllLong.index()].push(long);
                        }
                    }
                    pools
                })
                .collect();
            let blend = classic_blend(&draws, &Validation::default()).unwrap();
            let GapClass::Long(c) = GapClass::of(20) else {
                unreachable!("a long gap")
            };
            (blend.by_length[c], blend.long)
        };
        let (steady, _) = class_of([0.5; 6]);
        assert!(
            steady.own && steady.weights == Weights::only(Filler::Spline),
            "{steady:?}"
        );
        let (swinging, pooled) = class_of([0.2, 1.8, 0.2, 1.8, 0.2, 1.8]);
        assert!(!swinging.own, "{swinging:?}");
        assert_eq!(swinging.weights, pooled);
    }

    /// The pooled long gaps' weights are judged on a class as the long gaps use them. On
    /// clean draws a half-and-half blend of the chain fill (+1) and the Kalman smoother
    /// (−1) is exact, but the smoother misses one 20-frame span by 1000: learned on every
    /// draw, the long gaps take the chain fill alone. The 20-frame class, whose spline
    /// swings around the chain fill's 1.05, takes those weights; on its held-out draws
    /// they give the chain fill's 1.05 a span, not what blends learned on the other draws
    /// give.
    #[test]
    fn a_class_is_judged_against_the_pooled_weights_as_the_long_gaps_use_them() {
        let with = |len: usize, errors: &[(Filler, f32)]| {
            Arc::new(Residual {
                errors: std::array::from_fn(|m| {
                    let e = errors.iter().find(|(f, _)| *f == Filler::ALL[m]);
                    [e.map_or(1e3, |(_, e)| *e), 0.0, 0.0]
                }),
                len,
                track: 0,
                depth: 1,
            })
        };
        let draws: Vec<Pools<M>> = (0..6)
            .map(|d| {
                let mut pools = empty_pools();
                let spline = if d % 2 == 0 { 0.2 } else { 1.8 };
                let kalman = if d == 5 { 1000.0 } else { -1.0 };
                let spans = [
                    (100, vec![(Filler::Chain, 1.0), (Filler::Kalman, -1.0)]),
                    (
                        20,
                        vec![
                            (Filler::Spline, spline),
                            (Filler::Chain, 1.05),
                            (Filler::Kalman, kalman),
                        ],
                    ),
                ];
                for (len, errors) in spans {
                    for _ in 0..len {
                        let long = with(len, &errors);
                        pools[Pool::Class(GapClass::of(len)).index()].push(Arc::clone(&long));
                        pools[Pool::AllLong.index()].push(long);
                    }
                }
                pools
            })
            .collect();
        let blend = classic_blend(&draws, &Validation::default()).unwrap();
        assert_eq!(blend.long, Weights::only(Filler::Chain));
        let GapClass::Long(c) = GapClass::of(20) else {
            unreachable!("a long gap")
        };
        let class = blend.by_length[c];
        assert!(!class.own, "{class:?}");
        let held = class.held_out.unwrap();
        assert!((held.chosen - 1.05).abs() < 1e-6, "{held:?}");
        assert_eq!(held.best, Filler::Spline);
        assert!((held.best_alone - 1.0).abs() < 1e-6, "{held:?}");
    }

    /// The held-out figures by hand: every 20-frame span errs by 0.5 with the spline and
    /// 1.0 with the chain fill, each 100-frame span by 5.0 and 0.1. The 20-frame class
    /// fills with the spline (0.5 a span, as the spline alone); the pooled long gaps'
    /// best filler alone is the chain fill (half the spans at 1.0, half at 0.1: 0.55 a
    /// span), and their blend, cross-fitted, does no worse.
    #[test]
    fn the_held_out_figures_are_the_mean_distance_per_span() {
        let draws: Vec<Pools<M>> = (0..6)
            .map(|_| {
                let mut pools = empty_pools();
                for (len, spline, chain) in [(20, 0.5, 1.0), (100, 5.0, 0.1)] {
                    for _ in 0..len {
                        let long = entry(len, spline, chain);
                        pools[Pool::Class(GapClass::of(len)).index()].push(Arc::clone(&long));
                        pools[Pool::AllLong.index()].push(long);
                    }
                }
                pools
            })
            .collect();
        let blend = classic_blend(&draws, &Validation::default()).unwrap();
        let GapClass::Long(c) = GapClass::of(20) else {
            unreachable!("a long gap")
        };
        let held = blend.by_length[c].held_out.unwrap();
        assert_eq!(held.best, Filler::Spline);
        assert!((held.best_alone - 0.5).abs() < 1e-6, "{held:?}");
        assert!((held.chosen - 0.5).abs() < 1e-6, "{held:?}");
        // One span of each length a draw, every draw held out once.
        assert!((held.spans - 6.0).abs() < 1e-9, "{held:?}");
        let long = blend.held_out[1].unwrap();
        assert_eq!(long.best, Filler::Chain);
        assert!((long.best_alone - 0.55).abs() < 1e-6, "{long:?}");
        assert!(long.chosen <= long.best_alone + 1e-9, "{long:?}");
        assert!((long.spans - 12.0).abs() < 1e-9, "{long:?}");
        // No short gap was validated.
        assert_eq!(blend.held_out[0], None);
        // In the data's units: every figure times the scale, the spans as they were.
        let in_mm = blend.clone().in_units(1000.0);
        let (class_mm, long_mm) = (
            in_mm.by_length[c].held_out.unwrap(),
            in_mm.held_out[1].unwrap(),
        );
        assert!((class_mm.chosen - 1000.0 * held.chosen).abs() < 1e-9);
        assert!((long_mm.best_alone - 1000.0 * long.best_alone).abs() < 1e-9);
        assert_eq!(class_mm.spans, held.spans);
        // A report keeps them, the filler by its name; one written before reads without.
        let json = serde_json::to_string(&blend).unwrap();
        assert!(json.contains(r#""best":"chain""#), "{json}");
        // (serde_json reads a float back to within an ulp.)
        let read = serde_json::from_str::<Blend>(&json).unwrap().by_length[c].held_out;
        let read = read.unwrap();
        assert_eq!(read.best, held.best);
        assert!(
            (read.chosen - held.chosen).abs() < 1e-12 && (read.spans - held.spans).abs() < 1e-12
        );
        let before = serde_json::to_value(Blend {
            held_out: [None, None],
            ..blend.clone()
        })
        .unwrap();
        assert!(before.get("held_out").is_none());
        let read: Blend = serde_json::from_value(before).unwrap();
        assert_eq!(read.held_out, [None, None]);
    }

    /// Six draws: on the short gaps the spline wins some draws and loses others by as much
    /// (no clear gain over the chain fill); on the long gaps, and so across the recording,
    /// the chain fill is far better. With `fall_back` the short gaps take the chain fill;
    /// without, the short gaps' own choice leans on the spline.
    #[test]
    fn a_class_that_cannot_tell_the_parts_apart_falls_back_to_the_recording_s_best() {
        let spline_short = [0.5, 1.5, 0.5, 1.5, 0.5, 0.2];
        let draws: Vec<Pools<M>> = spline_short
            .iter()
            .map(|&s| {
                let mut pools = empty_pools();
                for _ in 0..4 {
                    pools[Pool::Class(GapClass::Short).index()].push(entry(1, s, 1.0));
                    let long = entry(20, 5.0, 0.1);
                    pools[Pool::Class(GapClass::of(20)).index()].push(Arc::clone(&long));
                    pools[Pool::AllLong.index()].push(long);
                }
                pools
            })
            .collect();
        assert_eq!(
            recording_best(&draws, classic_fillers()),
            Filler::Chain.index()
        );
        let on = Validation {
            fall_back: true,
            ..Validation::default()
        };
        let with = classic_blend(&draws, &on).unwrap();
        assert_eq!(with.short, Weights::only(Filler::Chain));
        let without = classic_blend(&draws, &Validation::default()).unwrap();
        assert!(without.short[Filler::Spline] > 0.5, "{:?}", without.short);
        // The long gaps choose the chain fill either way.
        assert_eq!(with.long, Weights::only(Filler::Chain));
        assert_eq!(without.long, Weights::only(Filler::Chain));
    }
}
