//! Where the gaps are, and where to make new ones: each track's gaps ([`Gap`], the one place
//! that finds their borders), their classes and lengths, and the seeded spans of observations
//! hidden to measure a fill ([`hold_out_spans`]) or to validate a blend
//! ([`validation_spans`]). Every span lies inside its track's observations, so a hidden
//! entry is a gap to fill, never an extrapolation past the ends.

use std::ops::Range;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::marked::Marked;

/// A run of frames in which one track is unobserved, with the observed frames that border
/// it (`None` past either end of the clip).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Gap {
    /// The track.
    pub track: usize,
    /// The unobserved frames.
    pub frames: Range<usize>,
    /// The last observed frame before the gap.
    pub before: Option<usize>,
    /// The first observed frame after the gap.
    pub after: Option<usize>,
}

impl Gap {
    /// The frames in the gap.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Never: a gap holds at least one frame (for clippy's `len` without `is_empty`).
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Whether the track is observed on both sides: a gap that interpolation fills, not a
    /// run before the first or after the last observation.
    pub fn is_interior(&self) -> bool {
        self.before.is_some() && self.after.is_some()
    }
}

/// The gaps of track `i` of `tracks`, in frame order; none for a track never observed.
pub fn track_gaps(tracks: &Marked, i: usize) -> Vec<Gap> {
    let t = tracks.frames;
    let mut out = Vec::new();
    let mut before = None;
    let mut start = 0;
    for k in 0..=t {
        if k < t && !tracks.seen(k, i) {
            continue;
        }
        if k > start {
            let after = (k < t).then_some(k);
            if before.is_some() || after.is_some() {
                out.push(Gap {
                    track: i,
                    frames: start..k,
                    before,
                    after,
                });
            }
        }
        before = Some(k);
        start = k + 1;
    }
    out
}

/// Every gap of every track, track by track and in frame order within a track.
pub fn gaps<'a>(tracks: &'a Marked<'a>) -> impl Iterator<Item = Gap> + 'a {
    (0..tracks.points).flat_map(move |i| track_gaps(tracks, i))
}

/// Each track's gaps in frame order, to find the gap of an entry: a few words a gap, where
/// a mask of the recording's entries would grow with its frames.
pub struct GapIndex {
    by_track: Vec<Vec<Range<usize>>>,
}

impl GapIndex {
    /// The gaps of `tracks` ([`gaps`]).
    pub fn new(tracks: &Marked) -> Self {
        let mut by_track = vec![Vec::new(); tracks.points];
        for g in gaps(tracks) {
            by_track[g.track].push(g.frames);
        }
        GapIndex { by_track }
    }

    /// The frames of the gap of track `i` that holds frame `k`; `None` where `k` is
    /// observed, or the track never is.
    pub fn gap_at(&self, k: usize, i: usize) -> Option<Range<usize>> {
        let own = &self.by_track[i];
        let at = own.partition_point(|g| g.end <= k);
        own.get(at).filter(|g| g.contains(&k)).cloned()
    }

    /// The length in frames of the gap that holds entry `(k, i)` ([`GapIndex::gap_at`]).
    pub fn len_at(&self, k: usize, i: usize) -> Option<usize> {
        self.gap_at(k, i).map(|g| g.len())
    }
}

/// The span lengths of [`hold_out_spans`] unless asked otherwise: 2 to 10 frames.
pub const DEFAULT_SPANS: std::ops::RangeInclusive<usize> = 2..=10;

/// A seeded choice of about `fraction` of the observed entries of `tracks` to hide, in
/// spans of `spans` consecutive frames of one track (as a marker or a tracked point is lost
/// for a while). Every span lies inside its track's observations: the track keeps an
/// observation before it and one after, so that every hidden entry is a gap to fill, not an
/// extrapolation past the ends. Returns the entries `(frame, point)`, sorted. Refuses a
/// fraction outside `(0, 1)`, an empty or zero-length span range, and a fraction that cannot
/// be reached.
pub fn hold_out_spans(
    tracks: &Marked,
    fraction: f64,
    spans: std::ops::RangeInclusive<usize>,
    seed: u64,
) -> Result<Vec<(usize, usize)>, String> {
    check_fraction(fraction)?;
    let (shortest, longest) = (*spans.start(), *spans.end());
    if shortest == 0 || shortest > longest {
        return Err(format!(
            "spans of {shortest} to {longest} frames: the lengths must be at least 1 and in order"
        ));
    }
    let t = tracks.frames;
    let every: Vec<usize> = (0..tracks.points).collect();
    hold_out_drawn(tracks, fraction, [shortest, longest], seed, &every, |rng| {
        rng.random_range(shortest..=longest.min(t - 2))
    })
}

