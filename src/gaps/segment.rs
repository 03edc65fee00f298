//! The segment fill: the rigid-body fill ([`Marked::rigid_body`]) with its three donors
//! chosen by how they move, not by where they are. In Vicon Nexus the user picks the
//! markers of the gapped marker's own segment; the three nearest at the gap's borders often
//! are not on it (a knee marker beside the other knee, a wrist beside the hip). Here the
//! donors are the triple that best transports the track through its own observations next to
//! the gap:
//!
//! 1. the candidates, the [`SEGMENT_POOL`] nearest of the other tracks seen through the
//!    gap, are ranked by how rigidly they keep their distance to the track around it: the
//!    standard deviation of that distance over the frames around the gap ([`around`])
//!    where both are seen, plus
//!    [`NEARNESS`] times their mean distance at the gap's borders (a near marker's rigid
//!    motion transports less lever error); the first [`SEGMENT_RANKED`] are kept;
//! 2. every triple of them moves the track, as the rigid-body fill would, from the gap's
//!    border to at most [`SEGMENT_SAMPLES`] of its observed frames on that side within
//!    those frames; the triple with the least mean distance to those observations fills the
//!    gap, with the rigid-body fill's blend of the moves from both borders.
//!
//! A motion field learns which markers move together from every frame; this asks the
//! observations around each gap directly. Where no triple can be judged (the track unseen
//! around its gap), the three nearest fill it, as in the rigid-body fill; where fewer than
//! three tracks are seen through the gap, the linear interpolation does.

use super::donors::{DonorGap, RIGID_BODY_DONORS, rigid_motion};
use super::marked::Marked;

/// The nearest tracks seen through a gap whose rigidity [`Marked::segment`] ranks.
pub const SEGMENT_POOL: usize = 64;

/// The candidates whose triples [`Marked::segment`] judges (6: 20 triples).
pub const SEGMENT_RANKED: usize = 6;

/// The observed frames on each side of a gap that a triple is judged on, at most.
pub const SEGMENT_SAMPLES: usize = 16;

/// The weight of a candidate's distance to the track in its rank, against the spread of
/// that distance.
pub const NEARNESS: f64 = 0.05;

/// The fewest frames on each side of a gap that its donors are judged on.
pub const MIN_AROUND: usize = 20;

/// The frames on each side of a gap between observations at `a` and `b` that its donors
/// are ranked and judged on: as many as the gap spans, at least [`MIN_AROUND`].
pub fn around(a: usize, b: usize) -> usize {
    (b - a).max(MIN_AROUND)
}

