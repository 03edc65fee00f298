use super::*;
use crate::gaps::blend::stage_one::span_lengths;
use crate::gaps::marked::Marked;
use crate::gaps::prediction::FieldPrediction;

/// Residuals of 1-D errors: filler 0's `a`, filler 1's `b`, every other filler far off.
fn residuals_of(a: &[f32], b: &[f32]) -> Vec<Residual<M>> {
    a.iter()
        .zip(b)
        .map(|(&a, &b)| Residual {
            errors: std::array::from_fn(|m| match m {
                0 => [a, 0.0, 0.0],
                1 => [b, 0.0, 0.0],
                _ => [1e3, 0.0, 0.0],
            }),
            len: 1,
            track: 0,
            depth: 1,
        })
        .collect()
}

#[test]
fn the_mean_distance_is_not_led_by_one_far_miss() {
    // Filler 0 exact on four entries and 10 off on the fifth; filler 1 3 off on all.
    // Mean distance, w₀ + w₁ = 1: 4·3w₁ + |10w₀ + 3w₁| = 10 + 5w₁, least at w₁ = 0.
    // Squared: 4·9w₁² + (10 − 7w₁)², least at w₁ = 140/170.
    let r = residuals_of(&[0.0, 0.0, 0.0, 0.0, 10.0], &[3.0; 5]);
    let refs: Vec<&Residual<M>> = r.iter().collect();
    let w = mean_distance(&refs, u32::MAX);
    // Reweighting nears a vertex of the simplex slowly: within a few hundredths.
    assert!(w[0] > 0.97 && w[0] + w[1] > 1.0 - 1e-9, "{w:?}");
    assert!(cost(r.iter(), &w) < 10.15, "{w:?}");
    let mut squared = [0.0; M];
    (squared[0], squared[1]) = (30.0 / 170.0, 140.0 / 170.0);
    assert!((cost(r.iter(), &squared) - (10.0 + 5.0 * 140.0 / 170.0)).abs() < 1e-9);
    assert!(cost(r.iter(), &w) < cost(r.iter(), &squared));
}

#[test]
fn spans_are_each_track_s_runs_of_consecutive_frames() {
    // Track 0: frames 2–4 and 7; track 1: frame 3; unsorted.
    let hidden = [(7, 0), (3, 1), (2, 0), (4, 0), (3, 0)];
    let mut lengths = span_lengths(&hidden);
    lengths.sort_unstable();
    assert_eq!(lengths, [1, 1, 3]);
    assert!(span_lengths(&[]).is_empty());
}

#[test]
fn residuals_keep_the_order_of_the_entries_asked_for() {
    // Track 0 hidden at frames 3 to 5 of 10; the first entry asked for is observed,
    // so no gap: its slot is `None` and the others stay where they were asked.
    let (t, n) = (10usize, 2usize);
    let positions: Vec<f32> = (0..3 * t * n).map(|v| (v as f32 * 0.3).sin()).collect();
    let mut left = vec![true; t * n];
    (left[3 * n], left[4 * n], left[5 * n]) = (false, false, false);
    let field = FieldPrediction::new(n, &positions, &positions[..3 * n], &left);
    let sources = Sources::new(Marked::new(t, n, &positions, &left), &field);
    let got = residuals(
        &sources,
        &[(0, 1), (3, 0), (4, 0)],
        super::super::EVERY_FILLER,
    );
    assert_eq!(got.len(), 3);
    assert!(got[0].is_none());
    assert!(
        got[1..]
            .iter()
            .all(|r| r.as_ref().is_some_and(|r| r.len == 3))
    );
    // Frame 3 is beside frame 2, frame 4 two frames from either side.
    let depths: Vec<usize> = got[1..].iter().flatten().map(|r| r.depth).collect();
    assert_eq!(depths, [1, 2]);
}

#[test]
fn a_distance_is_the_norm_of_the_blended_errors() {
    let r = Residual {
        errors: std::array::from_fn(|m| match m {
            0 => [3.0, 0.0, 4.0],
            1 => [-3.0, 8.0, 0.0],
            _ => [0.0; 3],
        }),
        len: 2,
        track: 0,
        depth: 1,
    };
    let mut w = [0.0; M];
    (w[0], w[1]) = (0.5, 0.5);
    // (0, 4, 2): √20, weighed by one half.
    assert!((r.distance(&w) - 20f64.sqrt()).abs() < 1e-12);
    assert!((cost([&r].into_iter(), &w) - 0.5 * 20f64.sqrt()).abs() < 1e-12);
}
