//! How far to trust a filled gap: an *expected error* per gap, in the tracks' own units,
//! for a person to check a fill before it goes into inverse kinematics.
//!
//! The donor fillers (chain, segment, rigid-body and pattern fill) each carry the marker
//! through the gap on other markers' motion. Where they agree, the markers around it move
//! as one body and the fill is well determined; where they part, it is not. A gap's
//! *spread* is the root mean square distance of their fills from their mean, over its
//! entries. It is turned into millimetres by a factor *calibrated on the same recording*:
//! spans of observations hidden on purpose (lengths drawn from the recording's own gaps),
//! filled by the chain fill, the median of their true error over their spread. No capture
//! package gives such an estimate; how well it ranks the true errors is measured in
//! docs/gap-filling.md ("Expected error per gap").

use std::ops::Range;

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{Filler, Marked};

/// The donor fillers whose disagreement is the spread.
pub const DONOR_FILLERS: [Filler; 4] = [
    Filler::Chain,
    Filler::Segment,
    Filler::RigidBody,
    Filler::Pattern,
];

/// The most spans hidden to calibrate: enough for a stable median, few enough that a
/// minute at 200 Hz calibrates in well under its fill's time.
pub const CALIBRATION_SPANS: usize = 120;

/// Fewer calibration spans than this and there is no factor: the spread alone is given.
pub const MIN_CALIBRATION_SPANS: usize = 8;

/// The factor from a gap's spread to its expected error, and the spans that chose it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// The median of the chain fill's error over the spread on the calibration spans.
    pub factor: f64,
    /// The calibration spans used.
    pub spans: usize,
}

/// The spread of the [`DONOR_FILLERS`] over each gap of `gaps` (`(track, frames)`): the root
/// mean square distance of their fills from their mean, over the gap's entries.
pub fn spreads(marked: &Marked, gaps: &[(usize, Range<usize>)]) -> Vec<f64> {
    let entries: Vec<(usize, usize)> = gaps
        .iter()
        .flat_map(|(i, frames)| frames.clone().map(move |k| (k, *i)))
        .collect();
    let fills: Vec<Vec<[f32; 3]>> = DONOR_FILLERS
        .iter()
        .map(|f| f.fill_observed(marked, &entries).unwrap_or_default())
        .collect();
    let mut out = Vec::with_capacity(gaps.len());
    let mut at = 0;
    for (_, frames) in gaps {
        let mut sum = 0.0;
        let mut count = 0usize;
        for e in at..at + frames.len() {
            let values: Vec<[f64; 3]> = fills
                .iter()
                .filter_map(|f| f.get(e))
                .filter(|v| v.iter().all(|c| c.is_finite()))
                .map(|v| [v[0] as f64, v[1] as f64, v[2] as f64])
                .collect();
            if values.len() < 2 {
                continue;
            }
            let mean =
                [0, 1, 2].map(|d| values.iter().map(|v| v[d]).sum::<f64>() / values.len() as f64);
            for v in &values {
                sum += (0..3).map(|d| (v[d] - mean[d]).powi(2)).sum::<f64>();
                count += 1;
            }
        }
        at += frames.len();
        out.push(if count == 0 {
            f64::NAN
        } else {
            (sum / count as f64).sqrt()
        });
    }
    out
}

