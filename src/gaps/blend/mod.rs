//! doma's fill: the field's fills ([`field_fill`](super::field_fill::field_fill), with
//! fixed lenders and with lenders chosen frame by frame) blended with the classic fillers
//! ([`Filler`]), each weighted by how well it fills gaps in this very data.
//!
//! No filler wins everywhere. On sparse markers the field's fill beats every baseline in
//! most cases, but a cubic spline wins short gaps of a fast, densely sampled motion; on
//! hundreds or thousands of tracks of one skinned surface the neighbours' motion does
//! better, and on dense marker sets the donors' rigid motion (docs/results.md, gap
//! filling). So the weights are learned per data set, in two stages (`learn.rs`).
//!
//! First the classic fillers: in each of at least [`VALIDATION_FOLDS`] draws (more, up to
//! [`MAX_VALIDATION_DRAWS`], until each class of gap length to fill holds
//! [`VALIDATION_SPANS`] spans), [`VALIDATION_FRACTION`] of the observations of the tracks
//! with gaps are hidden again, in the pattern of the data's own gaps moved in time
//! ([`validation_spans`]: as long as they are, and as many tracks at once; the tracks
//! without a gap stay whole, as for the real gaps, since the donor fillers and Gløersen's
//! depend on them); every filler fills them from what is left, and the convex combination
//! with the least mean distance over the draws (each span counted once, as the literature
//! counts each gap) is found: one for gaps of at most
//! [`SPLINE_CARRY_FRAMES`](super::SPLINE_CARRY_FRAMES) frames, one for longer gaps pooled,
//! and one for each [`length_class`] of the longer ones seen in two draws or more (the
//! pooled one serves the others). Each is used only if it also beats every filler alone
//! cross-fitted (weights learned on the other draws, judged on the rest in turn): a blend
//! that won by chance on a few spans is not used, and the filler that did best alone fills
//! that class instead.
//!
//! Then the field's fills, on spans the field was not fitted to. The field was fitted to
//! every observation, the validation spans of the first stage included: judged there it
//! has seen the answer and looks far better than inside a gap (on the shared motion-capture
//! recordings, by up to twice). A fit with blind validation hides one draw of validation
//! spans from the field itself ([`blind_spans`]); on those spans alone, split into
//! [`VALIDATION_FOLDS`] folds by span, the first stage's blend and the field's two fills
//! are blended per class the same way. Without blind spans the field's fills take no
//! weight (its fill alone is still `--method field_fill`). The real gaps are then filled
//! from every observation (docs/design.md §7). On a recording longer than a window of time
//! ([`super::window`]) each validation draw hides its spans in one window, and every filler
//! fills each gap in the window that holds it.

// Index loops over 6 × 6 matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use super::field_fill::FieldPrediction;
use super::fillers::{Filler, Marked, PerFiller, Sources};
use super::spans::{GapIndex, validation_spans};
use super::window::windowed;
use learn::learn;
use serde::{Deserialize, Serialize};

/// The share of the observations of the tracks with gaps hidden in each validation draw.
pub const VALIDATION_FRACTION: f64 = 0.1;

/// The validation draws at least, and the groups of draws that cross-fitting holds out in
/// turn.
pub const VALIDATION_FOLDS: usize = 6;

/// The validation draws at most: past [`VALIDATION_FOLDS`], draws are added until every
/// class of gap length that has a gap to fill holds [`VALIDATION_SPANS`] validation spans.
/// A short recording hides only a few spans per draw (a tenth of a 2-second clip is a
/// couple of one-second gaps), too few to weigh the fillers by.
pub const MAX_VALIDATION_DRAWS: usize = 30;

/// The validation spans wanted in each class of gap length with a gap to fill.
pub const VALIDATION_SPANS: usize = 24;

/// Keeps the seed of the spans hidden from a fit ([`blind_spans`]) apart from the draws'.
const BLIND_SEED: u64 = 0x5851_f42d_4c95_7f2d;

