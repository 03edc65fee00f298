//! Tracks as a tracker reports them: points seen in some frames and not others.
//!
//! A [`Tracks`] holds positions `[T, N, 3]` and an observed mask `[T, N]`; an unobserved
//! entry may hold anything (NaN, a stale value, ground truth the tracker never saw). It
//! becomes [`Trajectories`] once every track's canonical position is known
//! ([`Tracks::into_trajectories`], docs/design.md §7):
//! - the reference frame is the one with the most observed points (the earliest of a
//!   tie), unless the user names one;
//! - a track observed there starts from its observation;
//! - a track not observed there starts from its observation in the nearest frame `s` where
//!   it is seen, moved by the mean motion from `s` to the reference frame of its
//!   [`NEIGHBOURS`] nearest tracks seen in both.
//!
//! The unobserved entries then store the track's linear interpolation ([`interpolate`]),
//! which is also the first gap-filling baseline ([`crate::gaps::baselines`] has the others).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::Trajectories;
use crate::knn::PointTree;
use crate::{DomaError, Result};

/// The neighbours whose motion places an unseen track's canonical position.
pub const NEIGHBOURS: usize = 8;

/// Positions with an observed mask; unobserved entries are never read.
#[derive(Clone, Debug, PartialEq)]
pub struct Tracks {
    frames: usize,
    points: usize,
    positions: Vec<f32>,
    observed: Vec<bool>,
    /// `[T, N]`, each observation's confidence weight (0 where unobserved).
    weights: Option<Vec<f32>>,
}

impl Tracks {
    /// Checks and wraps positions `[T, N, 3]` and a mask `[T, N]` (both frame-major).
    /// Refuses an empty sequence, lengths that do not match, and an observed entry that is
    /// not finite (naming its frame and point).
    pub fn new(
        frames: usize,
        points: usize,
        positions: Vec<f32>,
        observed: Vec<bool>,
    ) -> std::result::Result<Self, String> {
        if frames == 0 || points == 0 {
            return Err(format!("{frames} frames of {points} points: no tracks"));
        }
        let entries = frames
            .checked_mul(points)
            .ok_or_else(|| format!("{frames} frames of {points} points overflow"))?;
        if positions.len() != entries * 3 || observed.len() != entries {
            return Err(format!(
                "{} coordinates and a mask of {} entries do not fit {frames} frames of {points} points",
                positions.len(),
                observed.len()
            ));
        }
        if let Some(e) = (0..entries)
            .find(|&e| observed[e] && positions[3 * e..3 * e + 3].iter().any(|v| !v.is_finite()))
        {
            return Err(format!(
                "point {} of frame {} is observed but not finite ({:?})",
                e % points,
                e / points,
                &positions[3 * e..3 * e + 3]
            ));
        }
        Ok(Tracks {
            frames,
            points,
            positions,
            observed,
            weights: None,
        })
    }

    /// These tracks with a confidence weight per entry (`[T, N]`): finite and
    /// non-negative where observed (the error names the frame and point); an unobserved
    /// entry's weight is never read.
    pub fn with_weights(mut self, mut weights: Vec<f32>) -> std::result::Result<Self, String> {
        if weights.len() != self.observed.len() {
            return Err(format!(
                "{} weights for {} frames of {} tracks",
                weights.len(),
                self.frames,
                self.points
            ));
        }
        for (e, w) in weights.iter_mut().enumerate() {
            if !self.observed[e] {
                *w = 0.0;
            } else if !(w.is_finite() && *w >= 0.0) {
                return Err(format!(
                    "the weight of point {} in frame {} is {w}: weights are finite and non-negative",
                    e % self.points,
                    e / self.points
                ));
            }
        }
        self.weights = Some(weights);
        Ok(self)
    }

    /// Complete trajectories as tracks, every entry observed.
    pub fn complete(data: Trajectories) -> Self {
        let (frames, points) = (data.frames(), data.points());
        Tracks {
            frames,
            points,
            positions: data.into_positions(),
            observed: vec![true; frames * points],
            weights: None,
        }
    }

    /// `T`.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// `N`.
    pub fn points(&self) -> usize {
        self.points
    }

