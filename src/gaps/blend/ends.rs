//! Beyond a track's ends: the entries before its first observation or after its last,
//! which a tracker's late-starting and lost tracks leave by the thousand.
//!
//! No observation lies on the far side, so what interpolates there (the spline, the
//! linear and Kalman fills, and the donor fillers of capture software, which fill interior
//! gaps only) can only hold the border value. The fillers that predict there are those
//! that carry the track with the others' motion: the chained rigid-body fill from its one
//! border ([`Marked::chain`]), the neighbours' motion, and the spatial fills (iterative
//! PCA, Gløersen's) that read a frame's other markers ([`predicts_beyond_ends`]). Their
//! weights are learned as stage 1's are, on validation spans *cut at track ends*: in each
//! draw, a share of the tracks lose their first or their last observations, as many frames
//! as a run past the ends of the data itself, and the fillers carry them there from the
//! rest ([`end_spans`]). The field's fills take no part: the field was fitted on these
//! observations, so they cannot judge it.

use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::class::Pool;
use super::residual::{Pools, empty_pools, residuals, solve_judged};
use super::validation::Validation;
use super::{Blend, M, Weights, filler_values, with_gap_lengths};
use crate::gaps::fillers::{Filler, PerFiller, Sources};
use crate::gaps::marked::Marked;
use crate::gaps::prediction::FieldPrediction;
use crate::gaps::spans::gaps;
use crate::gaps::window::DrawWindows;

/// Keeps the seeds of the end spans apart from stage 1's.
const ENDS_SEED: u64 = 0x2545_f491_4f6c_dd1d;

/// The one pool the end spans are solved in: every entry beyond the ends, whatever its
/// length (the pool of all long gaps' slot, which no other entry fills here).
const ENDS: Pool = Pool::AllLong;

/// A track keeps at least this share of its observations in an end span's draw, so that
/// what carries it is judged from a border it has, as in the data.
const KEPT_SHARE: f64 = 0.5;

/// A track with fewer observations draws no end span.
const MIN_OBSERVED: usize = 4;

/// The fillers that predict beyond a track's ends rather than hold its border value
/// (module docs), as bits ([`Filler::bit`]).
pub fn predicts_beyond_ends() -> u32 {
    [
        Filler::Chain,
        Filler::Neighbours,
        Filler::IterativePca,
        Filler::Gloersen,
    ]
    .iter()
    .fold(0, |bits, f| bits | f.bit())
}

/// The weights beyond the ends, and the validation entries that chose them.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct EndBlend {
    /// The weight of each filler (those of [`predicts_beyond_ends`] alone).
    pub weights: Weights,
    /// The validation entries cut at track ends, over the draws.
    pub validated: usize,
    /// Whether the blend beat every filler alone cross-fitted (else its weights are all
    /// on the filler that did best alone).
    pub cross_fitted: bool,
}

/// The weights beyond the ends of `tracks`, learned on [`Validation::min_draws`] draws of
/// end spans seeded by `seed`; `None` where no track runs past an end or no span can be
/// cut.
pub(super) fn end_blend(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    v: &Validation,
) -> Option<EndBlend> {
    let lengths: Vec<usize> = gaps(tracks)
        .filter(|g| !g.is_interior())
        .map(|g| g.len())
        .collect();
    if lengths.is_empty() {
        return None;
    }
    let n = tracks.points;
    let allowed = predicts_beyond_ends();
    let windows = DrawWindows::new(tracks);
    let draws: Vec<Pools<M>> = (0..v.min_draws)
        .into_par_iter()
        .map(|draw| {
            let frames = windows.at(draw);
            let (window, field) = (tracks.window(frames.clone()), field.window(frames));
            let draw_seed =
                seed ^ ENDS_SEED ^ 0x9e37_79b9_7f4a_7c15u64.wrapping_mul(draw as u64 + 1);
            let hidden = end_spans(&window, &lengths, v.fraction, draw_seed);
            let mut left = window.observed.to_vec();
            for &(k, i) in &hidden {
                left[k * n + i] = false;
            }
            let sources = Sources::new(window.with_observed(&left), &field);
            let mut pools = empty_pools();
            pools[ENDS.index()] = residuals(&sources, &hidden, allowed)
                .into_iter()
                .flatten()
                .collect::<Vec<Arc<_>>>();
            pools
        })
        .collect();
    let validated: usize = draws.iter().map(|d| d[ENDS.index()].len()).sum();
    if validated == 0 {
        return None;
    }
    let solved = solve_judged(&draws, ENDS, allowed, v.cross_fit_groups);
    Some(EndBlend {
        weights: PerFiller(solved.weights),
        validated,
        cross_fitted: solved.beat,
    })
}

/// Whether an entry `(k, i)` lies before track `i`'s first observation or after its last
/// (a track never observed has none).
pub(super) fn past_ends(tracks: &Marked) -> impl Fn(usize, usize) -> bool + use<> {
    let ends = tracks.track_ends();
    move |k, i| ends[i].is_some_and(|(a, b)| k < a || k > b)
}

