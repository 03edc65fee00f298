//! Stage 1 on hand-made validation entries: which weights each class takes, and what it
//! reports of them.

use super::*;
use crate::gaps::blend::residual::Residual;

/// A validation entry of track 0 in a gap of `len` frames where each filler of `errors`
/// errs by its value (1-D) and every other filler far off.
fn with(len: usize, errors: &[(Filler, f32)]) -> Arc<Residual<M>> {
    Arc::new(Residual {
        errors: std::array::from_fn(|m| {
            let e = errors.iter().find(|(f, _)| *f == Filler::ALL[m]);
            [e.map_or(1e3, |(_, e)| *e), 0.0, 0.0]
        }),
        len,
        track: 0,
        depth: 1,
    })
}

/// [`with`] the spline and the chain fill erring by these.
fn entry(len: usize, spline: f32, chain: f32) -> Arc<Residual<M>> {
    with(len, &[(Filler::Spline, spline), (Filler::Chain, chain)])
}

/// `count` copies of a long gap's validation entry `r`, in its class and the pooled
/// long gaps.
fn push_long(pools: &mut Pools<M>, r: &Arc<Residual<M>>, count: usize) {
    for _ in 0..count {
        pools[Pool::Class(GapClass::of(r.len)).index()].push(Arc::clone(r));
        pools[Pool::AllLong.index()].push(Arc::clone(r));
    }
}

/// The index in [`Blend::by_length`] of the class of gaps of `len` frames.
fn long_class(len: usize) -> usize {
    match GapClass::of(len) {
        GapClass::Long(c) => c,
        GapClass::Short => unreachable!("a long gap"),
    }
}

/// Six draws of long gaps: 100-frame gaps where the chain fill is far better, and
/// 20-frame gaps where the spline beats it by `spline_20` in each draw. Where that gain
/// is steady the 20-frame class keeps its own choice (the spline); where it swings
/// from draw to draw (the validation cannot tell the two apart) the class takes the
/// pooled long gaps' weights.
#[test]
fn a_length_class_keeps_its_own_weights_only_where_they_clearly_beat_the_pooled_ones() {
    let class_of = |spline_20: [f32; 6]| {
        let draws: Vec<Pools<M>> = spline_20
            .iter()
            .map(|&s| {
                let mut pools = empty_pools();
                for (len, spline, chain) in [(20, s, 1.0), (100, 5.0, 0.1)] {
                    push_long(&mut pools, &entry(len, spline, chain), 4);
                }
                pools
            })
            .collect();
        let blend = classic_blend(&draws, &Validation::default()).unwrap();
        (blend.by_length[long_class(20)], blend.long)
    };
    let (steady, _) = class_of([0.5; 6]);
    assert!(
        steady.own && steady.weights == Weights::only(Filler::Spline),
        "{steady:?}"
    );
    let (swinging, pooled) = class_of([0.2, 1.8, 0.2, 1.8, 0.2, 1.8]);
    assert!(!swinging.own, "{swinging:?}");
    assert_eq!(swinging.weights, pooled);
}

/// The pooled long gaps' weights are judged on a class as the long gaps use them. On
/// clean draws a half-and-half blend of the chain fill (+1) and the Kalman smoother
/// (−1) is exact, but the smoother misses one 20-frame span by 1000: learned on every
/// draw, the long gaps take the chain fill alone. The 20-frame class, whose spline
/// swings around the chain fill's 1.05, takes those weights; on its held-out draws
/// they give the chain fill's 1.05 a span, not what blends learned on the other draws
/// give.
#[test]
fn a_class_is_judged_against_the_pooled_weights_as_the_long_gaps_use_them() {
    let draws: Vec<Pools<M>> = (0..6)
        .map(|d| {
            let mut pools = empty_pools();
            let spline = if d % 2 == 0 { 0.2 } else { 1.8 };
            let kalman = if d == 5 { 1000.0 } else { -1.0 };
            let spans = [
                (100, vec![(Filler::Chain, 1.0), (Filler::Kalman, -1.0)]),
                (
                    20,
                    vec![
                        (Filler::Spline, spline),
                        (Filler::Chain, 1.05),
                        (Filler::Kalman, kalman),
                    ],
                ),
            ];
            for (len, errors) in spans {
                push_long(&mut pools, &with(len, &errors), len);
            }
            pools
        })
        .collect();
    let blend = classic_blend(&draws, &Validation::default()).unwrap();
    assert_eq!(blend.long, Weights::only(Filler::Chain));
    let class = blend.by_length[long_class(20)];
    assert!(!class.own, "{class:?}");
    let held = class.held_out.unwrap();
    assert!((held.chosen - 1.05).abs() < 1e-6, "{held:?}");
    assert_eq!(held.best, Filler::Spline);
    assert!((held.best_alone - 1.0).abs() < 1e-6, "{held:?}");
}