    /// The positions `[T, N, 3]` (unobserved entries as the file stored them).
    pub fn positions(&self) -> &[f32] {
        &self.positions
    }

    /// The observed mask `[T, N]`.
    pub fn observed(&self) -> &[bool] {
        &self.observed
    }

    /// The confidence weights `[T, N]` (0 where unobserved), if any.
    pub fn weights(&self) -> Option<&[f32]> {
        self.weights.as_deref()
    }

    /// The number of observed entries.
    pub fn observed_count(&self) -> usize {
        self.observed.iter().filter(|&&o| o).count()
    }

    /// The tracks observed in no frame, in order.
    pub fn never_observed(&self) -> Vec<usize> {
        (0..self.points)
            .filter(|&i| (0..self.frames).all(|k| !self.observed[k * self.points + i]))
            .collect()
    }

    /// The tracks at `indices`, in that order (each index checked by the caller).
    pub fn select_points(&self, indices: &[usize]) -> Self {
        let mut positions = Vec::with_capacity(self.frames * indices.len() * 3);
        let mut observed = Vec::with_capacity(self.frames * indices.len());
        let mut weights = self.weights.as_ref().map(|_| Vec::new());
        for k in 0..self.frames {
            for &i in indices {
                let e = k * self.points + i;
                positions.extend_from_slice(&self.positions[3 * e..3 * e + 3]);
                observed.push(self.observed[e]);
                if let (Some(out), Some(w)) = (&mut weights, &self.weights) {
                    out.push(w[e]);
                }
            }
        }
        Tracks {
            frames: self.frames,
            points: indices.len(),
            positions,
            observed,
            weights,
        }
    }

    /// The frames `range`, every `stride`-th. Refuses an empty selection or frames past
    /// the end.
    pub fn select_frames(
        &self,
        range: std::ops::Range<usize>,
        stride: usize,
    ) -> std::result::Result<Self, String> {
        if stride == 0 || range.start >= range.end || range.end > self.frames {
            return Err(format!(
                "frames {}..{} (stride {stride}) do not select a clip of the {} frames",
                range.start, range.end, self.frames
            ));
        }
        let n = self.points;
        let (mut positions, mut observed, mut count) = (Vec::new(), Vec::new(), 0);
        let mut weights = self.weights.as_ref().map(|_| Vec::new());
        for k in range.step_by(stride) {
            positions.extend_from_slice(&self.positions[3 * k * n..3 * (k + 1) * n]);
            observed.extend_from_slice(&self.observed[k * n..(k + 1) * n]);
            if let (Some(out), Some(w)) = (&mut weights, &self.weights) {
                out.extend_from_slice(&w[k * n..(k + 1) * n]);
            }
            count += 1;
        }
        Ok(Tracks {
            frames: count,
            points: n,
            positions,
            observed,
            weights,
        })
    }

    /// Marks the entries `(frame, point)` unobserved.
    pub fn hide(&mut self, entries: &[(usize, usize)]) {
        for &(k, i) in entries {
            self.observed[k * self.points + i] = false;
            if let Some(w) = &mut self.weights {
                w[k * self.points + i] = 0.0;
            }
        }
    }

    /// The frame with the most observed points (the earliest of a tie).
    pub fn most_observed_frame(&self) -> usize {
        let counts = (0..self.frames).map(|k| {
            self.observed[k * self.points..(k + 1) * self.points]
                .iter()
                .filter(|&&o| o)
                .count()
        });
        // `max_by_key` keeps the last maximum; reversing the frames makes it the earliest.
        counts
            .enumerate()
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .max_by_key(|&(_, c)| c)
            .map_or(0, |(k, _)| k)
    }

