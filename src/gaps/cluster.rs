//! Rigid clusters found in the data: markers whose pairwise distances stay constant over the
//! frames that see them (a handled prop, a cluster plate, a head band). A marker on such a
//! cluster moves as a rigid body with its mates, so where at least three of them are seen,
//! their rigid motion carries it exactly, through a gap or past its track's ends; no donor
//! chosen by nearness alone (the rigid-body fill's) or blend weighed on other markers does
//! as well there. doma's fill fills those entries from the cluster first
//! ([`super::blend::doma_fill_at`]).
//!
//! A pair is rigid where the population deviation of its distance, over at least
//! [`CLUSTER_FRAMES`] frames seen by both, is at most [`CLUSTER_TOLERANCE`] of its mean,
//! while both markers move [`CLUSTER_MOTION`] times that deviation or more. A
//! marker's cluster is its rigid partners that are rigid among themselves too, taken most
//! rigid first; it is used where it holds at least [`CLUSTER_DONORS`] of them.

use super::donors::{RigidMotion, rigid_motion};
use super::marked::Marked;
use crate::numeric::knn::PointTree;

/// The deviation of a pair's distance, relative to its mean, below which the pair is
/// rigid: 0.5 % (a tenth of a millimetre per 20 mm on a marker plate, where markers on skin
/// drift by a few per cent of their distances as joints bend).
pub const CLUSTER_TOLERANCE: f64 = 0.005;

/// The frames that must see both markers of a pair to judge it.
pub const CLUSTER_FRAMES: usize = 20;

/// How far both markers of a rigid pair must move (the norm of their positions' deviation)
/// against the deviation of their distance: a still body's markers keep their distances
/// too. On the shared knee recording, whose subject holds the upper body still, the pairs
/// within [`CLUSTER_TOLERANCE`] moved 0.2–6.6 times their distance's deviation (10th to
/// 90th percentile); the wands and plates of two other recordings, 340–3200 times.
pub const CLUSTER_MOTION: f64 = 50.0;

/// The mates a marker's cluster needs to carry it: three, a rigid body's least.
pub const CLUSTER_DONORS: usize = 3;

/// The tracks nearest a track, at the frame that sees the most, among which its rigid
/// partners are looked for: a prop's or a plate's markers are near one another, and a
/// mesh's thousands of tracks are not compared pair by pair.
pub const CLUSTER_CANDIDATES: usize = 24;

/// Each track's rigid mates ([`RigidClusters::find`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RigidClusters {
    /// For each track, its mates, most rigid first; empty where it has fewer than
    /// [`CLUSTER_DONORS`].
    mates: Vec<Vec<usize>>,
}

impl RigidClusters {
    /// The clusters of `tracks` (module docs).
    pub fn find(tracks: &Marked) -> RigidClusters {
        let n = tracks.points;
        let candidates = candidates(tracks);
        // The relative deviation of each candidate pair judged rigid.
        let mut rigid: std::collections::HashMap<(usize, usize), f64> = Default::default();
        for (i, near) in candidates.iter().enumerate() {
            for &j in near {
                let key = (i.min(j), i.max(j));
                if rigid.contains_key(&key) {
                    continue;
                }
                if let Some(spread) = pair_spread(tracks, i, j).filter(|&s| s <= CLUSTER_TOLERANCE)
                {
                    rigid.insert(key, spread);
                }
            }
        }
        let is_rigid = |i: usize, j: usize| rigid.get(&(i.min(j), i.max(j))).copied();
        let mates = (0..n)
            .map(|i| {
                let mut partners: Vec<(f64, usize)> = candidates[i]
                    .iter()
                    .filter_map(|&j| is_rigid(i, j).map(|s| (s, j)))
                    .collect();
                partners.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
                let mut cluster: Vec<usize> = Vec::new();
                for (_, j) in partners {
                    if cluster.iter().all(|&m| is_rigid(m, j).is_some()) {
                        cluster.push(j);
                    }
                }
                if cluster.len() < CLUSTER_DONORS {
                    cluster.clear();
                }
                cluster
            })
            .collect();
        RigidClusters { mates }
    }

