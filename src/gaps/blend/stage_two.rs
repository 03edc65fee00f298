//! Stage 2 of a blend's learning: the field's fills weighed against stage 1's blend
//! (and the leans) on the blind spans, observations the field was fitted without
//! ([`super::blind_spans`]), and kept only where they gain clearly.
//!
//! The field was fitted to every other observation, so judged on a validation span of
//! stage 1 it would be judged where it has seen the answer; there it looks far better than
//! inside a gap. Per class, stage 1's blend and the field's fills ([`Filler::FIELD`]) are blended again,
//! the weights learned and cross-fitted the same way on the blind spans. Without blind
//! spans the field's fills take no weight: nothing measured them as they fill a gap.

use std::sync::Arc;

use super::class::{GapClass, Pool};
use super::residual::{Hidden, Pools, Residual, cost, empty_pools, one_hot, residuals, solve};
use super::validation::Validation;
use super::{Blend, Weights};
use crate::gaps::fillers::{Filler, PerFiller, Sources};
use crate::gaps::marked::Marked;
use crate::gaps::prediction::FieldPrediction;
use crate::gaps::window::WINDOW_ENTRIES;

/// Stage 2 on the observed entries of `blind`: `blend`'s classes that gain clearly from
/// the field's fills take them in ([`judge_field`]); nothing changes where `blind` holds
/// no observed entry.
pub(super) fn stage_two(
    blend: &mut Blend,
    tracks: &Marked,
    field: &FieldPrediction,
    blind: &[(usize, usize)],
    validation: &Validation,
) {
    let folds = blind_residuals(tracks, field, blind, blend, validation.blind_folds);
    if !folds.is_empty() {
        judge_field(blend, &folds, validation);
    }
}

/// The candidates of stage 2: stage 1's blend, then each of the field's fills
/// ([`Filler::FIELD`]).
const STAGE_TWO: usize = 1 + Filler::FIELD.len();

/// The blind spans' residuals for stage 2, split into `folds` folds span by span: stage
/// 1's blend by `blend`'s weights for each entry's gap, and the field's fills. Empty where
/// `blind` holds no observed entry.
fn blind_residuals(
    tracks: &Marked,
    field: &FieldPrediction,
    blind: &[(usize, usize)],
    blend: &Blend,
    folds: usize,
) -> Vec<Pools<STAGE_TWO>> {
    // Stage 1's fillers with a weight, and the field's fills.
    let fillers = Filler::FIELD
        .iter()
        .fold(blend.in_use(), |bits, f| bits | f.bit());
    let n = tracks.points;
    // One mask for every fold: the fold's spans hidden, then seen again.
    let mut left = tracks.observed.to_vec();
    blind_draws(tracks, blind, folds)
        .iter()
        .map(|fold| {
            // The fold's spans hidden, the other folds' seen: each filler fills them from
            // what it has in the real gaps, the blind spans included, less one fold.
            fold.iter().for_each(|&(k, i)| left[k * n + i] = false);
            let sources = Sources::new(tracks.with_observed(&left), field);
            let found = residuals(&sources, fold, fillers);
            fold.iter().for_each(|&(k, i)| left[k * n + i] = true);
            let mut pools = empty_pools();
            for r in found.into_iter().flatten() {
                // Stage 1's blend of the values, less the truth: its blend of the errors.
                let three = Arc::new(Residual {
                    errors: std::array::from_fn(|c| match c {
                        0 => blend.combine(r.len, r.track, &r.errors),
                        c => r.errors[Filler::FIELD[c - 1].index()],
                    }),
                    len: r.len,
                    track: r.track,
                    depth: r.depth,
                });
                for pool in Pool::of(r.len) {
                    pools[pool.index()].push(Arc::clone(&three));
                }
            }
            pools
        })
        .collect()
}