/// The validation spans hidden from a fit with blind validation: [`VALIDATION_FRACTION`]
/// of the observations of the tracks of `tracks` with gaps, in spans as long as its own
/// gaps ([`validation_spans`]), drawn with `seed`; none where no span fits.
/// `(frame, track)`, sorted.
pub fn blind_spans(tracks: &Marked, seed: u64) -> Vec<(usize, usize)> {
    validation_spans(tracks, VALIDATION_FRACTION, seed ^ BLIND_SEED, span_class).unwrap_or_default()
}

/// The class of a gap of `len` frames among the short gaps (0) and the [`LENGTH_CLASSES`]
/// of the long ones (1 on): the strata of the validation spans.
fn span_class(len: usize) -> usize {
    length_class(len).map_or(0, |c| c + 1)
}

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

/// The classes of long gaps by length: more than
/// [`SPLINE_CARRY_FRAMES`](super::SPLINE_CARRY_FRAMES) frames up to twice that, then each
/// up to twice the last, the last one unbounded. A convex blend tuned on two-second gaps
/// is not the one for quarter-second ones: rigid-body fill's error grows with the gap, a
/// spline's much faster, and the squared errors of the longest gaps would set the weights
/// of all of them.
pub const LENGTH_CLASSES: usize = 5;

/// The class of a gap of `len` frames among [`LENGTH_CLASSES`]; `None` for a short gap.
pub fn length_class(len: usize) -> Option<usize> {
    let carry = super::SPLINE_CARRY_FRAMES;
    (len > carry).then(|| {
        let (mut class, mut top) = (0, 2 * carry);
        while len > top && class + 1 < LENGTH_CLASSES {
            class += 1;
            top *= 2;
        }
        class
    })
}

/// The longest gap of length class `class`, in frames (`None`: no bound).
pub fn class_longest(class: usize) -> Option<usize> {
    (class + 1 < LENGTH_CLASSES).then(|| super::SPLINE_CARRY_FRAMES << (class + 1))
}

/// The weights a fill used, and the validation entries that chose them.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Blend {
    /// For gaps of at most [`SPLINE_CARRY_FRAMES`](super::SPLINE_CARRY_FRAMES) frames.
    pub short: Weights,
    /// For longer gaps, all lengths pooled: those of a length class without its own.
    pub long: Weights,
    /// The validation entries behind `short` and `long`, over the draws (0: that class had
    /// none and took the other's weights, or the field's fill alone if neither had any).
    pub validated: [usize; 2],
    /// Whether each class's blend beat every filler alone cross-fitted; where not, that
    /// class fills with the filler that did best alone (its weights all on it).
    pub cross_fitted: [bool; 2],
    /// The long gaps by length ([`LENGTH_CLASSES`]; empty where there was no long
    /// validation entry, and in reports written before).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub by_length: Vec<LengthBlend>,
    /// The blind validation entries that weighed the field's fills against the classic
    /// fillers' blend (0: none, and the field's fills take no weight where anything was
    /// validated).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub field_validated: usize,
    /// The tracks whose own validation spans moved part of their classic fillers' weight to
    /// one filler, by track (empty: none, and in reports written before).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub leans: Vec<TrackLean>,
}

fn is_zero(v: &usize) -> bool {
    *v == 0
}

/// The weights of one length class of long gaps ([`length_class`]).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct LengthBlend {
    /// The longest gap of the class, in frames (`None`: no bound).
    pub longest: Option<usize>,
    /// The weights used: the class's own, or the pooled long ones.
    pub weights: Weights,
    /// The validation entries of the class, over the draws.
    pub validated: usize,
    /// Whether the weights are the class's own: it had validation entries in at least
    /// two draws (else it takes the pooled long weights).
    pub own: bool,
    /// Whether its own blend beat every filler alone cross-fitted (else its own weights
    /// are all on the filler that did best alone).
    pub cross_fitted: bool,
}

