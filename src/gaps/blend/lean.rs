//! Between the stages: a track's own lean from its class's weights ([`TrackLean`]),
//! learned on its own validation spans of stage 1.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::class::{GapClass, Pool};
use super::residual::{Pools, Residual};
use super::validation::Validation;
use super::{Blend, M, Weights, classic_fillers};
use crate::gaps::fillers::{Filler, PerFiller};

/// A track's lean, for its short gaps or for its longer ones: this share of its classic
/// fillers' weight moved to one filler in each class of gap length. A motion-capture
/// marker on soft tissue follows the pose better than its neighbours' rigid motion, one
/// on the head the other way; one class's weights, learned on every marker, serve
/// neither. Learned on the track's own validation spans and kept
/// only where it clearly beats the class's weights there cross-fitted (`track_leans`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct TrackLean {
    /// The track.
    pub track: usize,
    /// The gaps it holds for: 0 for the short ones ([`GapClass::Short`]), 1 for the long
    /// ones, every length class ([`lean_key`]).
    pub class: usize,
    /// The filler leaned to, with the share moved to it (the other fillers' zero).
    pub toward: Weights,
    /// The longest gap it holds for, in frames: twice the depth of the deepest validation
    /// entry that chose it (`None`: any, as in blends saved before).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reach: Option<usize>,
}

impl TrackLean {
    /// `w` leaned: the classic fillers' weights scaled by one less the share, the share of
    /// their sum added to the filler leaned to; the field's fills' weights as they are.
    pub fn apply(&self, w: &Weights) -> Weights {
        let share: f64 = self.toward.0.iter().sum();
        let classic: f64 = Filler::ALL
            .iter()
            .filter(|f| !f.is_field())
            .map(|&f| w[f])
            .sum();
        PerFiller::from_fn(|f| {
            if f.is_field() {
                w[f]
            } else {
                (1.0 - share) * w[f] + classic * self.toward[f]
            }
        })
    }
}

/// The key of a gap of `len` frames in [`TrackLean::class`]: 0 for a short gap, 1 for a
/// long one. A track's spans are too few to lean each length class apart.
pub fn lean_key(len: usize) -> usize {
    usize::from(GapClass::of(len).is_long())
}