/// Each class's weights become the blend of its stage-1 weights and the field's fills
/// learned on the blind spans (`folds`), where the class has blind entries in
/// [`Validation::field_folds`] folds or more and that blend, cross-fitted, beats the first
/// stage's clearly ([`Validation::clearly_positive`] of its gain per fold). A blind draw
/// holds few spans on a short recording: a share that wins on some folds and loses on
/// others by as much is the spans' noise. A class that does not qualify keeps its stage-1
/// weights (the pooled long gaps' share of the field would be judged on gaps of other
/// lengths).
fn judge_field(blend: &mut Blend, folds: &[Pools<STAGE_TWO>], v: &Validation) {
    let counts: [usize; Pool::COUNT] =
        std::array::from_fn(|c| folds.iter().map(|f| f[c].len()).sum());
    let drawn: [usize; Pool::COUNT] =
        std::array::from_fn(|c| folds.iter().filter(|f| !f[c].is_empty()).count());
    let groups = v.cross_fit_groups;
    let share = |pool: Pool| -> Option<[f64; STAGE_TWO]> {
        let class = pool.index();
        if drawn[class] < v.field_folds {
            return None;
        }
        let classic = one_hot::<STAGE_TWO>(0);
        let (s, _) = solve(folds, pool, u32::MAX, groups);
        // Each fold judged with the weights the others choose, against the first stage's
        // blend: the field's share holds only where it gains by more than two standard
        // errors of the folds' gains.
        let gains: Vec<f64> = (0..folds.len())
            .filter(|&d| !folds[d][class].is_empty())
            .map(|d| {
                let others: Vec<Pools<STAGE_TWO>> = folds
                    .iter()
                    .enumerate()
                    .filter(|&(e, _)| e != d)
                    .map(|(_, f)| f.clone())
                    .collect();
                let (w, _) = solve(&others, pool, u32::MAX, groups);
                let judged = || folds[d][class].iter().map(|r| &**r);
                cost(judged(), &classic) - cost(judged(), &w)
            })
            .collect();
        (s != classic && v.clearly_positive(&gains)).then_some(s)
    };
    let with_field = |classic: &Weights, s: [f64; STAGE_TWO]| -> Weights {
        PerFiller::from_fn(|f| {
            s[0] * classic[f]
                + Filler::FIELD
                    .iter()
                    .position(|&g| g == f)
                    .map_or(0.0, |c| s[1 + c])
        })
    };
    if let Some(s) = share(Pool::Class(GapClass::Short)) {
        blend.short = with_field(&blend.short, s);
    }
    for (c, class) in blend.by_length.iter_mut().enumerate() {
        if let Some(s) = share(Pool::Class(GapClass::Long(c))) {
            class.weights = with_field(&class.weights, s);
        }
    }
    if let Some(s) = share(Pool::AllLong) {
        blend.long = with_field(&blend.long, s);
    }
    blend.field_validated =
        counts[Pool::Class(GapClass::Short).index()] + counts[Pool::AllLong.index()];
}

/// The blind entries that stage 2 weighs at most, about: an eighth of a window of time
/// ([`WINDOW_ENTRIES`]), more than a recording in one window holds (a tenth of its
/// observations, [`blind_spans`](super::blind_spans)). A long recording's blind spans grow
/// with it; its stage 2 weighs a stretch of them, as its fill's memory and time must not
/// grow.
const BLIND_ENTRIES: usize = WINDOW_ENTRIES / 8;

