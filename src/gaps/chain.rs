//! The chained rigid-body fill: the rigid-body fill ([`Marked::rigid_body`]) for gaps
//! that no three markers are seen through. Rigid-body and pattern fill need donors seen at
//! every frame of the gap; on a recording with real occlusions a gap of a second or two
//! often has none (the markers near a foot or a hand are lost together, or one after
//! another), and then they give the linear interpolation. Here the donors are passed on:
//!
//! 1. from the gap's last observation, the track is moved frame by frame with the rigid
//!    motion of three donors, from the frame where they were taken up (its position there
//!    known, or already transported) to each frame where all three are still seen;
//! 2. where one of them is lost, three others are taken up at the frame before, among the
//!    [`CHAIN_POOL`] tracks nearest to the track's transported position there that are seen
//!    at both frames: the [`SEGMENT_RANKED`] most rigid (the least spread of their
//!    distance to the track over its observed frames around the gap, plus
//!    [`NEARNESS`] times its mean: the segment fill's rank), and of those
//!    the triple whose rigid motion best transports the track from the border the transport
//!    started at to its observations around the gap (the segment fill's judge; the three
//!    most rigid where no triple is seen at the border and at one of those frames). On
//!    dense markers the three most rigid alone now and then took a triple whose motion
//!    transports the track badly: on a 5 s excerpt at 200 Hz, 0.5 s gaps filled at 2.50 mm
//!    against 0.94 judged;
//! 3. the same backwards from the gap's first observation after it, and the two blended
//!    linearly in time, as the rigid-body fill blends its moves from both borders, so
//!    that the fill meets both observations.
//!
//! Past a track's ends the transport runs from its one border alone: the first step
//! carries the track from its last observation to the end of the recording (or from its
//! first back to the start), as a tracked point that leaves the view keeps moving with the
//! surface around it.
//!
//! Where fewer than three tracks are seen at a frame and the one before, the transported
//! position is held there. It is what a motion field knows, that nearby markers move
//! together, asked of the observations through the gap rather than of a fitted field;
//! each hand-over adds the donors' own error, which the blend from the other border
//! bounds. Not a filler of capture software: doma's own, blended and reported beside the
//! named ones.

use std::collections::HashMap;

use super::donors::{RIGID_BODY_DONORS, rigid_motion};
use super::marked::Marked;
use super::segment::{NEARNESS, SEGMENT_RANKED, around, best_triple, sample};

/// The tracks nearest to the transported position among which a hand-over ranks its donors.
pub const CHAIN_POOL: usize = 12;

impl Marked<'_> {
    /// The chained rigid-body fill at each entry `(k, i)` (module docs): an interior gap
    /// is transported once from each border, an entry past a track's ends from its one
    /// border ([`ChainGap::carry`]); an entry of a track never observed is whatever its
    /// position holds.
    pub fn chain(&self, entries: &[(usize, usize)]) -> Vec<[f32; 3]> {
        let mut fills = self.by_donors(
            entries,
            |i, a, b| Some((a, ChainGap::new(self, i, a, b).fill())),
            |(a, fill), k| fill[k - a - 1],
        );
        // Each run past an end is carried once, by its track, its border and its side (a
        // track seen once has one border for both).
        let mut carried: HashMap<(usize, usize, bool), Vec<[f64; 3]>> = HashMap::new();
        let ends = self.track_ends();
        for (v, &(k, i)) in fills.iter_mut().zip(entries) {
            if self.seen(k, i) {
                continue;
            }
            // (border, frames from it, whether the run follows it)
            let past = match ends[i] {
                Some((first, _)) if k < first => (first, first - 1 - k, false),
                Some((_, last)) if k > last => (last, k - last - 1, true),
                _ => continue,
            };
            let carry = carried
                .entry((i, past.0, past.2))
                .or_insert_with(|| ChainGap::open(self, i, past.0, past.2).carry(past.2));
            *v = carry[past.1].map(|x| x as f32);
        }
        fills
    }
}

/// Track `i`'s gap between its observations at `a` and `b`, with what its hand-overs
/// judge again and again, kept for the gap: each candidate's rank and each triple's error
/// transported from each border (neither depends on the frame of the hand-over).
struct ChainGap<'t, 'a> {
    tracks: &'t Marked<'a>,
    i: usize,
    a: usize,
    b: usize,
    /// The track's observed frames around the gap ([`around`]).
    around: Vec<usize>,
    rank: HashMap<usize, f64>,
    transported: HashMap<(usize, [usize; RIGID_BODY_DONORS]), Option<f64>>,
}