/// Each track's lean for its short gaps and for its longer ones ([`TrackLean`]): of every
/// classic filler and [`Validation::lean_shares`], the one with the least cost on the
/// track's own validation entries of those gaps in `folds`, each judged by `blend`'s
/// weights for its class leaned so; kept where its gain cross-fitted (the lean chosen on
/// the other draws, judged on each draw in turn) is clear
/// ([`Validation::clearly_positive`]), over the draws that hold such entries,
/// [`Validation::lean_draws`] at least. Short and long gaps lean apart: the fillers that
/// suit a gap of a few frames (the spline) are not those of a second (the donors). By
/// track, then class.
pub(super) fn track_leans(folds: &[Pools<M>], blend: &Blend, v: &Validation) -> Vec<TrackLean> {
    let classic = classic_fillers();
    let leans: Vec<TrackLean> = Filler::ALL
        .into_iter()
        .filter(|f| classic & f.bit() != 0)
        .flat_map(|f| {
            v.lean_shares.iter().map(move |&share| TrackLean {
                track: 0,
                class: 0,
                toward: PerFiller::from_fn(|g| if g == f { share } else { 0.0 }),
                reach: None,
            })
        })
        .collect();
    // Each entry once, with its draw: each class's pool, not the pooled long gaps that
    // repeat them.
    let mut by_track: BTreeMap<(usize, usize), Vec<(usize, &Residual<M>)>> = BTreeMap::new();
    for (d, fold) in folds.iter().enumerate() {
        for class in GapClass::all() {
            for r in &fold[Pool::Class(class).index()] {
                by_track
                    .entry((r.track, lean_key(r.len)))
                    .or_default()
                    .push((d, r));
            }
        }
    }
    // Per class of gap length, its weights with no lean, then with each.
    let leaned: Vec<Vec<Weights>> = GapClass::all()
        .map(|class| {
            let w = *blend.class_weights(class);
            std::iter::once(w)
                .chain(leans.iter().map(|l| l.apply(&w)))
                .collect()
        })
        .collect();
    let mut out = Vec::new();
    for ((track, class), entries) in by_track {
        // cost[d][c]: draw d's cost with no lean (c = 0) or lean c − 1.
        let mut cost = vec![vec![0f64; 1 + leans.len()]; folds.len()];
        for &(d, r) in &entries {
            let weight = r.weight();
            for (c, w) in leaned[GapClass::of(r.len).index()].iter().enumerate() {
                cost[d][c] += weight * r.distance(&w.0);
            }
        }
        let drawn: Vec<usize> = (0..folds.len())
            .filter(|&d| entries.iter().any(|e| e.0 == d))
            .collect();
        if drawn.len() < v.lean_draws {
            continue;
        }
        let total = |c: usize, without: Option<usize>| -> f64 {
            drawn
                .iter()
                .filter(|&&d| Some(d) != without)
                .map(|&d| cost[d][c])
                .sum()
        };
        // Ties go to no lean, then to the earlier lean.
        let best = |without: Option<usize>| {
            (0..=leans.len())
                .min_by(|&x, &y| {
                    total(x, without)
                        .total_cmp(&total(y, without))
                        .then(x.cmp(&y))
                })
                .unwrap_or(0)
        };
        let chosen = best(None);
        // The gain of the lean chosen on the other draws, draw by draw: kept where it is
        // clear, as stage 2 keeps the field's share.
        let gains: Vec<f64> = drawn
            .iter()
            .map(|&d| cost[d][0] - cost[d][best(Some(d))])
            .collect();
        if chosen > 0 && v.clearly_positive(&gains) {
            // Judged only as deep into a gap as its validation entries reach (a span that
            // ran into a real gap is judged near that gap's border), a lean holds for gaps
            // no longer than that depth on both sides: deeper, the spline drifts off and
            // the donors change.
            let reach = 2 * entries.iter().map(|e| e.1.depth).max().unwrap_or(0);
            out.push(TrackLean {
                track,
                class,
                reach: Some(reach),
                ..leans[chosen - 1]
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::gaps::blend::residual::empty_pools;

    #[test]
    fn a_lean_moves_a_share_of_the_classic_weight_and_keeps_the_field_s() {
        let w = PerFiller::from_fn(|f| match f {
            Filler::FieldFill => 0.2,
            Filler::Spline => 0.5,
            Filler::Chain => 0.3,
            _ => 0.0,
        });
        let lean = TrackLean {
            track: 4,
            class: 0,
            toward: PerFiller::from_fn(|f| if f == Filler::Gloersen { 0.5 } else { 0.0 }),
            reach: None,
        };
        // The classic fillers hold 0.8: half of each goes, 0.4 comes to Gløersen's.
        let got = lean.apply(&w);
        let want = [
            (Filler::FieldFill, 0.2),
            (Filler::Spline, 0.25),
            (Filler::Chain, 0.15),
            (Filler::Gloersen, 0.4),
        ];
        for (f, v) in want {
            assert!((got[f] - v).abs() < 1e-12, "{f:?}: {}", got[f]);
        }
        assert!((got.0.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    /// One validation entry of `track`, one frame long: the spline off by `spline` and
    /// Gløersen's fill by `gloersen` along x, every other filler far off.
    fn entry(track: usize, spline: f32, gloersen: f32) -> Arc<Residual<M>> {
        entry_in(track, 1, spline, gloersen)
    }

    /// [`entry`], `depth` frames deep in a gap of twice that.
    fn entry_in(track: usize, depth: usize, spline: f32, gloersen: f32) -> Arc<Residual<M>> {
        Arc::new(Residual {
            errors: std::array::from_fn(|m| match Filler::ALL[m] {
                Filler::Spline => [spline, 0.0, 0.0],
                Filler::Gloersen => [gloersen, 0.0, 0.0],
                _ => [1e3, 0.0, 0.0],
            }),
            len: 2 * depth - 1,
            track,
            depth,
        })
    }

    #[test]
    fn a_track_leans_where_its_own_spans_say_so_cross_fitted() {
        // Every class on the spline. Track 0: the spline exact. Track 1: Gløersen's fill
        // exact in every draw. Track 2: likewise, but in one draw only. Track 3: Gløersen's
        // fill better in one draw by 3, worse in two by 1: over all three, leaning all the
        // way costs 2 against 3, but each draw judged by the lean of the other two costs
        // 3 + 1 + 1, a gain of −2. Track 4: Gløersen's fill better in every draw, by 10,
        // 0.1 and 0.1: a mean gain of 3.4 whose standard error is 3.3, not clear.
        let blend = Blend::only(Filler::Spline);
        let mut folds: Vec<Pools<M>> = (0..3).map(|_| empty_pools()).collect();
        for (d, fold) in folds.iter_mut().enumerate() {
            let short = &mut fold[0];
            short.push(entry(0, 0.0, 1.0));
            short.push(entry(1, 1.0, 0.0));
            if d == 0 {
                short.push(entry(2, 1.0, 0.0));
                short.push(entry(3, 3.0, 0.0));
                short.push(entry(4, 10.0, 0.0));
            } else {
                short.push(entry(3, 0.0, 1.0));
                short.push(entry(4, 0.1, 0.0));
            }
        }
        let leans = track_leans(&folds, &blend, &Validation::default());
        assert_eq!(leans.len(), 1, "{leans:?}");
        assert_eq!((leans[0].track, leans[0].class), (1, 0));
        assert_eq!(leans[0].toward[Filler::Gloersen], 1.0);
        assert_eq!(leans[0].toward.0.iter().sum::<f64>(), 1.0);
        // Applied: the track's weights are Gløersen's alone, the others' the spline's.
        let mut blend = blend;
        blend.leans = leans;
        assert_eq!(blend.weights_at(1, 1)[Filler::Gloersen], 1.0);
        // Learned on its short spans, the lean leaves its long gaps as they were.
        assert_eq!(blend.weights_at(100, 1)[Filler::Spline], 1.0);
        assert_eq!(blend.weights_at(1, 3)[Filler::Spline], 1.0);
        assert_ne!(blend.in_use() & Filler::Gloersen.bit(), 0);
    }

    #[test]
    fn a_lean_holds_only_as_deep_as_it_was_judged() {
        // Every class on the linear fill. In each of three draws, track 0's spline is
        // exact 3 frames deep in a gap, and track 1's Gløersen fill 5 frames deep.
        let mut blend = Blend::only(Filler::Linear);
        let folds: Vec<Pools<M>> = (0..3)
            .map(|_| {
                let mut fold = empty_pools();
                fold[0].extend([entry_in(0, 3, 0.0, 1.0), entry_in(1, 5, 1.0, 0.0)]);
                fold
            })
            .collect();
        blend.leans = track_leans(&folds, &blend, &Validation::default());
        let reach: Vec<_> = blend.leans.iter().map(|l| (l.track, l.reach)).collect();
        assert_eq!(reach, [(0, Some(6)), (1, Some(10))]);
        assert_eq!(blend.weights_at(6, 0)[Filler::Spline], 1.0);
        assert_eq!(blend.weights_at(7, 0)[Filler::Linear], 1.0);
        assert_eq!(blend.weights_at(10, 1)[Filler::Gloersen], 1.0);
        assert_eq!(blend.weights_at(11, 1)[Filler::Linear], 1.0);
    }
}