/// The indices of `entries` that `blend` fills inside the tracks' observations and of
/// those it fills beyond their ends by its own weights ([`Blend::ends`]; none where it has
/// none, and every entry is then inside).
pub(super) fn split_beyond(
    tracks: &Marked,
    blend: &Blend,
    entries: &[(usize, usize)],
) -> (Vec<usize>, Vec<usize>) {
    if blend.ends.is_none() {
        return ((0..entries.len()).collect(), Vec::new());
    }
    let past = past_ends(tracks);
    (0..entries.len()).partition(|&e| !past(entries[e].0, entries[e].1))
}

/// `fills` at the entries `at` of `entries`, past the tracks' ends ([`split_beyond`]),
/// from the fillers that predict there, by `blend`'s weights beyond the ends
/// ([`Blend::ends`]; kept as they are where it has none).
pub(super) fn beyond_ends(
    tracks: &Marked,
    field: &FieldPrediction,
    blend: &Blend,
    entries: &[(usize, usize)],
    at: &[usize],
    fills: &mut [[f32; 3]],
) {
    let Some(ends) = &blend.ends else {
        return;
    };
    let pairs: Vec<(usize, usize)> = at.iter().map(|&e| entries[e]).collect();
    let used = Filler::ALL
        .iter()
        .filter(|&&f| ends.weights[f] > 0.0)
        .fold(0, |bits, f| bits | f.bit());
    let values = filler_values(
        &Sources::new(*tracks, field),
        &with_gap_lengths(tracks, &pairs),
        used,
    );
    let w = ends.weights.0;
    for (&e, p) in at.iter().zip(values) {
        fills[e] = std::array::from_fn(|c| {
            (0..M)
                .filter(|&m| w[m] > 0.0)
                .map(|m| w[m] * p[m][c] as f64)
                .sum::<f64>() as f32
        });
    }
}

/// Validation spans cut at track ends: about `fraction` of the tracks of `tracks` with at
/// least [`MIN_OBSERVED`] observations, each losing its observations in the first or the
/// last `len` frames from its first or last observation, `len` drawn from `lengths` (the
/// data's own runs past the ends) and cut short to keep [`KEPT_SHARE`] of them. Seeded by
/// `seed`; `(frame, track)`, sorted.
pub(super) fn end_spans(
    tracks: &Marked,
    lengths: &[usize],
    fraction: f64,
    seed: u64,
) -> Vec<(usize, usize)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut hidden = Vec::new();
    for i in 0..tracks.points {
        let seen: Vec<usize> = (0..tracks.frames).filter(|&k| tracks.seen(k, i)).collect();
        // Every track draws, so that the choice of one does not move the others'.
        let (pick, side, len) = (
            rng.random_bool(fraction),
            rng.random_bool(0.5),
            lengths[rng.random_range(0..lengths.len())],
        );
        if !pick || seen.len() < MIN_OBSERVED {
            continue;
        }
        let most = ((1.0 - KEPT_SHARE) * seen.len() as f64).floor() as usize;
        let (first, last) = (seen[0], seen[seen.len() - 1]);
        let cut: Vec<usize> = if side {
            seen.iter().copied().filter(|&k| k < first + len).collect()
        } else {
            seen.iter().copied().filter(|&k| k + len > last).collect()
        };
        let cut = if cut.len() > most {
            if side {
                cut[..most].to_vec()
            } else {
                cut[cut.len() - most..].to_vec()
            }
        } else {
            cut
        };
        hidden.extend(cut.into_iter().map(|k| (k, i)));
    }
    hidden.sort_unstable();
    hidden
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn end_spans_cut_at_the_ends_and_keep_half_of_each_track() {
        let (t, n) = (40, 50);
        let positions = vec![0f32; 3 * t * n];
        let mut observed = vec![true; t * n];
        // Track 0 starts late (frame 30): a run of 30 past its end; track 1 is seen 3 times.
        for k in 0..30 {
            observed[k * n] = false;
        }
        for k in 3..t {
            observed[k * n + 1] = false;
        }
        let tracks = Marked::new(t, n, &positions, &observed);
        let hidden = end_spans(&tracks, &[6, 30], 0.5, 7);
        let mut by_track = vec![Vec::new(); n];
        for &(k, i) in &hidden {
            assert!(tracks.seen(k, i));
            by_track[i].push(k);
        }
        assert!(by_track[1].is_empty(), "too few observations to cut");
        let cut = by_track.iter().filter(|c| !c.is_empty()).count();
        assert!((15..=35).contains(&cut), "{cut} of {n} tracks cut");
        for (i, frames) in by_track.iter().enumerate().filter(|(_, c)| !c.is_empty()) {
            let seen: Vec<usize> = (0..t).filter(|&k| tracks.seen(k, i)).collect();
            assert!(frames.len() <= seen.len() / 2, "track {i}: {frames:?}");
            // One run of frames at one end of the track's observations.
            let at_start = frames[0] == seen[0];
            let at_end = *frames.last().unwrap() == *seen.last().unwrap();
            assert!(at_start ^ at_end, "track {i}: {frames:?}");
            assert!(frames.windows(2).all(|w| w[1] == w[0] + 1), "{frames:?}");
        }
        assert_eq!(hidden, end_spans(&tracks, &[6, 30], 0.5, 7));
    }
}