impl<'t, 'a> ChainGap<'t, 'a> {
    fn new(tracks: &'t Marked<'a>, i: usize, a: usize, b: usize) -> Self {
        let w = around(a, b);
        let around = (a.saturating_sub(w)..=a)
            .chain(b..=(b + w).min(tracks.frames - 1))
            .filter(|&f| tracks.seen(f, i))
            .collect();
        Self::with_around(tracks, i, a, b, around)
    }

    /// Track `i`'s run past its end at `border`, its last observation (`forward`) or its
    /// first: as a gap whose other border lies beyond the recording, judged on the
    /// observations on `border`'s side alone.
    fn open(tracks: &'t Marked<'a>, i: usize, border: usize, forward: bool) -> Self {
        let t = tracks.frames;
        let run = if forward { t - 1 - border } else { border };
        let w = around(0, run + 1);
        let frames = if forward {
            border.saturating_sub(w)..=border
        } else {
            border..=(border + w).min(t - 1)
        };
        let around = frames.filter(|&f| tracks.seen(f, i)).collect();
        Self::with_around(tracks, i, border, border, around)
    }

    fn with_around(
        tracks: &'t Marked<'a>,
        i: usize,
        a: usize,
        b: usize,
        around: Vec<usize>,
    ) -> Self {
        ChainGap {
            tracks,
            i,
            a,
            b,
            around,
            rank: HashMap::new(),
            transported: HashMap::new(),
        }
    }

    /// Frames `a + 1..b`: the transports from both borders blended linearly in time.
    fn fill(mut self) -> Vec<[f64; 3]> {
        let (a, b) = (self.a, self.b);
        let forward = self.transport(a, b - a - 1, true);
        let backward = self.transport(b, b - a - 1, false);
        (a + 1..b)
            .map(|k| {
                let (p, q) = (forward[k - a - 1], backward[b - 1 - k]);
                let s = (k - a) as f64 / (b - a) as f64;
                std::array::from_fn(|c| p[c] + s * (q[c] - p[c]))
            })
            .collect()
    }

    /// An open run's frames (made by [`ChainGap::open`]), nearest the border first: the
    /// track transported from its one border on to the end of the recording (`forward`)
    /// or back to its start.
    fn carry(mut self, forward: bool) -> Vec<[f64; 3]> {
        let a = self.a;
        let steps = if forward {
            self.tracks.frames - 1 - a
        } else {
            a
        };
        self.transport(a, steps, forward)
    }

    /// The track transported from its observation at `from`, `steps` frames on (`forward`)
    /// or back, one frame at a time: its position at each, nearest `from` first.
    fn transport(&mut self, from: usize, steps: usize, forward: bool) -> Vec<[f64; 3]> {
        let tracks = self.tracks;
        let step = |f: usize| if forward { f + 1 } else { f - 1 };
        let mut transported = Vec::with_capacity(steps);
        // The donors and the frame they were taken up at, with the track's position there.
        let mut held: Option<([usize; RIGID_BODY_DONORS], usize, [f64; 3])> = None;
        let (mut previous, mut position) = (from, tracks.at64(from, self.i));
        let mut k = from;
        for _ in 0..steps {
            k = step(k);
            let still = held.filter(|(donors, _, _)| donors.iter().all(|&j| tracks.seen(k, j)));
            let taken = still.or_else(|| {
                self.hand_over(from, previous, k, position)
                    .map(|donors| (donors, previous, position))
            });
            if let Some((donors, start, p)) = taken {
                let at = |f: usize| donors.map(|j| tracks.at64(f, j));
                position = rigid_motion(&at(start), &at(k)).apply(p);
            }
            held = taken;
            transported.push(position);
            previous = k;
        }
        transported
    }

