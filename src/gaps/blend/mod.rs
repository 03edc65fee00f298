//! doma's fill: the field's fills ([`field_fill`](super::field_fill::field_fill), with
//! fixed lenders and with lenders chosen frame by frame) blended with the classic fillers
//! ([`Filler`]), each weighted by how well it fills gaps in this very data.
//!
//! No filler wins everywhere. On sparse markers the field's fill beats every baseline in
//! most cases, but a cubic spline wins short gaps of a fast, densely sampled motion; on
//! hundreds or thousands of tracks of one skinned surface the neighbours' motion does
//! better, and on dense marker sets the donors' rigid motion (docs/gap-filling.md, gap
//! filling). So the weights are learned on the data itself, per [`GapClass`] of gap
//! length, in the order the files tell it:
//!
//! 1. **Stage 1** (`stage_one.rs`): the classic fillers, on validation draws. Spans of
//!    the observations are hidden in the pattern of the data's own gaps, every classic
//!    filler fills them from the rest, and per class the convex combination with the
//!    least mean distance is kept where it beats every filler alone cross-fitted.
//! 2. **The leans** (`lean.rs`): a track may move a share of its classic weight to one
//!    filler, where its own validation spans say so clearly.
//! 3. **Stage 2** (`stage_two.rs`): the field's two fills, on the blind spans, observations
//!    the field was fitted without ([`blind_spans`]): stage 1's blend and the field's fills
//!    are blended again per class, kept where the gain is clear.
//! 4. **Beyond the ends** (`ends.rs`), where a fill reaches past a track's first or last
//!    observation: the fillers that predict there, weighed on spans cut at track ends.
//!
//! What both stages share, the residuals and the objective, is `residual.rs`; how many
//! spans, draws and folds, and how clear a gain must be, is [`Validation`]
//! (`validation.rs`). The real gaps are then filled from every observation
//! ([`doma_fill`]); on a recording longer than a window of time ([`super::window`])
//! each validation draw hides its spans in one window, and every filler fills each gap in
//! the window that holds it (docs/design.md §7).

// Index loops over 6 × 6 matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use super::cluster::RigidClusters;
use super::fillers::{Filler, PerFiller, Sources};
use super::marked::Marked;
use super::prediction::FieldPrediction;
use super::spans::{GapIndex, validation_spans};
use super::window::windowed;
use serde::{Deserialize, Serialize};

mod class;
mod ends;
mod held_out;
mod lean;
mod residual;
mod stage_one;
mod stage_two;
mod validation;

pub use class::{GapClass, LENGTH_CLASSES, Pool};
pub use ends::{EndBlend, predicts_beyond_ends};
pub use held_out::HeldOut;
pub use lean::{TrackLean, lean_key};
pub use validation::Validation;

/// Keeps the seed of the spans hidden from a fit ([`blind_spans`]) apart from the draws'.
const BLIND_SEED: u64 = 0x5851_f42d_4c95_7f2d;

/// The validation spans hidden from a fit with blind validation: [`Validation::fraction`]
/// of the observations of the tracks of `tracks` with gaps, in spans as long as its own
/// gaps ([`validation_spans`], stratified by [`GapClass`]), drawn with `seed`; none where
/// no span fits. `(frame, track)`, sorted.
pub fn blind_spans(tracks: &Marked, seed: u64, validation: &Validation) -> Vec<(usize, usize)> {
    let stratum = |len: usize| GapClass::of(len).index();
    validation_spans(tracks, validation.fraction, seed ^ BLIND_SEED, stratum).unwrap_or_default()
}

/// The weights (module docs): stage 1 on validation draws with `seed`, the leans, stage 2
/// on the observed entries of `blind`, observations the field was fitted without, and the
/// weights beyond the ends where `entries` reach past a track's ends.
fn learn(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    blind: &[(usize, usize)],
    entries: &[(usize, usize)],
    validation: &Validation,
) -> Blend {
    let mut blend = learn_inside(tracks, field, seed, blind, validation);
    let past = ends::past_ends(tracks);
    if tracks.frames >= 3 && entries.iter().any(|&(k, i)| past(k, i)) {
        blend.ends = ends::end_blend(tracks, field, seed, validation);
    }
    blend
}

