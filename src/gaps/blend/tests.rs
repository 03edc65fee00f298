//! The blend's tests: where it keeps the field's fill, where it moves to other fillers,
//! its length classes and its blind spans.

use super::*;

/// Today's validation, as every fit has it by default.
static V: std::sync::LazyLock<Validation> = std::sync::LazyLock::new(Validation::default);
use crate::gaps::field_fill::{Lending, field_fill};

/// `[T, N, 3]`: a grid of `n` tracks, five to a row, translated by an irregular jump
/// every frame (a camera shake: no spline follows it).
fn camera_shake(t: usize, n: usize) -> Vec<f32> {
    let jump = |k: usize| {
        let k = k as f32;
        [
            (1.7 * k * k).sin(),
            (2.3 * k * k + 1.0).cos(),
            0.5 * (0.9 * k * k).sin(),
        ]
    };
    (0..t)
        .flat_map(|k| {
            let d = jump(k);
            (0..n).flat_map(move |i| {
                let (x, y) = ((i % 5) as f32, (i / 5) as f32);
                [x + d[0], y + d[1], d[2]]
            })
        })
        .collect()
}

#[test]
fn where_nothing_can_be_validated_the_fill_is_the_carried_one() {
    // Every track seen at its first and last frame only: no span can be hidden with an
    // observation on both sides.
    let (t, n) = (12usize, 3usize);
    let truth: Vec<f32> = (0..3 * t * n).map(|v| (v as f32 * 0.37).sin()).collect();
    let predicted: Vec<f32> = truth.iter().map(|v| 0.9 * v + 0.05).collect();
    let mut observed = vec![false; t * n];
    for i in 0..n {
        observed[i] = true;
        observed[(t - 1) * n + i] = true;
    }
    let canonical: Vec<f32> = (0..3 * n).map(|v| v as f32).collect();
    let field = FieldPrediction::new(n, &predicted, &canonical, &observed);
    let (filled, blend) = doma_fill(&Marked::new(t, n, &truth, &observed), &field, 3, &[], &V);
    assert_eq!(blend.short, Weights::only(Filler::FieldFill));
    assert_eq!(blend.validated, [0, 0]);
    assert_eq!(
        filled,
        field_fill(
            &Marked::new(t, n, &truth, &observed),
            &field,
            Lending::Fixed
        )
    );
}

#[test]
fn a_jittering_translation_with_a_wrong_field_is_filled_by_the_neighbours() {
    // 20 tracks of a grid that translates by an irregular jump every frame (a camera
    // shake: no spline follows it), over 30 frames; each track has a gap of 4 frames.
    // The "field" is garbage (zeros) and lends no track a neighbour's residual, so its
    // fill is the spline's: the blend must move its weight to the fillers that follow
    // the other tracks' motion, which are exact here.
    let (t, n) = (30usize, 20usize);
    let truth = camera_shake(t, n);
    let mut observed = vec![true; t * n];
    for i in 0..n {
        for k in 0..4 {
            observed[(3 + i + k) * n + i] = false;
        }
    }
    let predicted = vec![0f32; 3 * t * n];
    let field = FieldPrediction::new(n, &predicted, &[f32::NAN; 3].repeat(n), &observed);
    let (filled, blend) = doma_fill(&Marked::new(t, n, &truth, &observed), &field, 7, &[], &V);
    assert!(blend.validated[0] > 0, "{blend:?}");
    // The neighbours' motion, pattern, rigid-body, segment and chain fill are all exact for a
    // translation: the weight goes to them, to one alone where no blend of them beats it.
    let exact = [
        Filler::Neighbours,
        Filler::Pattern,
        Filler::RigidBody,
        Filler::Segment,
        Filler::Chain,
    ];
    let on_exact: f64 = exact.iter().map(|&f| blend.short[f]).sum();
    assert!(on_exact > 0.95, "{blend:?}");
    let total: f64 = blend.short.0.iter().sum();
    assert!((total - 1.0).abs() < 1e-9);
    let mut worst = 0f32;
    let mut spline_worst = 0f32;
    let spline = Marked::new(t, n, &truth, &observed).spline();
    for (e, (&f, &y)) in filled.iter().zip(&truth).enumerate() {
        if observed[e / 3] {
            assert_eq!(f, y);
        } else {
            worst = worst.max((f - y).abs());
            spline_worst = spline_worst.max((spline[e] - y).abs());
        }
    }
    assert!(worst < 0.1, "{worst} {blend:?}");
    assert!(
        worst <= spline_worst,
        "{worst} against the spline's {spline_worst}"
    );
}