/// The factor of [`expected_errors`], calibrated on spans of `marked`'s observations hidden
/// on purpose: up to [`CALIBRATION_SPANS`], each as long as one of `lengths` (the gaps to
/// estimate, drawn in turn), inside a run of observations of its track with an observed
/// frame on either side, none overlapping, drawn from `seed`. `None` where fewer than
/// [`MIN_CALIBRATION_SPANS`] fit or their spread is zero.
pub fn calibrate(marked: &Marked, lengths: &[usize], seed: u64) -> Option<Calibration> {
    let (t, n) = (marked.frames, marked.points);
    if lengths.is_empty() || t < 3 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Each track's runs of observations, as (track, first, end).
    let mut runs: Vec<(usize, usize, usize)> = Vec::new();
    for i in 0..n {
        let mut k = 0;
        while k < t {
            if !marked.seen(k, i) {
                k += 1;
                continue;
            }
            let start = k;
            while k < t && marked.seen(k, i) {
                k += 1;
            }
            runs.push((i, start, k));
        }
    }
    let mut hidden = marked.observed.to_vec();
    let mut spans: Vec<(usize, Range<usize>)> = Vec::new();
    let mut order: Vec<usize> = (0..lengths.len()).collect();
    order.shuffle(&mut rng);
    for attempt in 0..CALIBRATION_SPANS * 8 {
        if spans.len() == CALIBRATION_SPANS || runs.is_empty() {
            break;
        }
        let len = lengths[order[attempt % order.len()]].max(1);
        // A run long enough for the span and an observed frame on either side.
        let fitting: Vec<&(usize, usize, usize)> =
            runs.iter().filter(|(_, a, b)| b - a >= len + 2).collect();
        let Some(&&(i, a, b)) = fitting.get(rng.random_range(0..fitting.len().max(1))) else {
            continue;
        };
        let first = rng.random_range(a + 1..b - len);
        let frames = first..first + len;
        // Clear of every span already hidden on this track, by a frame.
        if spans
            .iter()
            .any(|(j, f)| *j == i && f.start <= frames.end && frames.start <= f.end)
        {
            continue;
        }
        for k in frames.clone() {
            hidden[k * n + i] = false;
        }
        spans.push((i, frames));
    }
    if spans.len() < MIN_CALIBRATION_SPANS {
        return None;
    }
    let seen = marked.with_observed(&hidden);
    let spread = spreads(&seen, &spans);
    let entries: Vec<(usize, usize)> = spans
        .iter()
        .flat_map(|(i, frames)| frames.clone().map(move |k| (k, *i)))
        .collect();
    let chain = Filler::Chain.fill_observed(&seen, &entries)?;
    let mut ratios = Vec::with_capacity(spans.len());
    let mut at = 0;
    for ((i, frames), s) in spans.iter().zip(&spread) {
        let error: f64 = frames
            .clone()
            .zip(&chain[at..at + frames.len()])
            .map(|(k, v)| {
                let truth = marked.at(k, *i);
                (0..3)
                    .map(|d| (v[d] as f64 - truth[d] as f64).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum::<f64>()
            / frames.len() as f64;
        at += frames.len();
        if s.is_finite() && *s > 0.0 && error.is_finite() {
            ratios.push(error / s);
        }
    }
    if ratios.len() < MIN_CALIBRATION_SPANS {
        return None;
    }
    ratios.sort_by(f64::total_cmp);
    Some(Calibration {
        factor: ratios[ratios.len() / 2],
        spans: ratios.len(),
    })
}

/// Each gap's expected error: its spread ([`spreads`]) times the recording's factor
/// ([`calibrate`], drawn from `seed` with the gaps' own lengths); the spread alone where no
/// factor could be calibrated (and the calibration `None`).
pub fn expected_errors(
    marked: &Marked,
    gaps: &[(usize, Range<usize>)],
    seed: u64,
) -> (Vec<f64>, Option<Calibration>) {
    let spread = spreads(marked, gaps);
    let lengths: Vec<usize> = gaps.iter().map(|(_, f)| f.len()).collect();
    let calibration = calibrate(marked, &lengths, seed);
    let factor = calibration.map_or(1.0, |c| c.factor);
    (spread.iter().map(|s| s * factor).collect(), calibration)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Markers on a rigid plate moving and turning, and one marker that slides on it by
    /// `slide` per frame: the donors agree on the plate's markers and part on the slider.
    fn plate(t: usize, slide: f32) -> (Vec<f32>, Vec<bool>, usize) {
        let n = 6;
        let mut p = vec![0f32; t * n * 3];
        for k in 0..t {
            let a = k as f32 * 0.02;
            let (c, s) = (a.cos(), a.sin());
            for i in 0..n {
                let base = [
                    (i as f32 * 1.3).cos() * 100.0,
                    (i as f32 * 0.7).sin() * 80.0,
                    i as f32 * 15.0,
                ];
                let local = if i == n - 1 {
                    [base[0] + slide * k as f32, base[1], base[2]]
                } else {
                    base
                };
                let e = 3 * (k * n + i);
                p[e] = c * local[0] - s * local[1] + k as f32;
                p[e + 1] = s * local[0] + c * local[1];
                p[e + 2] = local[2] + 0.5 * k as f32;
            }
        }
        (p, vec![true; t * n], n)
    }

    #[test]
    fn the_spread_is_zero_where_the_donors_agree_and_grows_where_they_part() {
        let t = 120;
        let (p, mut seen, n) = plate(t, 0.0);
        for k in 40..60 {
            seen[k * n] = false;
        }
        let m = Marked::new(t, n, &p, &seen);
        let rigid = spreads(&m, &[(0, 40..60)])[0];
        // A marker sliding on the plate (soft tissue): the donors' fills part.
        let (p, mut seen, n) = plate(t, 0.8);
        for k in 40..60 {
            seen[k * n + n - 1] = false;
        }
        let m = Marked::new(t, n, &p, &seen);
        let sliding = spreads(&m, &[(n - 1, 40..60)])[0];
        assert!(
            sliding > 3.0 * rigid && sliding.is_finite(),
            "{sliding} against {rigid}"
        );
    }

    #[test]
    fn the_calibration_hides_spans_clear_of_each_other_and_is_seeded() {
        let t = 400;
        let (p, seen, n) = plate(t, 0.3);
        let m = Marked::new(t, n, &p, &seen);
        let a = calibrate(&m, &[10, 30], 7).unwrap();
        assert_eq!(calibrate(&m, &[10, 30], 7), Some(a));
        assert!(a.spans >= MIN_CALIBRATION_SPANS && a.factor.is_finite() && a.factor > 0.0);
        // Nothing to hide a span in: no factor.
        let short = Marked::new(2, n, &p[..2 * n * 3], &seen[..2 * n]);
        assert_eq!(calibrate(&short, &[10], 7), None);
    }
}