    /// Three donors taken up at frame `from` (the track there at `p`) for frame `to`, in a
    /// transport that started at the track's observation at `border`: of the [`CHAIN_POOL`]
    /// tracks nearest to `p` seen at both frames, the triple of the most rigid that best
    /// transports the track from `border` to its observations around the gap (module docs);
    /// `None` where fewer than three are seen at both frames.
    fn hand_over(
        &mut self,
        border: usize,
        from: usize,
        to: usize,
        p: [f64; 3],
    ) -> Option<[usize; RIGID_BODY_DONORS]> {
        let (tracks, i) = (self.tracks, self.i);
        let mut near: Vec<(f64, usize)> = (0..tracks.points)
            .filter(|&j| j != i && tracks.seen(from, j) && tracks.seen(to, j))
            .map(|j| {
                let q = tracks.at64(from, j);
                let d = (0..3).map(|c| (q[c] - p[c]).powi(2)).sum::<f64>().sqrt();
                (d, j)
            })
            .filter(|(d, _)| d.is_finite())
            .collect();
        if near.len() < RIGID_BODY_DONORS {
            return None;
        }
        near.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        near.truncate(CHAIN_POOL);
        let around = &self.around;
        let mut ranked: Vec<(f64, usize)> = near
            .into_iter()
            .map(|(_, j)| {
                let rank = *self.rank.entry(j).or_insert_with(|| {
                    tracks
                        .distance_spread(i, j, around.iter().copied())
                        .map_or(f64::INFINITY, |(spread, mean)| spread + NEARNESS * mean)
                });
                (rank, j)
            })
            .collect();
        ranked.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        ranked.truncate(SEGMENT_RANKED);
        let transported = &mut self.transported;
        let best = best_triple(&ranked, |triple| {
            *transported
                .entry((border, triple))
                .or_insert_with(|| tracks.transported_from(i, triple, border, around))
        });
        Some(best.unwrap_or_else(|| std::array::from_fn(|d| ranked[d].1)))
    }
}