#[test]
fn blind_spans_judge_a_field_that_only_memorised_what_it_saw() {
    // A camera-shake translation of 20 tracks, each with a real gap of 4 frames and a
    // blind span of 3 frames elsewhere. The "field" is exact where it was fitted and
    // 3 units off everywhere else, as an overfitted field is.
    // Validated on spans it was fitted to, it would look exact; without blind spans it
    // is not judged and takes no weight, and on the blind spans it is seen as it is
    // inside a gap, and the weight goes to the fillers that follow the other tracks.
    let (t, n) = (30usize, 20usize);
    let truth = camera_shake(t, n);
    let mut observed = vec![true; t * n];
    let mut blind = Vec::new();
    for i in 0..n {
        for k in 3 + i..7 + i {
            observed[k * n + i] = false;
        }
        let start = if i < 10 { 18 + i % 5 } else { 4 };
        blind.extend((start..start + 3).map(|k| (k, i)));
    }
    blind.sort_unstable();
    let mut fitted = observed.clone();
    for &(k, i) in &blind {
        fitted[k * n + i] = false;
    }
    let predicted: Vec<f32> = truth
        .iter()
        .enumerate()
        .map(|(e, &y)| if fitted[e / 3] { y } else { y + 3.0 })
        .collect();
    let field = FieldPrediction::new(n, &predicted, &[f32::NAN; 3].repeat(n), &observed);
    let tracks = Marked::new(t, n, &truth, &observed);
    let worst = |filled: &[f32]| {
        (0..3 * t * n)
            .filter(|&e| !observed[e / 3])
            .map(|e| (filled[e] - truth[e]).abs())
            .fold(0f32, f32::max)
    };

    // Fitted to every observation, the same field is exact on all of them.
    let memorised: Vec<f32> = truth
        .iter()
        .enumerate()
        .map(|(e, &y)| if observed[e / 3] { y } else { y + 3.0 })
        .collect();
    let memorised = FieldPrediction::new(n, &memorised, &[f32::NAN; 3].repeat(n), &observed);
    // Judged on the validation spans it was fitted to, it would look exact and take the
    // weight: without blind spans its fills take none.
    let (seen, unjudged) = doma_fill(&tracks, &memorised, 7, &[], &V);
    assert_eq!(unjudged.field_validated, 0);
    for weights in [unjudged.short, unjudged.long] {
        assert_eq!(
            weights[Filler::FieldFill] + weights[Filler::FieldFillFramewise],
            0.0
        );
    }
    assert!(worst(&seen) < 0.1, "{}", worst(&seen));

    // Each blind span lands whole in one fold.
    let folds = stage_two::blind_draws(&tracks, &blind, V.blind_folds);
    assert_eq!(folds.len(), V.blind_folds);
    let mut all: Vec<(usize, usize)> = folds.concat();
    all.sort_unstable();
    assert_eq!(all, blind);
    for hidden in &folds {
        for &(k, i) in hidden {
            let whole = (k.saturating_sub(2)..k + 3)
                .filter(|&j| blind.binary_search(&(j, i)).is_ok())
                .all(|j| hidden.contains(&(j, i)));
            assert!(whole, "the span of ({k}, {i}) is split across folds");
        }
    }

    let (filled, blend) = doma_fill(&tracks, &field, 7, &blind, &V);
    assert_eq!(blend.field_validated, blind.len(), "{blend:?}");
    let exact = [
        Filler::Neighbours,
        Filler::Pattern,
        Filler::RigidBody,
        Filler::Segment,
        Filler::Chain,
    ];
    for weights in [blend.short, blend.long] {
        let on_exact: f64 = exact.iter().map(|&f| weights[f]).sum();
        assert!(on_exact > 0.95, "{blend:?}");
    }
    assert!(worst(&filled) < 0.1, "{}", worst(&filled));
    for (e, (&f, &y)) in filled.iter().zip(&truth).enumerate() {
        if observed[e / 3] {
            assert_eq!(
                f, y,
                "an observed entry, blind or not, is returned as given"
            );
        }
    }
}