    /// The trajectories these tracks give: the canonical positions in `reference` (default:
    /// [`Self::most_observed_frame`]) as the module says, the unobserved entries
    /// [`interpolate`]d. Complete tracks with reference 0 give exactly the complete
    /// [`Trajectories`]. Refuses a track that is never observed, with the count and the
    /// first, a reference frame past the end, and one where no track is observed.
    pub fn into_trajectories(self, reference: Option<usize>) -> Result<Trajectories> {
        let never = self.never_observed();
        if let Some(&first) = never.first() {
            return Err(DomaError::InvalidData(format!(
                "{} of the {} tracks are never observed (the first is track {first}); \
                 --drop-unobserved goes on without them",
                never.len(),
                self.points
            )));
        }
        let r = reference.unwrap_or_else(|| self.most_observed_frame());
        if r >= self.frames {
            return Err(DomaError::InvalidConfig(format!(
                "reference frame {r} is past the last of the {} frames",
                self.frames
            )));
        }
        // The canonical positions are the reference frame's observations: with none there,
        // every track would be placed from other frames and L_H would have no point to
        // sample, so such a frame is refused rather than fitted.
        if !self.observed[r * self.points..(r + 1) * self.points].contains(&true) {
            let best = self.most_observed_frame();
            let seen = self.observed[best * self.points..(best + 1) * self.points]
                .iter()
                .filter(|&&o| o)
                .count();
            return Err(DomaError::InvalidConfig(format!(
                "reference frame {r}: no track is observed there, and the canonical positions \
                 are read in the reference frame; choose a frame where tracks are seen (frame \
                 {best}, the default, sees {seen} of the {})",
                self.points
            )));
        }
        let mut filled = self.positions;
        interpolate(self.frames, self.points, &mut filled, &self.observed);
        let canonical = canonical_positions(self.frames, self.points, &filled, &self.observed, r)?;
        let data = Trajectories::new(self.frames, self.points, filled)?.with_observations(
            self.observed,
            r,
            canonical,
        )?;
        match self.weights {
            Some(w) => data.with_weights(w),
            None => Ok(data),
        }
    }
}

/// Replaces, in place, every entry of `positions` (`[T, N, 3]`) that `observed` (`[T, N]`)
/// does not mark by its track's linear interpolation in frame index between the nearest
/// observations before and after, or holds it at the first or last observation past the
/// ends. Only observed entries are read, so the writes never feed later reads. A track with
/// no observation is left as it is.
pub fn interpolate(frames: usize, points: usize, positions: &mut [f32], observed: &[bool]) {
    let mut seen = Vec::with_capacity(frames);
    for i in 0..points {
        seen.clear();
        seen.extend((0..frames).filter(|&k| observed[k * points + i]));
        if seen.is_empty() || seen.len() == frames {
            continue;
        }
        let at = |p: &[f32], k: usize, c: usize| p[3 * (k * points + i) + c];
        let mut next = 0;
        for k in 0..frames {
            if observed[k * points + i] {
                continue;
            }
            while next < seen.len() && seen[next] < k {
                next += 1;
            }
            for c in 0..3 {
                let p = &*positions;
                let value = match (next.checked_sub(1), seen.get(next)) {
                    (Some(q), Some(&b)) => {
                        let a = seen[q];
                        let w = (k - a) as f32 / (b - a) as f32;
                        at(p, a, c) + w * (at(p, b, c) - at(p, a, c))
                    }
                    (Some(q), None) => at(p, seen[q], c),
                    (None, Some(&b)) => at(p, b, c),
                    (None, None) => unreachable!("the track has an observation"),
                };
                positions[3 * (k * points + i) + c] = value;
            }
        }
    }
}