/// doma's fill of every unobserved entry of `tracks` from the field's prediction `field`:
/// each gap filled by the blend of the fillers whose weights did best on validation spans
/// drawn with `seed`, or on `blind`, observed entries of `tracks` that the field was fitted
/// without ([`blind_spans`]), where there are any (module docs). Observed entries are
/// returned as observed; a track never observed is left as it is.
pub fn blended_fill(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    blind: &[(usize, usize)],
) -> (Vec<f32>, Blend) {
    let n = tracks.points;
    let seen = tracks.seen_tracks();
    let entries: Vec<(usize, usize)> = (0..tracks.frames)
        .flat_map(|k| seen.iter().map(move |&i| (k, i)))
        .filter(|&(k, i)| !tracks.seen(k, i))
        .collect();
    let (fills, blend) = blended_fill_at(tracks, field, seed, blind, &entries);
    let mut out = tracks.positions.to_vec();
    for (&(k, i), v) in entries.iter().zip(fills) {
        let e = 3 * (k * n + i);
        out[e..e + 3].copy_from_slice(&v);
    }
    (out, blend)
}

/// [`blended_fill`]'s values at `entries` `(frame, track)` alone, unobserved entries of
/// tracks observed somewhere: what a long recording's completion holds instead of a second
/// copy of it.
pub fn blended_fill_at(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    blind: &[(usize, usize)],
    entries: &[(usize, usize)],
) -> (Vec<[f32; 3]>, Blend) {
    let blend = learn(tracks, field, seed, blind);
    let fills = if blend.is_field_only() {
        fill_with(tracks, field, Filler::FieldFill, entries)
    } else {
        let (entries, used) = (with_gap_lengths(tracks, entries), blend.in_use());
        windowed(&Sources::new(*tracks, field), &entries, |s, local| {
            combined(&blend, &candidates_in(s, local, used), local)
        })
    };
    (fills, blend)
}

/// `filler`'s values at `entries` `(frame, track)`, unobserved entries of `tracks`, in
/// windows of time on a long recording ([`windowed`]).
pub fn fill_with(
    tracks: &Marked,
    field: &FieldPrediction,
    filler: Filler,
    entries: &[(usize, usize)],
) -> Vec<[f32; 3]> {
    let entries = with_gap_lengths(tracks, entries);
    windowed(&Sources::new(*tracks, field), &entries, |s, local| {
        let pairs: Vec<(usize, usize)> = local.iter().map(|&(k, i, _)| (k, i)).collect();
        filler.fill_at(s, &pairs)
    })
}

/// `entries` `(frame, track)` with the length of each one's gap (0 for an observed entry).
fn with_gap_lengths(tracks: &Marked, entries: &[(usize, usize)]) -> Vec<(usize, usize, usize)> {
    let index = GapIndex::new(tracks);
    entries
        .iter()
        .map(|&(k, i)| (k, i, index.len_at(k, i).unwrap_or(0)))
        .collect()
}

/// The blend of every filler at `entries` `(frame, track, gap length)` by `blend`'s
/// weights for each entry's class, and the fillers' values there.
fn blend_at(
    sources: &Sources,
    blend: &Blend,
    entries: &[(usize, usize, usize)],
) -> (Vec<[f32; 3]>, Vec<[[f32; 3]; M]>) {
    let values = candidates(sources, entries, EVERY_FILLER);
    (combined(blend, &values, entries), values)
}

/// `blend` of the fillers' `values` at `entries`, by each entry's class.
fn combined(
    blend: &Blend,
    values: &[[[f32; 3]; M]],
    entries: &[(usize, usize, usize)],
) -> Vec<[f32; 3]> {
    let with_lengths = values.iter().zip(entries);
    with_lengths
        .map(|(p, &(_, i, len))| blend.combine(len, i, p))
        .collect()
}

/// Every filler's value at `entries` `(frame, track, gap length)`, in the order of
/// [`Filler::ALL`], computed for the fillers whose bits are set in `fillers` (the others'
/// are NaN): in windows of time on a long recording ([`windowed`]).
fn candidates(
    sources: &Sources,
    entries: &[(usize, usize, usize)],
    fillers: u32,
) -> Vec<[[f32; 3]; M]> {
    windowed(sources, entries, |s, local| {
        candidates_in(s, local, fillers)
    })
}