/// A seeded choice of about `fraction` of the observed entries of the tracks with gaps to
/// fill, to hide for validating a gap fill: the data's own gaps moved in time. Each draw
/// takes one interior gap and the interior gaps of other tracks that overlap it (markers
/// lost together, as an occlusion or a gap "in several markers at once" hides them), and
/// hides the same pattern at a random other time, each span inside its track's
/// observations (a member that does not fit there is left out). The gap that leads a draw
/// is drawn by its class, `stratum` of its length, uniformly among the classes, then
/// uniformly within its class: where a few short gaps sit among many long ones, the long
/// ones would otherwise take nearly every validation entry. So the spans are as long
/// as the gaps to fill and hidden together as they are: a donor filler validated on one
/// marker at a time while the gaps take three at once would be judged with donors it will
/// not have. The tracks without a gap are left whole, as they are for the real gaps: they
/// are the donors of pattern and rigid-body fill and the frame of reference of Gløersen's,
/// which cannot run once every marker has a gap. Without an interior gap, every track, in
/// spans of [`DEFAULT_SPANS`]. Refuses what [`hold_out_spans`] refuses.
pub fn validation_spans(
    tracks: &Marked,
    fraction: f64,
    seed: u64,
    stratum: impl Fn(usize) -> usize,
) -> Result<Vec<(usize, usize)>, String> {
    let t = tracks.frames;
    let mut interior: Vec<Gap> = gaps(tracks)
        .filter(|g| g.is_interior() && g.len() + 2 <= t)
        .collect();
    if interior.is_empty() {
        let lengths: Vec<usize> = DEFAULT_SPANS.filter(|&l| l + 2 <= t).collect();
        let every: Vec<usize> = (0..tracks.points).collect();
        return hold_out_lengths(tracks, fraction, &lengths, &every, seed);
    }
    interior.sort_by_key(|g| (g.frames.start, g.track));
    hold_out_groups(tracks, fraction, &interior, seed, stratum)
}

/// The draw of [`validation_spans`] from the `interior` gaps, sorted by start.
fn hold_out_groups(
    tracks: &Marked,
    fraction: f64,
    interior: &[Gap],
    seed: u64,
    stratum: impl Fn(usize) -> usize,
) -> Result<Vec<(usize, usize)>, String> {
    let (t, n) = (tracks.frames, tracks.points);
    check_fraction(fraction)?;
    // The interior gaps by class, in the order the classes first appear.
    let mut strata: Vec<(usize, Vec<usize>)> = Vec::new();
    for (j, g) in interior.iter().enumerate() {
        let class = stratum(g.len());
        match strata.iter_mut().find(|(c, _)| *c == class) {
            Some((_, members)) => members.push(j),
            None => strata.push((class, vec![j])),
        }
    }
    let mut gapped: Vec<usize> = interior.iter().map(|g| g.track).collect();
    gapped.sort_unstable();
    gapped.dedup();
    let observed_count = gapped
        .iter()
        .map(|&i| (0..t).filter(|&k| tracks.observed[k * n + i]).count())
        .sum::<usize>();
    let target = (fraction * observed_count as f64).round() as usize;
    let longest = interior.iter().map(Gap::len).max().unwrap_or(0);
    let mut observed = tracks.observed.to_vec();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut hidden = Vec::with_capacity(target);
    let mut tries = 0usize;
    while hidden.len() < target {
        tries += 1;
        if tries > 100 * (target + n) {
            return Err(format!(
                "cannot hide {fraction} of the {observed_count} observations of the tracks \
                 with gaps in the pattern of their gaps (hid {} of {target})",
                hidden.len()
            ));
        }
        let members = &strata[rng.random_range(0..strata.len())].1;
        let g = &interior[members[rng.random_range(0..members.len())]];
        let start = rng.random_range(1..=t - 1 - g.len());
        // The gaps that overlap it: they start less than the longest gap before it ends.
        let from = interior.partition_point(|h| h.frames.start + longest < g.frames.start);
        let to = interior.partition_point(|h| h.frames.start < g.frames.end);
        for h in &interior[from..to] {
            if h.frames.end <= g.frames.start {
                continue;
            }
            let Some(first) = (start + h.frames.start).checked_sub(g.frames.start) else {
                continue;
            };
            let i = h.track;
            let seen = |k: usize| observed[k * n + i];
            if first == 0
                || first + h.len() >= t
                || !(0..first).any(seen)
                || !(first + h.len()..t).any(seen)
            {
                continue;
            }
            hide_span(
                &mut observed,
                n,
                i,
                first..first + h.len(),
                &mut hidden,
                target,
            );
        }
    }
    hidden.sort_unstable();
    Ok(hidden)
}