impl Marked<'_> {
    /// The segment fill at each entry `(k, i)` (module docs); an entry of a track never
    /// observed is whatever its position holds.
    pub fn segment(&self, entries: &[(usize, usize)]) -> Vec<[f32; 3]> {
        self.by_donors(
            entries,
            |i, a, b| self.segment_donors(i, a, b),
            |gap, k| self.rigid_fill(gap, k),
        )
    }

    /// The donors of track `i`'s gap between its observations at `a` and `b` (module
    /// docs); `None` where fewer than three tracks are seen through it.
    fn segment_donors(&self, i: usize, a: usize, b: usize) -> Option<DonorGap> {
        let nearest = self.donors(i, a, b, RIGID_BODY_DONORS)?;
        let w = around(a, b);
        let (lo, hi) = (a.saturating_sub(w), (b + w).min(self.frames - 1));
        let distance = |f: usize, j: usize| {
            let (p, q) = (self.at64(f, i), self.at64(f, j));
            (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>().sqrt()
        };
        // The nearest first: on thousands of dense tracks the spreads of all of them would
        // cost far more than the fill.
        let mut pool: Vec<(f64, usize)> = (0..self.points)
            .filter(|&j| j != i && (a..=b).all(|f| self.seen(f, j)))
            .map(|j| ((distance(a, j) + distance(b, j)) / 2.0, j))
            .filter(|(near, _)| !near.is_nan())
            .collect();
        pool.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        pool.truncate(SEGMENT_POOL);
        let mut ranked: Vec<(f64, usize)> = pool
            .into_iter()
            .map(|(near, j)| {
                let spread = self
                    .distance_spread(i, j, lo..=hi)
                    .map_or(f64::INFINITY, |(spread, _)| spread);
                (spread + NEARNESS * near, j)
            })
            .filter(|(score, _)| !score.is_nan())
            .collect();
        ranked.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        ranked.truncate(SEGMENT_RANKED);
        let before = sample((lo..a).filter(|&f| self.seen(f, i)).collect());
        let after = sample((b + 1..=hi).filter(|&f| self.seen(f, i)).collect());
        let best = best_triple(&ranked, |triple| {
            let (sa, na) = self.transport_error(i, triple, a, &before);
            let (sb, nb) = self.transport_error(i, triple, b, &after);
            (na + nb > 0).then(|| (sa + sb) / (na + nb) as f64)
        });
        Some(match best {
            Some(triple) => DonorGap {
                donors: triple.to_vec(),
                ..nearest
            },
            None => nearest,
        })
    }

    /// The standard deviation and the mean of track `j`'s distance to track `i` over the
    /// `frames` where both are seen; `None` at fewer than three such frames.
    pub(super) fn distance_spread(
        &self,
        i: usize,
        j: usize,
        frames: impl IntoIterator<Item = usize>,
    ) -> Option<(f64, f64)> {
        let d: Vec<f64> = frames
            .into_iter()
            .filter(|&f| self.seen(f, i) && self.seen(f, j))
            .map(|f| {
                let (p, q) = (self.at64(f, i), self.at64(f, j));
                (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>().sqrt()
            })
            .collect();
        if d.len() < 3 {
            return None;
        }
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let variance = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64;
        Some((variance.sqrt(), mean))
    }

    /// The summed distance from track `i`'s observations at `frames` to its position at
    /// frame `from` moved with `donors` (their rigid motion from `from` to that frame), and
    /// the number of frames summed: those where every donor is seen.
    pub(super) fn transport_error(
        &self,
        i: usize,
        donors: [usize; 3],
        from: usize,
        frames: &[usize],
    ) -> (f64, usize) {
        let at = |f: usize| donors.map(|j| self.at64(f, j));
        let (start, p) = (at(from), self.at64(from, i));
        frames
            .iter()
            .filter(|&&f| donors.iter().all(|&j| self.seen(f, j)))
            .fold((0.0, 0), |(sum, count), &f| {
                let q = rigid_motion(&start, &at(f)).apply(p);
                let truth = self.at64(f, i);
                let d = (0..3)
                    .map(|c| (q[c] - truth[c]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                (sum + d, count + 1)
            })
    }
}

/// Of every triple of `ranked`'s tracks (in rank order), the one `judge` gives the least
/// error (the first of a tie); `None` where it judges none.
pub(super) fn best_triple(
    ranked: &[(f64, usize)],
    mut judge: impl FnMut([usize; 3]) -> Option<f64>,
) -> Option<[usize; 3]> {
    let m = ranked.len();
    let mut best: Option<(f64, [usize; 3])> = None;
    for x in 0..m {
        for y in x + 1..m {
            for z in y + 1..m {
                let triple = [ranked[x].1, ranked[y].1, ranked[z].1];
                if let Some(e) = judge(triple).filter(|&e| best.is_none_or(|(b, _)| e < b)) {
                    best = Some((e, triple));
                }
            }
        }
    }
    best.map(|(_, triple)| triple)
}

/// At most [`SEGMENT_SAMPLES`] of `frames`, evenly spaced.
pub(super) fn sample(frames: Vec<usize>) -> Vec<usize> {
    let n = frames.len();
    if n <= SEGMENT_SAMPLES {
        return frames;
    }
    (0..SEGMENT_SAMPLES)
        .map(|s| frames[s * n / SEGMENT_SAMPLES])
        .collect()
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A rigid body of four markers (0..4) turning over 40 frames, and three markers
    /// (4..7) that start beside marker 0 and drift away from it on their own paths; marker
    /// 0 hidden at frames 15..25.
    fn decoy_clip() -> (Vec<f32>, Vec<bool>) {
        let body = [
            [0.0, 0.0, 0.0],
            [0.4, 0.0, 0.0],
            [0.0, 0.5, 0.0],
            [0.0, 0.0, 0.45],
        ];
        let (t, n) = (40, 7);
        let mut positions = Vec::new();
        for k in 0..t {
            let f = k as f64 / 10.0;
            let (c, s) = ((0.8 * f).cos(), (0.8 * f).sin());
            for p in &body {
                let v = [c * p[0] - s * p[1] + f, s * p[0] + c * p[1], p[2] + 0.2 * f];
                positions.extend(v.map(|x| x as f32));
            }
            for d in 0..3 {
                let o = 0.05 * (d as f64 + 1.0);
                let wobble = (1.7 * f + d as f64).sin();
                let v = [f + o, o + 0.3 * wobble, 0.2 * f - o * wobble];
                positions.extend(v.map(|x| x as f32));
            }
        }
        let mut observed = vec![true; t * n];
        for k in 15..25 {
            observed[k * n] = false;
        }
        (positions, observed)
    }

    /// The largest coordinate error of `fill` at `entries`.
    pub(in crate::gaps) fn worst_error(
        tracks: &Marked,
        entries: &[(usize, usize)],
        fill: &[[f32; 3]],
    ) -> f32 {
        fill.iter()
            .zip(entries)
            .map(|(p, &(k, i))| {
                let truth = tracks.at(k, i);
                (0..3).map(|c| (p[c] - truth[c]).abs()).fold(0f32, f32::max)
            })
            .fold(0f32, f32::max)
    }

    #[test]
    fn the_segment_fill_finds_the_body_that_the_nearest_markers_are_not() {
        let (positions, observed) = decoy_clip();
        let tracks = Marked::new(40, 7, &positions, &observed);
        let entries: Vec<(usize, usize)> = (15..25).map(|k| (k, 0)).collect();
        // The three nearest at the borders are the decoys.
        let sorted = |g: Option<DonorGap>| {
            let mut d = g.map(|g| g.donors).unwrap_or_default();
            d.sort_unstable();
            d
        };
        assert_eq!(
            sorted(tracks.donors(0, 14, 25, RIGID_BODY_DONORS)),
            [4, 5, 6]
        );
        assert_eq!(sorted(tracks.segment_donors(0, 14, 25)), [1, 2, 3]);
        let segment = worst_error(&tracks, &entries, &tracks.segment(&entries));
        assert!(segment < 1e-5, "{segment}");
        let rigid = worst_error(&tracks, &entries, &tracks.rigid_body(&entries));
        assert!(rigid > 1e-2, "{rigid}");
    }

    #[test]
    fn unseen_around_its_gap_the_track_takes_the_nearest_donors() {
        let (positions, mut observed) = decoy_clip();
        // Marker 0 seen only at the gap's borders.
        for k in (0..14).chain(26..40) {
            observed[k * 7] = false;
        }
        let tracks = Marked::new(40, 7, &positions, &observed);
        let entries: Vec<(usize, usize)> = (15..25).map(|k| (k, 0)).collect();
        assert_eq!(tracks.segment(&entries), tracks.rigid_body(&entries));
        // With two tracks seen through the gap, the linear fill.
        for k in 15..25 {
            for j in 3..7 {
                observed[k * 7 + j] = false;
            }
        }
        let tracks = Marked::new(40, 7, &positions, &observed);
        let linear = tracks.linear();
        let want: Vec<[f32; 3]> = entries
            .iter()
            .map(|&(k, i)| {
                let e = 3 * (k * 7 + i);
                [linear[e], linear[e + 1], linear[e + 2]]
            })
            .collect();
        assert_eq!(tracks.segment(&entries), want);
    }

    #[test]
    fn at_most_the_samples_are_judged_evenly_spaced() {
        assert_eq!(sample(vec![3, 4, 5]), vec![3, 4, 5]);
        let many: Vec<usize> = (0..64).collect();
        let judged = sample(many);
        assert_eq!(judged.len(), SEGMENT_SAMPLES);
        let step = 64 / SEGMENT_SAMPLES;
        assert_eq!(&judged[..3], &[0, step, 2 * step]);
        assert_eq!(around(10, 12), 20);
        assert_eq!(around(10, 60), 50);
    }
}