impl Marked<'_> {
    /// The mean distance from track `i`'s observations at the frames of `around` where
    /// `donors` are seen (at most [`SEGMENT_SAMPLES`](super::segment::SEGMENT_SAMPLES) of
    /// them, evenly spaced) to its position at `border` moved there with the donors' rigid
    /// motion (the segment fill's judge); `None` where the donors are unseen at `border`
    /// or at every such frame.
    fn transported_from(
        &self,
        i: usize,
        donors: [usize; RIGID_BODY_DONORS],
        border: usize,
        around: &[usize],
    ) -> Option<f64> {
        let seen = |f: usize| donors.iter().all(|&j| self.seen(f, j));
        if !seen(border) {
            return None;
        }
        let frames = sample(
            around
                .iter()
                .copied()
                .filter(|&f| f != border && seen(f))
                .collect(),
        );
        let (total, count) = self.transport_error(i, donors, border, &frames);
        (count > 0).then(|| total / count as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaps::segment::tests::worst_error as worst;

    /// Seven markers of one rigid body turning and moving over 60 frames; marker 0 hidden
    /// at frames 20..40, markers 1–3 at 30..45 and markers 4–6 at 10..25: no three are
    /// seen through the gap, three are seen at every frame of it.
    fn handed_over() -> (usize, usize, Vec<f32>, Vec<bool>) {
        let body = [
            [0.0, 0.0, 0.0],
            [0.3, 0.1, 0.0],
            [0.0, 0.4, 0.1],
            [0.1, 0.0, 0.35],
            [-0.3, 0.1, 0.05],
            [0.0, -0.4, 0.1],
            [0.15, 0.2, -0.3],
        ];
        let (t, n) = (60, body.len());
        let mut positions = Vec::new();
        for k in 0..t {
            let f = k as f64 / 10.0;
            let (c, s) = ((0.7 * f).cos(), (0.7 * f).sin());
            let (cx, sx) = ((0.4 * f).cos(), (0.4 * f).sin());
            for p in &body {
                // About z, then about x, then moved along a curve.
                let q = [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]];
                let r = [q[0], cx * q[1] - sx * q[2], sx * q[1] + cx * q[2]];
                let v = [r[0] + f, r[1] + 0.3 * f * f, r[2] - 0.5 * f];
                positions.extend(v.map(|x| x as f32));
            }
        }
        let mut observed = vec![true; t * n];
        let mut hide = |frames: std::ops::Range<usize>, tracks: std::ops::Range<usize>| {
            for k in frames {
                for i in tracks.clone() {
                    observed[k * n + i] = false;
                }
            }
        };
        hide(20..40, 0..1);
        hide(30..45, 1..4);
        hide(10..25, 4..7);
        (t, n, positions, observed)
    }

    #[test]
    fn donors_passed_on_transport_a_rigid_body_through_a_gap_none_is_seen_through() {
        let (t, n, positions, observed) = handed_over();
        let tracks = Marked::new(t, n, &positions, &observed);
        let entries: Vec<(usize, usize)> = (20..40).map(|k| (k, 0)).collect();
        let chain = worst(&tracks, &entries, &tracks.chain(&entries));
        assert!(chain < 1e-4, "{chain}");
        // Rigid-body fill has no donor seen from frame 19 to 40: the linear fill, far off.
        let rigid = worst(&tracks, &entries, &tracks.rigid_body(&entries));
        assert!(rigid > 0.1, "{rigid}");
        // Asked in any order, one entry or all, the same values.
        let one = tracks.chain(&[(33, 0)]);
        let all = tracks.chain(&entries);
        assert_eq!(one[0], all[13]);
    }

    /// A rigid body rolling about the x axis: the three markers nearest to track 0 lie
    /// on that axis, so their motion says nothing of the roll; three further ones do not.
    #[test]
    fn a_hand_over_takes_the_triple_that_transports_the_track_not_the_nearest() {
        let body = [
            [0.0, 0.3, 0.0],
            [-0.1, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.1, 0.0, 0.0],
            [0.5, 0.6, 0.2],
            [-0.5, 0.7, -0.1],
            [0.2, 0.8, 0.5],
        ];
        let (t, n) = (50, body.len());
        let mut positions = Vec::new();
        for k in 0..t {
            let f = k as f64 / 10.0;
            let (c, s) = ((0.9 * f).cos(), (0.9 * f).sin());
            for p in &body {
                let v = [
                    p[0] + 0.2 * f,
                    c * p[1] - s * p[2],
                    s * p[1] + c * p[2] + 0.1 * f,
                ];
                positions.extend(v.map(|x| x as f32));
            }
        }
        let mut observed = vec![true; t * n];
        for k in 20..30 {
            observed[k * n] = false;
        }
        let tracks = Marked::new(t, n, &positions, &observed);
        let entries: Vec<(usize, usize)> = (20..30).map(|k| (k, 0)).collect();
        let chain = worst(&tracks, &entries, &tracks.chain(&entries));
        assert!(chain < 1e-4, "{chain}");
        // The three nearest, equally rigid, transport the track far off its observations.
        let around: Vec<usize> = (0..20).chain(30..t).collect();
        let on_axis = tracks.transported_from(0, [1, 2, 3], 19, &around);
        assert!(on_axis.is_some_and(|e| e > 0.05), "{on_axis:?}");
        let off_axis = tracks.transported_from(0, [1, 4, 6], 19, &around);
        assert!(off_axis.is_some_and(|e| e < 1e-4), "{off_axis:?}");
    }

    #[test]
    fn with_no_donors_the_chain_holds_each_border_and_is_the_linear_fill() {
        // Three tracks: marker 0's gap has two others seen, fewer than three.
        let (t, n) = (30, 3);
        let positions: Vec<f32> = (0..3 * t * n)
            .map(|e| ((e as f32) * 0.37).sin() + (e / 9) as f32 * 0.1)
            .collect();
        let mut observed = vec![true; t * n];
        for k in 10..20 {
            observed[k * n] = false;
        }
        let tracks = Marked::new(t, n, &positions, &observed);
        let entries: Vec<(usize, usize)> = (10..20).map(|k| (k, 0)).collect();
        let linear = tracks.linear();
        for (p, &(k, i)) in tracks.chain(&entries).iter().zip(&entries) {
            let e = 3 * (k * n + i);
            for c in 0..3 {
                assert!((p[c] - linear[e + c]).abs() < 1e-5, "{k}: {p:?}");
            }
        }
    }

    #[test]
    fn past_a_track_s_ends_the_rigid_body_carries_it_and_observations_stay() {
        let (t, n, positions, mut observed) = handed_over();
        // Marker 0 unseen before frame 8 and from frame 50 to the end: the rigid body
        // carries it there exactly, through the hand-overs of markers 4–6 (unseen 10..25).
        for k in (0..8).chain(50..t) {
            observed[k * n] = false;
        }
        let tracks = Marked::new(t, n, &positions, &observed);
        let entries: Vec<(usize, usize)> = (0..8).chain(50..t).map(|k| (k, 0)).collect();
        let chain = worst(&tracks, &entries, &tracks.chain(&entries));
        assert!(chain < 1e-4, "{chain}");
        assert_eq!(tracks.chain(&[(5, 1)]), [tracks.at(5, 1)]);
    }

    #[test]
    fn past_a_track_s_ends_with_no_donors_the_border_is_held() {
        let (t, n) = (30, 3);
        let positions: Vec<f32> = (0..3 * t * n).map(|e| ((e as f32) * 0.37).sin()).collect();
        let mut observed = vec![true; t * n];
        for k in 20..t {
            observed[k * n] = false;
        }
        let tracks = Marked::new(t, n, &positions, &observed);
        assert_eq!(tracks.chain(&[(25, 0)]), [tracks.at(19, 0)]);
        // Seen once: held on both sides.
        let mut once = vec![true; t * n];
        for k in (0..t).filter(|&k| k != 12) {
            once[k * n] = false;
        }
        let tracks = Marked::new(t, n, &positions, &once);
        let both = tracks.chain(&[(3, 0), (29, 0)]);
        assert_eq!(both, [tracks.at(12, 0), tracks.at(12, 0)]);
    }
}