/// [`candidates`] from `sources` as they are.
fn candidates_in(
    sources: &Sources,
    entries: &[(usize, usize, usize)],
    fillers: u32,
) -> Vec<[[f32; 3]; M]> {
    let pairs: Vec<(usize, usize)> = entries.iter().map(|&(k, i, _)| (k, i)).collect();
    let columns = Filler::ALL.map(|f| {
        if fillers & f.bit() != 0 {
            f.fill_at(sources, &pairs)
        } else {
            vec![[f32::NAN; 3]; pairs.len()]
        }
    });
    (0..entries.len())
        .map(|row| std::array::from_fn(|m| columns[m][row]))
        .collect()
}

/// The bits of every filler ([`Filler::bit`]).
const EVERY_FILLER: u32 = (1 << M) - 1;

/// The bits of the classic fillers, those that fill from the observations alone.
fn classic_fillers() -> u32 {
    Filler::ALL
        .iter()
        .filter(|f| !f.is_field())
        .fold(0, |bits, f| bits | f.bit())
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
    blind: &[(usize, usize)],
    entries: &[(usize, usize)],
) -> FillsAt {
    let blend = learn(tracks, field, seed, blind);
    let entries = with_gap_lengths(tracks, entries);
    let (doma, fillers) = blend_at(&Sources::new(*tracks, field), &blend, &entries);
    FillsAt {
        blend,
        doma,
        fillers,
    }
}

impl Blend {
    /// `filler` alone for every gap, nothing validated: what a fill with one filler
    /// reports, and the blend where no validation entry can be drawn.
    pub fn only(filler: Filler) -> Blend {
        let only = Weights::only(filler);
        Blend {
            short: only,
            long: only,
            validated: [0, 0],
            cross_fitted: [false, false],
            by_length: Vec::new(),
            field_validated: 0,
            leans: Vec::new(),
        }
    }

    /// The bits ([`Filler::bit`]) of the fillers with a weight in some class: the others'
    /// values are never read.
    fn in_use(&self) -> u32 {
        let classes = [self.short, self.long]
            .into_iter()
            .chain(self.by_length.iter().map(|c| c.weights))
            .chain(self.leans.iter().map(|l| l.toward));
        classes.fold(0, |bits, w| {
            Filler::ALL
                .iter()
                .filter(|&&f| w[f] > 0.0)
                .fold(bits, |bits, f| bits | f.bit())
        })
    }

    /// The weights for a gap of `len` frames.
    pub fn weights_for(&self, len: usize) -> &Weights {
        self.class_weights(span_class(len))
    }

    /// The weights of class `class` ([`span_class`]: 0 for the short gaps, `c + 1` for
    /// length class `c`).
    fn class_weights(&self, class: usize) -> &Weights {
        match class {
            0 => &self.short,
            c => self.by_length.get(c - 1).map_or(&self.long, |b| &b.weights),
        }
    }

    /// Whether every class fills with the field's fill alone.
    fn is_field_only(&self) -> bool {
        let field_only = Weights::only(Filler::FieldFill);
        self.short == field_only
            && self.long == field_only
            && self.by_length.iter().all(|b| b.weights == field_only)
            && self.leans.is_empty()
    }

    /// The weights for a gap of `len` frames of track `track`: its class's, with the
    /// track's lean where it has one.
    pub fn weights_at(&self, len: usize, track: usize) -> Weights {
        let w = self.weights_for(len);
        let key = (track, lean::class_key(len));
        match self
            .leans
            .binary_search_by_key(&key, |l| (l.track, l.class))
        {
            Ok(at) if self.leans[at].reach.is_none_or(|r| len <= r) => self.leans[at].apply(w),
            _ => *w,
        }
    }

    /// The blend of one entry's filler values `p`, in a gap of `len` frames of track
    /// `track`, by its weights ([`Blend::weights_at`]).
    pub(super) fn combine(&self, len: usize, track: usize, p: &[[f32; 3]; M]) -> [f32; 3] {
        let w = self.weights_at(len, track).0;
        std::array::from_fn(|c| {
            (0..M)
                .filter(|&m| w[m] > 0.0)
                .map(|m| w[m] * p[m][c] as f64)
                .sum::<f64>() as f32
        })
    }
}

mod blind;
mod lean;
mod learn;

pub use lean::TrackLean;

#[cfg(test)]
mod tests;