#[test]
fn each_length_class_learns_its_own_weights() {
    // Twelve tracks on slow sines of their own (no donor follows another), each with a
    // gap of 24 frames and one of 100. A spline is near exact across 24 frames and far
    // off across 100; the "field" is off by the same noise everywhere. Pooled, the long
    // gaps' squared errors would choose for both; by length, the 24-frame gaps go to
    // the spline and the 100-frame ones away from it.
    let (t, n) = (400usize, 12usize);
    let truth: Vec<f32> = (0..t)
        .flat_map(|k| {
            (0..n).flat_map(move |i| {
                let (k, i) = (k as f32, i as f32);
                let tau = std::f32::consts::TAU;
                [
                    (tau * k / 160.0 + i).sin(),
                    (tau * k / (130.0 + 7.0 * i)).cos(),
                    0.1 * i + 0.3 * (tau * k / (190.0 + 5.0 * i)).sin(),
                ]
            })
        })
        .collect();
    let mut observed = vec![true; t * n];
    for i in 0..n {
        let (a, b) = (10 + 7 * i, 200 + 9 * i);
        for k in (a..a + 24).chain(b..b + 100) {
            observed[k * n + i] = false;
        }
    }
    let predicted: Vec<f32> = truth
        .iter()
        .enumerate()
        .map(|(e, &y)| y + 0.05 * ((e as f32 * 12.9898).sin() * 43_758.547).fract())
        .collect();
    let field = FieldPrediction::new(n, &predicted, &[f32::NAN; 3].repeat(n), &observed);
    let tracks = Marked::new(t, n, &truth, &observed);
    // The field judged where it was not fitted, as it is inside a gap.
    let (filled, blend) = doma_fill(&tracks, &field, 5, &blind_spans(&tracks, 5, &V), &V);
    let of = |len: usize| {
        blend.by_length[match GapClass::of(len) {
            GapClass::Long(c) => c,
            GapClass::Short => unreachable!("a long gap"),
        }]
    };
    let (medium, long) = (of(24), of(100));
    assert!(medium.own && long.own, "{blend:?}");
    assert!(medium.weights[Filler::Spline] > 0.5, "{blend:?}");
    assert!(long.weights[Filler::Spline] < 0.1, "{blend:?}");
    // The 24-frame gaps filled by their class's weights beat the pooled ones there.
    let pooled = Blend {
        by_length: Vec::new(),
        ..blend.clone()
    };
    let entries: Vec<(usize, usize, usize)> = (0..n)
        .flat_map(|i| (10 + 7 * i..34 + 7 * i).map(move |k| (k, i, 24)))
        .collect();
    let (by_pool, _) = blend_at(&Sources::new(tracks, &field), &pooled, &entries);
    let error = |fill: &dyn Fn(usize) -> [f32; 3]| {
        entries
            .iter()
            .enumerate()
            .map(|(r, &(k, i, _))| {
                let e = 3 * (k * n + i);
                let v = fill(r);
                (0..3).map(|c| (v[c] - truth[e + c]).powi(2)).sum::<f32>()
            })
            .sum::<f32>()
    };
    let own = error(&|r| {
        let (k, i, _) = entries[r];
        let e = 3 * (k * n + i);
        [filled[e], filled[e + 1], filled[e + 2]]
    });
    let pooled_error = error(&|r| by_pool[r]);
    assert!(
        own < 0.5 * pooled_error,
        "{own} against {pooled_error}: {blend:?}"
    );
}