/// Hides track `i`'s observed entries at `frames` in `observed` (`[T, N]`, `n` tracks),
/// adding them to `hidden`, until it holds `target`.
fn hide_span(
    observed: &mut [bool],
    n: usize,
    i: usize,
    frames: Range<usize>,
    hidden: &mut Vec<(usize, usize)>,
    target: usize,
) {
    for k in frames {
        if hidden.len() == target {
            break;
        }
        if observed[k * n + i] {
            observed[k * n + i] = false;
            hidden.push((k, i));
        }
    }
}

/// [`hold_out_spans`] with each span's length
/// drawn from `lengths` (each at least 1 and at most `T − 2`), uniformly: a list of the
/// data's own gap lengths gives spans distributed as its gaps are.
fn hold_out_lengths(
    tracks: &Marked,
    fraction: f64,
    lengths: &[usize],
    eligible: &[usize],
    seed: u64,
) -> Result<Vec<(usize, usize)>, String> {
    let (Some(&shortest), Some(&longest)) = (lengths.iter().min(), lengths.iter().max()) else {
        return Err("no span lengths to draw from".into());
    };
    let t = tracks.frames;
    if shortest == 0 || longest + 2 > t {
        return Err(format!(
            "spans of {shortest} to {longest} frames do not fit inside {t} frames"
        ));
    }
    hold_out_drawn(
        tracks,
        fraction,
        [shortest, longest],
        seed,
        eligible,
        |rng| lengths[rng.random_range(0..lengths.len())],
    )
}

fn check_fraction(fraction: f64) -> Result<(), String> {
    if fraction > 0.0 && fraction < 1.0 {
        Ok(())
    } else {
        Err(format!(
            "a held-out fraction of {fraction} is not strictly between 0 and 1"
        ))
    }
}

/// The draw of [`hold_out_spans`] and [`hold_out_lengths`] in the `eligible` tracks
/// (`fraction` of their observations): `length` draws each span's length,
/// `[shortest, longest]` bound it (for the checks and the message).
fn hold_out_drawn(
    tracks: &Marked,
    fraction: f64,
    [shortest, longest]: [usize; 2],
    seed: u64,
    eligible: &[usize],
    mut length: impl FnMut(&mut ChaCha8Rng) -> usize,
) -> Result<Vec<(usize, usize)>, String> {
    let (t, n) = (tracks.frames, tracks.points);
    check_fraction(fraction)?;
    let observed_count = eligible
        .iter()
        .map(|&i| (0..t).filter(|&k| tracks.observed[k * n + i]).count())
        .sum::<usize>();
    let target = (fraction * observed_count as f64).round() as usize;
    let mut observed = tracks.observed.to_vec();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut hidden = Vec::with_capacity(target);
    let mut tries = 0usize;
    let cannot = |hid: usize| {
        format!(
            "cannot hide {fraction} of the {observed_count} observations in spans of {shortest} \
             to {longest} frames inside the tracks' observations (hid {hid} of {target})"
        )
    };
    while hidden.len() < target {
        tries += 1;
        if tries > 100 * (target + n) || t < shortest + 2 || eligible.is_empty() {
            return Err(cannot(hidden.len()));
        }
        let i = eligible[rng.random_range(0..eligible.len())];
        // A frame before and one after the span.
        let len = length(&mut rng);
        let start = rng.random_range(1..=t - 1 - len);
        let seen = |k: usize| observed[k * n + i];
        if !(0..start).any(seen) || !(start + len..t).any(seen) {
            continue;
        }
        hide_span(&mut observed, n, i, start..start + len, &mut hidden, target);
    }
    hidden.sort_unstable();
    Ok(hidden)
}

#[cfg(test)]
mod tests;