/// The observed entries of `blind`, split into `folds` folds span by span (none where
/// `blind` holds no observed entry). Past [`BLIND_ENTRIES`] of them, the
/// spans of one stretch of time in the recording's middle, as many as fit in
/// [`BLIND_ENTRIES`]: each fold is filled on its own, in the windows of time that hold
/// its spans, so spans spread over a long recording would have every fold fill every
/// window.
pub(super) fn blind_draws(tracks: &Marked, blind: &[(usize, usize)], folds: usize) -> Vec<Hidden> {
    let (n, observed) = (tracks.points, tracks.observed);
    let mut blind: Vec<(usize, usize)> = blind
        .iter()
        .copied()
        .filter(|&(k, i)| observed[k * n + i])
        .collect();
    // Span by span (a track's consecutive frames), so that a fold never judges a span
    // whose other half another fold learned from.
    blind.sort_unstable_by_key(|&(k, i)| (i, k));
    let mut spans: Vec<&[(usize, usize)]> = blind
        .chunk_by(|&(k, i), &(l, j)| i == j && l == k + 1)
        .collect();
    if blind.len() > BLIND_ENTRIES {
        // The middle stretch: the spans by their first frame, the run around the median.
        spans.sort_by_key(|span| span[0]);
        let (mut from, mut to, mut held) = (spans.len() / 2, spans.len() / 2, 0);
        while to < spans.len() && held + spans[to].len() <= BLIND_ENTRIES {
            held += spans[to].len();
            to += 1;
            if from > 0 && held + spans[from - 1].len() <= BLIND_ENTRIES {
                from -= 1;
                held += spans[from].len();
            }
        }
        spans = spans[from..to].to_vec();
        spans.sort_by_key(|span| (span[0].1, span[0].0));
    }
    let mut out = vec![Vec::new(); folds];
    for (s, span) in spans.iter().enumerate() {
        out[s % folds].extend_from_slice(span);
    }
    out.retain(|f| !f.is_empty());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn past_the_cap_stage_2_weighs_a_stretch_of_whole_spans_in_the_middle() {
        // 8 tracks of 20,000 frames, blind in spans of 2 frames every 4: 80,000 blind
        // entries, past the cap of 65,536.
        let (t, n) = (20_000, 8);
        let observed = vec![true; t * n];
        let positions = vec![0f32; 3 * t * n];
        let tracks = Marked::new(t, n, &positions, &observed);
        let blind: Vec<(usize, usize)> = (0..n)
            .flat_map(|i| (0..t).filter(|k| k % 4 < 2).map(move |k| (k, i)))
            .collect();
        assert!(blind.len() > BLIND_ENTRIES);
        let folds = blind_draws(&tracks, &blind, Validation::default().blind_folds);
        let weighed: Vec<(usize, usize)> = folds.concat();
        assert!(
            weighed.len() <= BLIND_ENTRIES && weighed.len() > BLIND_ENTRIES - 16,
            "{}",
            weighed.len()
        );
        // One stretch of time around the middle: its frames are the same for every
        // track, give or take the one span at each end, and they hold frame 10,000.
        let first = weighed.iter().map(|&(k, _)| k).min().unwrap();
        let last = weighed.iter().map(|&(k, _)| k).max().unwrap();
        assert!(first < 10_000 && last > 10_000, "{first}..{last}");
        assert!(
            (last - first + 1) * n / 2 <= weighed.len() + 4 * n,
            "{first}..{last} is not one stretch"
        );
        // No span split between folds, and every span whole.
        for fold in &folds {
            let own: std::collections::HashSet<&(usize, usize)> = fold.iter().collect();
            assert!(fold.iter().all(|&(k, i)| own.contains(&(k ^ 1, i))));
        }
    }

    /// One track with a real one-frame gap at frame 12 and blind spans at 10–11 and
    /// 13–14: two spans, two folds. Each fold is filled with the other's span seen, as
    /// the real gaps are filled with every blind span seen: a gap of 3 frames (its span
    /// and the real gap), not the 5 that hiding both spans makes.
    #[test]
    fn each_fold_is_filled_with_the_other_folds_spans_seen() {
        let (t, n) = (30, 2);
        let positions: Vec<f32> = (0..3 * t * n).map(|e| (e % 7) as f32).collect();
        let mut observed = vec![true; t * n];
        observed[12 * n] = false;
        let tracks = Marked::new(t, n, &positions, &observed);
        let field = FieldPrediction::new(n, &positions, &positions[..3 * n], &observed);
        let blind = [(10, 0), (11, 0), (13, 0), (14, 0)];
        let folds = blind_residuals(&tracks, &field, &blind, &Blend::only(Filler::Linear), 6);
        assert_eq!(folds.len(), 2);
        for fold in &folds {
            let lens: Vec<usize> = fold.iter().flatten().map(|r| r.len).collect();
            assert_eq!(lens, [3, 3]);
        }
    }
}
