//! Observations hidden from a fit: to measure its gap filling ([`HoldOut`],
//! `--holdout-observations`) and to weigh the field's fills on (the blind spans of
//! doma's fill, [`blind_spans`]); each kept with the positions it held ([`HeldOut`]).

use super::tracks::Tracks;
use crate::gaps::blend::{Validation, blind_spans};
use crate::gaps::spans::hold_out_spans;

/// Observations hidden from a fit, and what they were.
#[derive(Clone, Debug, PartialEq)]
pub struct HeldOut {
    /// `(frame, point)`, sorted.
    pub entries: Vec<(usize, usize)>,
    /// The observed position of each entry.
    pub truth: Vec<[f32; 3]>,
}

/// Observations hidden from a fit to measure gap filling ([`hold_out_spans`]).
#[derive(Clone, Debug, PartialEq)]
pub struct HoldOut {
    /// The fraction of the observed entries hidden.
    pub fraction: f64,
    /// The span lengths, in frames (of the clip, after the stride).
    pub spans: std::ops::RangeInclusive<usize>,
    /// The seed of the draw.
    pub seed: u64,
}

/// Hides `h`'s seeded spans of `tracks`' observations ([`hold_out_spans`]), returning them
/// with their true positions.
pub(super) fn hold_out(tracks: &mut Tracks, h: &HoldOut) -> Result<HeldOut, String> {
    let entries = hold_out_spans(&tracks.marked(), h.fraction, h.spans.clone(), h.seed)
        .map_err(|e| format!("--holdout-observations: {e}"))?;
    let truth = taken(tracks, &entries);
    tracks.hide(&entries);
    Ok(HeldOut { entries, truth })
}

/// The positions of `entries` `(frame, point)` of `tracks`.
fn taken(tracks: &Tracks, entries: &[(usize, usize)]) -> Vec<[f32; 3]> {
    let n = tracks.points();
    entries
        .iter()
        .map(|&(k, i)| {
            let e = 3 * (k * n + i);
            let p = &tracks.positions()[e..e + 3];
            [p[0], p[1], p[2]]
        })
        .collect()
}

/// Hides the blind spans drawn with `seed` from `tracks` where it has gaps
/// ([`blind_spans`]), and returns them with the positions they held.
pub(super) fn hide_blind_spans(
    tracks: &mut Tracks,
    seed: Option<u64>,
    validation: &Validation,
) -> Option<HeldOut> {
    let seed = seed?;
    if tracks.observed().iter().all(|&o| o) {
        return None;
    }
    let entries = blind_spans(&tracks.marked(), seed, validation);
    let kept = taken(tracks, &entries);
    tracks.hide(&entries);
    (!entries.is_empty()).then_some(HeldOut {
        entries,
        truth: kept,
    })
}