/// The held-out figures by hand: every 20-frame span errs by 0.5 with the spline and
/// 1.0 with the chain fill, each 100-frame span by 5.0 and 0.1. The 20-frame class
/// fills with the spline (0.5 a span, as the spline alone); the pooled long gaps'
/// best filler alone is the chain fill (half the spans at 1.0, half at 0.1: 0.55 a
/// span), and their blend, cross-fitted, does no worse.
#[test]
fn the_held_out_figures_are_the_mean_distance_per_span() {
    let draws: Vec<Pools<M>> = (0..6)
        .map(|_| {
            let mut pools = empty_pools();
            for (len, spline, chain) in [(20, 0.5, 1.0), (100, 5.0, 0.1)] {
                push_long(&mut pools, &entry(len, spline, chain), len);
            }
            pools
        })
        .collect();
    let blend = classic_blend(&draws, &Validation::default()).unwrap();
    let c = long_class(20);
    let held = blend.by_length[c].held_out.unwrap();
    assert_eq!(held.best, Filler::Spline);
    assert!((held.best_alone - 0.5).abs() < 1e-6, "{held:?}");
    assert!((held.chosen - 0.5).abs() < 1e-6, "{held:?}");
    // One span of each length a draw, every draw held out once.
    assert!((held.spans - 6.0).abs() < 1e-9, "{held:?}");
    let long = blend.held_out[1].unwrap();
    assert_eq!(long.best, Filler::Chain);
    assert!((long.best_alone - 0.55).abs() < 1e-6, "{long:?}");
    assert!(long.chosen <= long.best_alone + 1e-9, "{long:?}");
    assert!((long.spans - 12.0).abs() < 1e-9, "{long:?}");
    // No short gap was validated.
    assert_eq!(blend.held_out[0], None);
    // In the data's units: every figure times the scale, the spans as they were.
    let in_mm = blend.clone().in_units(1000.0);
    let (class_mm, long_mm) = (
        in_mm.by_length[c].held_out.unwrap(),
        in_mm.held_out[1].unwrap(),
    );
    assert!((class_mm.chosen - 1000.0 * held.chosen).abs() < 1e-9);
    assert!((long_mm.best_alone - 1000.0 * long.best_alone).abs() < 1e-9);
    assert_eq!(class_mm.spans, held.spans);
    // A report keeps them, the filler by its name; one written before reads without.
    let json = serde_json::to_string(&blend).unwrap();
    assert!(json.contains(r#""best":"chain""#), "{json}");
    // (serde_json reads a float back to within an ulp.)
    let read = serde_json::from_str::<Blend>(&json).unwrap().by_length[c].held_out;
    let read = read.unwrap();
    assert_eq!(read.best, held.best);
    assert!((read.chosen - held.chosen).abs() < 1e-12 && (read.spans - held.spans).abs() < 1e-12);
    let before = serde_json::to_value(Blend {
        held_out: [None, None],
        ..blend.clone()
    })
    .unwrap();
    assert!(before.get("held_out").is_none());
    let read: Blend = serde_json::from_value(before).unwrap();
    assert_eq!(read.held_out, [None, None]);
}

/// Six draws: on the short gaps the spline wins some draws and loses others by as much
/// (no clear gain over the chain fill); on the long gaps, and so across the recording,
/// the chain fill is far better. With `fall_back` the short gaps take the chain fill;
/// without, the short gaps' own choice leans on the spline.
#[test]
fn a_class_that_cannot_tell_the_parts_apart_falls_back_to_the_recording_s_best() {
    let spline_short = [0.5, 1.5, 0.5, 1.5, 0.5, 0.2];
    let draws: Vec<Pools<M>> = spline_short
        .iter()
        .map(|&s| {
            let mut pools = empty_pools();
            for _ in 0..4 {
                pools[Pool::Class(GapClass::Short).index()].push(entry(1, s, 1.0));
            }
            push_long(&mut pools, &entry(20, 5.0, 0.1), 4);
            pools
        })
        .collect();
    assert_eq!(
        recording_best(&draws, classic_fillers()),
        Filler::Chain.index()
    );
    let on = Validation {
        fall_back: true,
        ..Validation::default()
    };
    let with = classic_blend(&draws, &on).unwrap();
    assert_eq!(with.short, Weights::only(Filler::Chain));
    let without = classic_blend(&draws, &Validation::default()).unwrap();
    assert!(without.short[Filler::Spline] > 0.5, "{:?}", without.short);
    // The long gaps choose the chain fill either way.
    assert_eq!(with.long, Weights::only(Filler::Chain));
    assert_eq!(without.long, Weights::only(Filler::Chain));
}