    /// Track `i`'s mates, most rigid first (empty: it is on no cluster).
    pub fn mates(&self, i: usize) -> &[usize] {
        self.mates.get(i).map_or(&[], Vec::as_slice)
    }

    /// Whether any track is on a cluster.
    pub fn is_empty(&self) -> bool {
        self.mates.iter().all(Vec::is_empty)
    }
}

/// Each track's [`CLUSTER_CANDIDATES`] nearest tracks at the frame that sees the most
/// tracks (none for a track unseen there, or one seen in fewer than [`CLUSTER_FRAMES`]
/// frames).
fn candidates(tracks: &Marked) -> Vec<Vec<usize>> {
    let n = tracks.points;
    let reference =
        (0..tracks.frames).max_by_key(|&k| (0..n).filter(|&i| tracks.seen(k, i)).count());
    let Some(reference) = reference else {
        return vec![Vec::new(); n];
    };
    let enough =
        |i: usize| (0..tracks.frames).filter(|&k| tracks.seen(k, i)).count() >= CLUSTER_FRAMES;
    let usable: Vec<usize> = (0..n)
        .filter(|&i| tracks.seen(reference, i) && enough(i))
        .collect();
    let points: Vec<[f32; 3]> = usable.iter().map(|&i| tracks.at(reference, i)).collect();
    let mut out = vec![Vec::new(); n];
    let Ok(tree) = PointTree::new(&points) else {
        return out;
    };
    for (u, &i) in usable.iter().enumerate() {
        out[i] = tree
            .nearest_k(&points[u], CLUSTER_CANDIDATES + 1)
            .into_iter()
            .filter(|&v| v != u)
            .map(|v| usable[v])
            .collect();
    }
    out
}