#[test]
fn an_exact_field_keeps_the_whole_weight() {
    // The field is the truth: its carried fill is exact, so it wins every blind entry
    // and the real gaps are filled exactly.
    let (t, n) = (60usize, 12usize);
    let truth: Vec<f32> = (0..t)
        .flat_map(|k| {
            (0..n).flat_map(move |i| {
                let s = (0.5 * k as f32 + i as f32).sin();
                [s, s * s, i as f32 + 0.01 * (k * k) as f32]
            })
        })
        .collect();
    let mut observed = vec![true; t * n];
    for i in 0..n {
        for k in 5..9 {
            observed[(k + i) * n + i] = false;
        }
    }
    let field = FieldPrediction::new(n, &truth, &truth[..3 * n], &observed);
    let tracks = Marked::new(t, n, &truth, &observed);
    let blind = blind_spans(&tracks, 1, &V);
    assert!(!blind.is_empty());
    let (filled, blend) = doma_fill(&tracks, &field, 1, &blind, &V);
    assert_eq!(blend.short, Weights::only(Filler::FieldFill), "{blend:?}");
    assert_eq!(blend.field_validated, blind.len());
    for (a, b) in filled.iter().zip(&truth) {
        assert!((a - b).abs() < 1e-5);
    }
}

#[test]
fn nothing_to_fill_is_returned_as_given() {
    let (t, n) = (4usize, 2usize);
    let positions: Vec<f32> = (0..3 * t * n).map(|v| v as f32).collect();
    let observed = vec![true; t * n];
    let field = FieldPrediction::new(n, &positions, &positions[..3 * n], &observed);
    let (filled, blend) = doma_fill(
        &Marked::new(t, n, &positions, &observed),
        &field,
        0,
        &[],
        &V,
    );
    assert_eq!(filled, positions);
    assert_eq!(blend.validated, [0, 0]);
}

#[test]
fn beyond_the_ends_the_fillers_that_carry_the_track_take_the_weight() {
    // The camera-shake grid, 30 frames of 20 tracks: a quarter start late (frame 8) and a
    // quarter are lost early (after frame 21), and each has a short interior gap. No value
    // held at a border follows the shake; the other tracks' motion is exact here.
    let (t, n) = (30usize, 20usize);
    let truth = camera_shake(t, n);
    let mut observed = vec![true; t * n];
    for i in 0..n {
        for k in 0..3 {
            observed[(10 + (i % 7) + k) * n + i] = false;
        }
        let run = match i % 4 {
            0 => 0..8,
            1 => 22..t,
            _ => 0..0,
        };
        for k in run {
            observed[k * n + i] = false;
        }
    }
    let tracks = Marked::new(t, n, &truth, &observed);
    let predicted = vec![0f32; 3 * t * n];
    let field = FieldPrediction::new(n, &predicted, &[f32::NAN; 3].repeat(n), &observed);
    let (filled, blend) = doma_fill(&tracks, &field, 5, &[], &V);
    let ends = blend.ends.expect("runs past the ends to weigh");
    assert!(ends.validated > 0);
    for f in Filler::ALL {
        let carries = predicts_beyond_ends() & f.bit() != 0;
        assert!(carries || ends.weights[f] == 0.0, "{f:?}: {ends:?}");
    }
    let past = ends::past_ends(&tracks);
    let (mut worst, mut held) = (0f32, 0f32);
    for k in 0..t {
        for i in (0..n).filter(|&i| past(k, i)) {
            let e = 3 * (k * n + i);
            let border = if k < 8 { 8 } else { 21 };
            let b = 3 * (border * n + i);
            for c in 0..3 {
                worst = worst.max((filled[e + c] - truth[e + c]).abs());
                held = held.max((truth[b + c] - truth[e + c]).abs());
            }
        }
    }
    assert!(worst < 1e-3, "{worst}");
    assert!(held > 0.5, "{held}");
    // Nothing past the ends to fill: no weights there.
    let inside: Vec<(usize, usize)> = (0..t)
        .flat_map(|k| (0..n).map(move |i| (k, i)))
        .filter(|&(k, i)| !tracks.seen(k, i) && !past(k, i))
        .collect();
    let (_, blend) = doma_fill_at(&tracks, &field, 5, &[], &inside, &V);
    assert_eq!(blend.ends, None);
}