/// The canonical position of every track in frame `r`: its observation there, else its
/// observation in the nearest frame `s` where it is seen (the earlier of two as near)
/// moved by the mean `s → r` motion of its [`NEIGHBOURS`] nearest tracks (in frame `s`)
/// that are seen in both frames, else that observation unmoved.
fn canonical_positions(
    frames: usize,
    points: usize,
    positions: &[f32],
    observed: &[bool],
    r: usize,
) -> Result<Vec<f32>> {
    let seen = |k: usize, i: usize| observed[k * points + i];
    let at = |k: usize, i: usize| -> [f32; 3] {
        let e = 3 * (k * points + i);
        [positions[e], positions[e + 1], positions[e + 2]]
    };
    let mut canonical: Vec<f32> = positions[3 * r * points..3 * (r + 1) * points].to_vec();
    // The unseen tracks grouped by the frame they are placed from.
    let mut by_frame: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for i in (0..points).filter(|&i| !seen(r, i)) {
        let s = (0..frames)
            .filter(|&k| seen(k, i))
            .min_by_key(|&k| (k.abs_diff(r), k))
            .expect("every track is observed somewhere");
        by_frame.entry(s).or_default().push(i);
    }
    for (s, tracks) in by_frame {
        let both: Vec<usize> = (0..points).filter(|&i| seen(s, i) && seen(r, i)).collect();
        let tree = if both.is_empty() {
            None
        } else {
            let cloud: Vec<[f32; 3]> = both.iter().map(|&i| at(s, i)).collect();
            Some(PointTree::new(&cloud)?)
        };
        for j in tracks {
            let p = at(s, j);
            let mut moved = p;
            if let Some(tree) = &tree {
                let near = tree.nearest_k(&p, NEIGHBOURS.min(both.len()));
                for c in 0..3 {
                    let motion: f64 = near
                        .iter()
                        .map(|&n| (at(r, both[n])[c] - at(s, both[n])[c]) as f64)
                        .sum::<f64>()
                        / near.len() as f64;
                    moved[c] = (p[c] as f64 + motion) as f32;
                }
            }
            canonical[3 * j..3 * j + 3].copy_from_slice(&moved);
        }
    }
    Ok(canonical)
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
    tracks: &Tracks,
    fraction: f64,
    spans: std::ops::RangeInclusive<usize>,
    seed: u64,
) -> std::result::Result<Vec<(usize, usize)>, String> {
    check_fraction(fraction)?;
    let (shortest, longest) = (*spans.start(), *spans.end());
    if shortest == 0 || shortest > longest {
        return Err(format!(
            "spans of {shortest} to {longest} frames: the lengths must be at least 1 and in order"
        ));
    }
    let t = tracks.frames;
    hold_out_drawn(
        t,
        tracks.points,
        &tracks.observed,
        fraction,
        [shortest, longest],
        seed,
        |rng| rng.random_range(shortest..=longest.min(t - 2)),
    )
}

/// The length of every interior gap of `observed` `[T, N]` (a run of unobserved frames
/// with an observation on each side), one entry per gap.
pub fn gap_lengths(t: usize, n: usize, observed: &[bool]) -> Vec<usize> {
    let mut lengths = Vec::new();
    for i in 0..n {
        let mut last = None;
        for k in 0..t {
            if !observed[k * n + i] {
                continue;
            }
            if let Some(a) = last
                && k > a + 1
            {
                lengths.push(k - a - 1);
            }
            last = Some(k);
        }
    }
    lengths
}

/// A seeded choice of about `fraction` of the observed entries of `observed` `[T, N]` to
/// hide for validating a gap fill: spans inside the tracks' observations, their lengths
/// drawn from the tracks' own interior gaps (one draw per gap, so the spans are as long as
/// the gaps to fill), or from [`DEFAULT_SPANS`] when there is no interior gap. Refuses
/// what [`hold_out_spans`] refuses.
pub fn validation_spans(
    t: usize,
    n: usize,
    observed: &[bool],
    fraction: f64,
    seed: u64,
) -> std::result::Result<Vec<(usize, usize)>, String> {
    let mut lengths: Vec<usize> = gap_lengths(t, n, observed)
        .into_iter()
        .filter(|&l| l + 2 <= t)
        .collect();
    if lengths.is_empty() {
        lengths = DEFAULT_SPANS.filter(|&l| l + 2 <= t).collect();
    }
    hold_out_lengths(t, n, observed, fraction, &lengths, seed)
}