/// The population deviation of the distance between tracks `i` and `j` over the frames
/// that see both, relative to its mean; `None` where fewer than [`CLUSTER_FRAMES`] do, the
/// mean is 0, or either track moves less than [`CLUSTER_MOTION`] times that deviation.
fn pair_spread(tracks: &Marked, i: usize, j: usize) -> Option<f64> {
    let both: Vec<usize> = (0..tracks.frames)
        .filter(|&k| tracks.seen(k, i) && tracks.seen(k, j))
        .collect();
    if both.len() < CLUSTER_FRAMES {
        return None;
    }
    let count = both.len() as f64;
    let d: Vec<f64> = both
        .iter()
        .map(|&k| {
            let (p, q) = (tracks.at(k, i), tracks.at(k, j));
            (0..3)
                .map(|c| (p[c] as f64 - q[c] as f64).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let mean = d.iter().sum::<f64>() / count;
    let deviation = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / count).sqrt();
    // The norm of a track's positions' deviation over those frames.
    let movement = |track: usize| {
        (0..3)
            .map(|c| {
                let v: Vec<f64> = both
                    .iter()
                    .map(|&k| tracks.at(k, track)[c] as f64)
                    .collect();
                let m = v.iter().sum::<f64>() / count;
                v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / count
            })
            .sum::<f64>()
            .sqrt()
    };
    let moving = movement(i).min(movement(j)) >= CLUSTER_MOTION * deviation;
    (mean > 0.0 && moving).then(|| deviation / mean)
}

impl Marked<'_> {
    /// The cluster fill at each entry `(k, i)`: track `i`'s mates in `clusters` that are
    /// seen at `k` and at the track's observation on each side, at least
    /// [`CLUSTER_DONORS`], move the track from there by their rigid motion (from both
    /// sides, blended linearly in time, inside a gap; from its one side past its ends);
    /// `None` where no side has enough of them.
    pub fn cluster_fill(
        &self,
        clusters: &RigidClusters,
        entries: &[(usize, usize)],
    ) -> Vec<Option<[f32; 3]>> {
        entries
            .iter()
            .map(|&(k, i)| {
                let mates = clusters.mates(i);
                if mates.is_empty() || self.seen(k, i) {
                    return None;
                }
                let before = (0..k).rev().find(|&f| self.seen(f, i));
                let after = (k + 1..self.frames).find(|&f| self.seen(f, i));
                let moved = |border: Option<usize>| -> Option<[f64; 3]> {
                    let f = border?;
                    let common: Vec<usize> = mates
                        .iter()
                        .copied()
                        .filter(|&j| self.seen(f, j) && self.seen(k, j))
                        .collect();
                    if common.len() < CLUSTER_DONORS {
                        return None;
                    }
                    let at = |g: usize| -> Vec<[f64; 3]> {
                        common.iter().map(|&j| self.at64(g, j)).collect()
                    };
                    let motion: RigidMotion = rigid_motion(&at(f), &at(k));
                    Some(motion.apply(self.at64(f, i)))
                };
                let value = match (moved(before), moved(after)) {
                    (Some(pa), Some(pb)) => {
                        let (a, b) = (before?, after?);
                        let w = (k - a) as f64 / (b - a) as f64;
                        std::array::from_fn(|c| pa[c] + w * (pb[c] - pa[c]))
                    }
                    (Some(p), None) | (None, Some(p)) => p,
                    (None, None) => return None,
                };
                Some(value.map(|v| v as f32))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box of 8 markers carried by the hand of a two-segment arm (3 markers on the upper
    /// arm, 3 on the forearm, the elbow bending), 60 frames; the box turns in the hand, and
    /// its corner at the hand is nearer two forearm markers than any other corner.
    fn prop_and_arm() -> (usize, usize, Vec<f32>) {
        let (t, n) = (60usize, 14usize);
        let corners: Vec<[f64; 3]> = (0..8)
            .map(|c| {
                [
                    0.3 * (c & 1) as f64,
                    0.25 * ((c >> 1) & 1) as f64,
                    0.2 * ((c >> 2) & 1) as f64,
                ]
            })
            .collect();
        let mut positions = Vec::with_capacity(3 * t * n);
        for k in 0..t {
            let s = k as f64 / t as f64;
            let (shoulder, elbow_angle) = (0.6 * s, 0.3 + 1.4 * s);
            let elbow = [0.3 * shoulder.cos(), 0.3 * shoulder.sin(), 0.0];
            let forearm = shoulder + elbow_angle;
            let hand = [
                elbow[0] + 0.28 * forearm.cos(),
                elbow[1] + 0.28 * forearm.sin(),
                0.0,
            ];
            // The upper arm's and the forearm's markers, a little off their bones (skin).
            for (from, angle, len) in [([0.0; 3], shoulder, 0.3), (elbow, forearm, 0.28)] {
                for m in 0..3 {
                    // Skin slides along the bone by a centimetre as the joints turn.
                    let along = len * (0.25 + 0.25 * m as f64)
                        + 0.01 * (0.3 * k as f64 + 2.0 * m as f64).sin();
                    let off = 0.02 * (1.0 + 0.3 * (0.2 * k as f64 + m as f64).sin());
                    positions.extend(
                        [
                            from[0] + along * angle.cos() - off * angle.sin(),
                            from[1] + along * angle.sin() + off * angle.cos(),
                            0.01 * m as f64,
                        ]
                        .map(|v| v as f32),
                    );
                }
            }
            // The box: held at the hand, turning with the forearm and about its own axis.
            let (c1, s1) = (forearm.cos(), forearm.sin());
            let (c2, s2) = ((2.0 * s).cos(), (2.0 * s).sin());
            for p in &corners {
                let q = [p[0], c2 * p[1] - s2 * p[2], s2 * p[1] + c2 * p[2]];
                positions.extend(
                    [
                        hand[0] + c1 * q[0] - s1 * q[1],
                        hand[1] + s1 * q[0] + c1 * q[1],
                        q[2] + 0.02,
                    ]
                    .map(|v| v as f32),
                );
            }
        }
        (t, n, positions)
    }

    #[test]
    fn a_prop_is_found_and_fills_its_marker_exactly_where_the_nearest_donors_do_not() {
        let (t, n, positions) = prop_and_arm();
        let mut observed = vec![true; t * n];
        // The box's corner at the hand (track 6) unseen for 20 frames, and past the
        // recording's end.
        let (gapped, gap) = (6, 20..40);
        for k in gap.clone().chain(55..60) {
            observed[k * n + gapped] = false;
        }
        let tracks = Marked::new(t, n, &positions, &observed);
        let clusters = RigidClusters::find(&tracks);
        // The box's markers are one cluster, the arm's skin markers on none.
        for i in 6..14 {
            let mut mates = clusters.mates(i).to_vec();
            mates.sort_unstable();
            let want: Vec<usize> = (6..14).filter(|&j| j != i).collect();
            assert_eq!(mates, want, "track {i}");
        }
        assert!((0..6).all(|i| clusters.mates(i).is_empty()));
        let entries: Vec<(usize, usize)> = gap.chain(55..60).map(|k| (k, gapped)).collect();
        let truth = |k: usize| tracks.at(k, gapped);
        let error = |p: [f32; 3], k: usize| {
            (0..3)
                .map(|c| (p[c] - truth(k)[c]).powi(2))
                .sum::<f32>()
                .sqrt()
        };
        for (p, &(k, _)) in tracks
            .cluster_fill(&clusters, &entries)
            .iter()
            .zip(&entries)
        {
            let p = p.expect("a cluster fill");
            assert!(error(p, k) < 1e-5, "frame {k}: {}", error(p, k));
        }
        // The rigid-body fill's three nearest donors are not all on the box.
        let inside: Vec<(usize, usize)> = (20..40).map(|k| (k, gapped)).collect();
        let worst = tracks
            .rigid_body(&inside)
            .iter()
            .zip(&inside)
            .map(|(&p, &(k, _))| error(p, k))
            .fold(0f32, f32::max);
        assert!(worst > 1e-3, "{worst}");
    }

    /// doma's fill takes a prop's marker from its cluster first, whatever the blend.
    #[test]
    fn doma_s_fill_fills_a_prop_s_marker_from_its_cluster() {
        let (t, n, positions) = prop_and_arm();
        let mut observed = vec![true; t * n];
        for k in 20..40 {
            observed[k * n + 6] = false;
        }
        // Skin markers with gaps of their own, so that the blend has a choice to make.
        for k in (5..15).chain(45..52) {
            observed[k * n + 4] = false;
        }
        let tracks = Marked::new(t, n, &positions, &observed);
        let field =
            crate::gaps::FieldPrediction::new(n, &positions, &positions[..3 * n], &observed);
        let validation = crate::gaps::blend::Validation::default();
        let (filled, _) = crate::gaps::blend::doma_fill(&tracks, &field, 3, &[], &validation);
        for k in 20..40 {
            let e = 3 * (k * n + 6);
            let truth = tracks.at(k, 6);
            assert!(
                (0..3).all(|c| (filled[e + c] - truth[c]).abs() < 1e-5),
                "frame {k}"
            );
        }
    }

    #[test]
    fn a_hand_computed_pair_spread_and_a_still_pair() {
        // Two tracks 2 apart in 10 frames and 4 apart in 10 (mean 3, deviation 1), both
        // carried 1000 along y and back (moving far more than 50 times the deviation).
        let (t, n) = (20, 2);
        let y = |k: usize| if k.is_multiple_of(2) { 0.0 } else { 1000.0 };
        let positions: Vec<f32> = (0..t)
            .flat_map(|k| [0.0, y(k), 0.0, if k < 10 { 2.0 } else { 4.0 }, y(k), 0.0])
            .collect();
        let observed = vec![true; t * n];
        let tracks = Marked::new(t, n, &positions, &observed);
        assert!((pair_spread(&tracks, 0, 1).unwrap() - 1.0 / 3.0).abs() < 1e-12);
        let few = Marked::new(10, 2, &positions[..60], &observed[..20]);
        assert_eq!(pair_spread(&few, 0, 1), None);
        // Held still, the same pair tells nothing of rigidity: its markers move 0 and 1
        // (the second's deviation), under 50 times the distance's.
        let still: Vec<f32> = (0..t)
            .flat_map(|k| [0.0, 0.0, 0.0, if k < 10 { 2.0 } else { 4.0 }, 0.0, 0.0])
            .collect();
        assert_eq!(
            pair_spread(&Marked::new(t, n, &still, &observed), 0, 1),
            None
        );
    }
}