/// [`learn`]'s weights inside the tracks' observations: stages 1 and 2 and the leans.
fn learn_inside(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    blind: &[(usize, usize)],
    validation: &Validation,
) -> Blend {
    if tracks.frames < 3 || tracks.observed.iter().all(|&o| o) {
        return Blend::only(Filler::FieldFill);
    }
    let Some((mut blend, draws)) = stage_one::stage_one(tracks, field, seed, validation) else {
        // Nothing to validate on: the field's fill, as it is fitted.
        return Blend::only(Filler::FieldFill);
    };
    blend.leans = lean::track_leans(&draws, &blend, validation);
    // Stage 1's residuals (up to a window's tenth per draw) are spent: not held through
    // stage 2's fills.
    drop(draws);
    stage_two::stage_two(&mut blend, tracks, field, blind, validation);
    blend
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
    /// What `short` and `long` gave on stage 1's held-out draws, beside the best classic
    /// filler alone there (`None`: not cross-fitted, or a report written before).
    #[serde(default, skip_serializing_if = "held_out::none")]
    pub held_out: [Option<HeldOut>; 2],
    /// The long gaps by length, one per [`GapClass::Long`] ([`LENGTH_CLASSES`]; empty
    /// where there was no long validation entry, and in reports written before).
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
    /// The weights beyond the tracks' ends (`None`: the fill reached no entry there, none
    /// could be validated, or a report written before; those entries then take their
    /// run's length class's weights).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ends: Option<EndBlend>,
}

fn is_zero(v: &usize) -> bool {
    *v == 0
}

/// The weights of one length class of long gaps ([`GapClass::Long`]).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct LengthBlend {
    /// The longest gap of the class, in frames (`None`: no bound).
    pub longest: Option<usize>,
    /// The weights used: the class's own, or the pooled long ones.
    pub weights: Weights,
    /// The validation entries of the class, over the draws.
    pub validated: usize,
    /// Whether the weights are the class's own: it had validation entries in at least
    /// two draws and its choice clearly beat the pooled long weights on its held-out
    /// draws (else it takes the pooled long weights).
    pub own: bool,
    /// Whether its own blend beat every filler alone cross-fitted (else its own weights
    /// are all on the filler that did best alone).
    pub cross_fitted: bool,
    /// What `weights` (its own or the pooled ones) gave on its held-out draws, beside the
    /// best classic filler alone there (`None`: in fewer than two draws, or a report
    /// written before).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOut>,
}

/// doma's fill of every unobserved entry of `tracks` from the field's prediction `field`:
/// each gap filled by the blend of the fillers whose weights did best on validation spans
/// drawn with `seed`, or on `blind`, observed entries of `tracks` that the field was fitted
/// without ([`blind_spans`]), where there are any (module docs). Observed entries are
/// returned as observed; a track never observed is left as it is.
pub fn doma_fill(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    blind: &[(usize, usize)],
    validation: &Validation,
) -> (Vec<f32>, Blend) {
    let n = tracks.points;
    let seen = tracks.seen_tracks();
    let entries: Vec<(usize, usize)> = (0..tracks.frames)
        .flat_map(|k| seen.iter().map(move |&i| (k, i)))
        .filter(|&(k, i)| !tracks.seen(k, i))
        .collect();
    let (fills, blend) = doma_fill_at(tracks, field, seed, blind, &entries, validation);
    let mut out = tracks.positions.to_vec();
    for (&(k, i), v) in entries.iter().zip(fills) {
        let e = 3 * (k * n + i);
        out[e..e + 3].copy_from_slice(&v);
    }
    (out, blend)
}

