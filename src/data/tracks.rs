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
//!   [`PLACEMENT_NEIGHBOURS`] nearest tracks seen in both.
//!
//! The unobserved entries then store the track's linear interpolation
//! ([`crate::gaps::Marked::linear`], one of the gap fillers of [`crate::gaps`]).

use super::Trajectories;
use crate::gaps::Marked;
use crate::numeric::knn::PointTree;
use crate::{DomaError, Result};

/// The neighbours whose motion places an unseen track's canonical position.
pub const PLACEMENT_NEIGHBOURS: usize = 8;

/// Positions with an observed mask; unobserved entries are never read. A file's tracks
/// as read, before a canonical frame is chosen; not [`super::Trajectories`], whose every
/// entry must be finite for the trainer, nor [`crate::gaps::Marked`], the borrowed view
/// that gap filling reads ([`Tracks::marked`]).
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

    /// The positions `[T, N, 3]`, the tracks consumed (unobserved entries hold whatever the
    /// input held there).
    pub fn into_positions(self) -> Vec<f32> {
        self.positions
    }

    /// The positions `[T, N, 3]` and the mask `[T, N]`, the tracks consumed.
    pub fn into_parts(self) -> (Vec<f32>, Vec<bool>) {
        (self.positions, self.observed)
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

    /// The positions and mask as the gap fillers' view ([`crate::gaps`]).
    pub fn marked(&self) -> Marked<'_> {
        Marked::new(self.frames, self.points, &self.positions, &self.observed)
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
    /// [`Self::most_observed_frame`]) as the module says, the unobserved entries filled by
    /// linear interpolation ([`Marked::linear`]). Complete tracks with reference 0 give exactly the complete
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
        // Filled in place: a long recording is not held twice while it loads.
        let mut filled = self.positions;
        crate::gaps::classic::fill_linear(&mut filled, &self.observed, self.frames, self.points);
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

/// The canonical position of every track in frame `r`: its observation there, else its
/// observation in the nearest frame `s` where it is seen (the earlier of two as near)
/// moved by the mean `s → r` motion of its [`PLACEMENT_NEIGHBOURS`] nearest tracks (in frame `s`)
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
                let near = tree.nearest_k(&p, PLACEMENT_NEIGHBOURS.min(both.len()));
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
}