/// [`hold_out_spans`] on a bare mask `observed` `[T, N]` (frame-major), each span's length
/// drawn from `lengths` (each at least 1 and at most `T − 2`), uniformly: a list of the
/// data's own gap lengths gives spans distributed as its gaps are.
fn hold_out_lengths(
    t: usize,
    n: usize,
    observed: &[bool],
    fraction: f64,
    lengths: &[usize],
    seed: u64,
) -> std::result::Result<Vec<(usize, usize)>, String> {
    let (Some(&shortest), Some(&longest)) = (lengths.iter().min(), lengths.iter().max()) else {
        return Err("no span lengths to draw from".into());
    };
    if shortest == 0 || longest + 2 > t {
        return Err(format!(
            "spans of {shortest} to {longest} frames do not fit inside {t} frames"
        ));
    }
    hold_out_drawn(t, n, observed, fraction, [shortest, longest], seed, |rng| {
        lengths[rng.random_range(0..lengths.len())]
    })
}

fn check_fraction(fraction: f64) -> std::result::Result<(), String> {
    if fraction > 0.0 && fraction < 1.0 {
        Ok(())
    } else {
        Err(format!(
            "a held-out fraction of {fraction} is not strictly between 0 and 1"
        ))
    }
}

/// The draw of [`hold_out_spans`] and [`hold_out_lengths`]: `length` draws each span's
/// length, `[shortest, longest]` bound it (for the checks and the message).
fn hold_out_drawn(
    t: usize,
    n: usize,
    observed: &[bool],
    fraction: f64,
    [shortest, longest]: [usize; 2],
    seed: u64,
    mut length: impl FnMut(&mut ChaCha8Rng) -> usize,
) -> std::result::Result<Vec<(usize, usize)>, String> {
    debug_assert_eq!(observed.len(), t * n);
    check_fraction(fraction)?;
    let observed_count = observed.iter().filter(|&&o| o).count();
    let target = (fraction * observed_count as f64).round() as usize;
    let mut observed = observed.to_vec();
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
        if tries > 100 * (target + n) || t < shortest + 2 || n == 0 {
            return Err(cannot(hidden.len()));
        }
        let i = rng.random_range(0..n);
        // A frame before and one after the span.
        let len = length(&mut rng);
        let start = rng.random_range(1..=t - 1 - len);
        let seen = |k: usize| observed[k * n + i];
        if !(0..start).any(seen) || !(start + len..t).any(seen) {
            continue;
        }
        for k in start..start + len {
            if hidden.len() == target {
                break;
            }
            if observed[k * n + i] {
                observed[k * n + i] = false;
                hidden.push((k, i));
            }
        }
    }
    hidden.sort_unstable();
    Ok(hidden)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `frames` frames of `points` points; point p in frame k is at (k + 10p, 2k, 0).
    fn linear(frames: usize, points: usize) -> Vec<f32> {
        (0..frames)
            .flat_map(|k| (0..points).flat_map(move |p| [(k + 10 * p) as f32, 2.0 * k as f32, 0.0]))
            .collect()
    }

    #[test]
    fn interpolation_is_linear_between_observations_and_constant_past_the_ends() {
        let positions = linear(5, 1);
        // Seen in frames 1 and 3 only: frame 2 is their midpoint, 0 and 4 are held.
        let observed = [false, true, false, true, false];
        let mut poisoned = positions.clone();
        for k in [0, 2, 4] {
            poisoned[3 * k] = f32::NAN;
        }
        interpolate(5, 1, &mut poisoned, &observed);
        let out = poisoned;
        assert_eq!(&out[6..9], &[2.0, 4.0, 0.0]);
        assert_eq!(&out[0..3], &[1.0, 2.0, 0.0]);
        assert_eq!(&out[12..15], &[3.0, 6.0, 0.0]);
    }

    #[test]
    fn an_unseen_track_starts_where_its_neighbours_motion_takes_it() {
        // Three points translating by (1, 2, 0) per frame; point 2 is not seen in frame 0
        // (the most observed frame) but is in frames 1 and 2: it starts 1 frame's motion
        // back from frame 1, exactly its true frame-0 position.
        let positions = linear(3, 3);
        let mut observed = vec![true; 9];
        observed[2] = false;
        let tracks = Tracks::new(3, 3, positions.clone(), observed).unwrap();
        assert_eq!(tracks.most_observed_frame(), 1);
        let data = tracks.clone().into_trajectories(Some(0)).unwrap();
        assert_eq!(data.reference(), 0);
        assert_eq!(&data.canonical()[6..9], &[20.0, 0.0, 0.0]);
        assert!(!data.is_observed(0, 2) && data.is_observed(1, 2));
        // By default the reference is frame 1, where all three are seen.
        let data = tracks.into_trajectories(None).unwrap();
        assert_eq!((data.reference(), data.canonical()), (1, &positions[9..18]));
    }

    #[test]
    fn a_reference_frame_where_no_track_is_seen_is_refused_naming_it() {
        let mut observed = vec![true; 9];
        observed[3..6].fill(false);
        let tracks = Tracks::new(3, 3, linear(3, 3), observed).unwrap();
        let err = tracks.clone().into_trajectories(Some(1)).unwrap_err();
        assert!(matches!(err, DomaError::InvalidConfig(_)), "{err:?}");
        let err = err.to_string();
        assert!(
            err.contains("reference frame 1: no track is observed there")
                && err.contains("frame 0, the default, sees 3 of the 3"),
            "{err}"
        );
        assert_eq!(tracks.into_trajectories(Some(2)).unwrap().reference(), 2);
    }

    #[test]
    fn complete_tracks_are_the_complete_trajectories() {
        let t = Trajectories::new(4, 3, linear(4, 3)).unwrap();
        assert_eq!(
            Tracks::complete(t.clone()).into_trajectories(None).unwrap(),
            t
        );
    }

    #[test]
    fn refusals_name_the_track_and_the_entry() {
        let mut observed = vec![true; 6];
        observed[1] = false;
        observed[4] = false;
        let err = Tracks::new(2, 3, linear(2, 3), observed)
            .unwrap()
            .into_trajectories(None)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("1 of the 3 tracks") && err.contains("track 1"),
            "{err}"
        );
        let mut positions = linear(2, 3);
        positions[3 * 4 + 1] = f32::INFINITY;
        let err = Tracks::new(2, 3, positions, vec![true; 6]).unwrap_err();
        assert!(err.contains("point 1 of frame 1"), "{err}");
        assert!(Tracks::new(2, 3, linear(2, 3), vec![true; 5]).is_err());
    }

    #[test]
    fn held_out_spans_are_seeded_leave_every_track_seen_and_reach_the_fraction() {
        let tracks = Tracks::new(20, 30, linear(20, 30), vec![true; 600]).unwrap();
        let a = hold_out_spans(&tracks, 0.25, DEFAULT_SPANS, 7).unwrap();
        assert_eq!(a, hold_out_spans(&tracks, 0.25, DEFAULT_SPANS, 7).unwrap());
        assert_ne!(a, hold_out_spans(&tracks, 0.25, DEFAULT_SPANS, 8).unwrap());
        assert_eq!(a.len(), 150);
        let mut hidden = tracks.clone();
        hidden.hide(&a);
        assert!(hidden.never_observed().is_empty());
        // In spans: most hidden entries have a hidden neighbour in time on their track.
        let set: std::collections::BTreeSet<_> = a.iter().copied().collect();
        let runs = a
            .iter()
            .filter(|&&(k, i)| set.contains(&(k + 1, i)) || (k > 0 && set.contains(&(k - 1, i))))
            .count();
        assert!(runs as f64 > 0.9 * a.len() as f64, "{runs} of {}", a.len());
        // Inside the observations: every track keeps its first and last frame.
        assert!(a.iter().all(|&(k, _)| k > 0 && k < 19));
        assert!(hold_out_spans(&tracks, 1.0, DEFAULT_SPANS, 0).is_err());
        assert!(hold_out_spans(&tracks, 0.2, 0..=3, 0).is_err());
        // Long spans: runs of at least 6 frames, where the track had them.
        let long = hold_out_spans(&tracks, 0.2, 6..=12, 3).unwrap();
        let set: std::collections::BTreeSet<_> = long.iter().copied().collect();
        let starts: Vec<_> = long
            .iter()
            .filter(|&&(k, i)| !set.contains(&(k.wrapping_sub(1), i)))
            .collect();
        assert!(
            starts.len() * 6 <= long.len() + 6,
            "{} spans for {} entries",
            starts.len(),
            long.len()
        );
    }
}