/// [`doma_fill`]'s values at `entries` `(frame, track)` alone, unobserved entries of
/// tracks observed somewhere: what a long recording's completion holds instead of a second
/// copy of it.
pub fn doma_fill_at(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    blind: &[(usize, usize)],
    entries: &[(usize, usize)],
    validation: &Validation,
) -> (Vec<[f32; 3]>, Blend) {
    let blend = learn(tracks, field, seed, blind, entries, validation);
    // The entries past the ends take their own weights: not filled by the inside ones first.
    let (inside_at, beyond_at) = ends::split_beyond(tracks, &blend, entries);
    let inside: Vec<(usize, usize)> = inside_at.iter().map(|&e| entries[e]).collect();
    let inside_fills = if blend.is_field_only() {
        fill_with(tracks, field, Filler::FieldFill, &inside)
    } else {
        let (inside, used) = (with_gap_lengths(tracks, &inside), blend.in_use());
        windowed(&Sources::new(*tracks, field), &inside, |s, local| {
            combined(&blend, &filler_values_in(s, local, used), local)
        })
    };
    let mut fills = vec![[f32::NAN; 3]; entries.len()];
    for (&e, v) in inside_at.iter().zip(inside_fills) {
        fills[e] = v;
    }
    ends::beyond_ends(tracks, field, &blend, entries, &beyond_at, &mut fills);
    clusters_first(tracks, entries, &mut fills);
    (fills, blend)
}

/// `fills` at `entries` with every entry of a track on a rigid cluster that its mates can
/// carry there taken from them ([`RigidClusters`]): a marker on a prop or a plate moves
/// exactly as its mates do, which no blend weighed on other markers beats.
pub fn clusters_first(tracks: &Marked, entries: &[(usize, usize)], fills: &mut [[f32; 3]]) {
    let clusters = RigidClusters::find(tracks);
    if clusters.is_empty() {
        return;
    }
    for (value, fill) in tracks
        .cluster_fill(&clusters, entries)
        .into_iter()
        .zip(fills)
    {
        if let Some(v) = value {
            *fill = v;
        }
    }
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
    let values = filler_values(sources, entries, EVERY_FILLER);
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
fn filler_values(
    sources: &Sources,
    entries: &[(usize, usize, usize)],
    fillers: u32,
) -> Vec<[[f32; 3]; M]> {
    windowed(sources, entries, |s, local| {
        filler_values_in(s, local, fillers)
    })
}

/// [`filler_values`] from `sources` as they are.
fn filler_values_in(
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
/// what [`doma_fill`] gives there, without filling the other gaps. For measuring a fill
/// on held-out entries beside its parts.
pub struct FillsAt {
    /// The weights, as [`doma_fill`] learns them.
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

/// [`FillsAt`] of the same arguments as [`doma_fill`] and the entries to measure.
pub fn fills_at(
    tracks: &Marked,
    field: &FieldPrediction,
    seed: u64,
    blind: &[(usize, usize)],
    entries: &[(usize, usize)],
    validation: &Validation,
) -> FillsAt {
    let blend = learn(tracks, field, seed, blind, entries, validation);
    let (doma, fillers) = blend_at(
        &Sources::new(*tracks, field),
        &blend,
        &with_gap_lengths(tracks, entries),
    );
    let mut doma = doma;
    let (_, beyond_at) = ends::split_beyond(tracks, &blend, entries);
    ends::beyond_ends(tracks, field, &blend, entries, &beyond_at, &mut doma);
    clusters_first(tracks, entries, &mut doma);
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
            held_out: [None, None],
            by_length: Vec::new(),
            field_validated: 0,
            leans: Vec::new(),
            ends: None,
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

    /// The weights for a gap of `len` frames: its [`GapClass`]'s.
    pub fn weights_for(&self, len: usize) -> &Weights {
        self.class_weights(GapClass::of(len))
    }

    /// The weights of `class`: the short gaps', or a length class's own (the pooled long
    /// ones' where it has none).
    fn class_weights(&self, class: GapClass) -> &Weights {
        match class {
            GapClass::Short => &self.short,
            GapClass::Long(c) => self.by_length.get(c).map_or(&self.long, |b| &b.weights),
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
        let key = (track, lean_key(len));
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

#[cfg(test)]
mod tests;
