//! The fit loop: it learns, it is deterministic, it stops on a non-finite loss, and
//! every backend runs the same function to the same result.

use crate::common;

use burn::tensor::Device;
use common::{backward_lock, rel_err, to_vec};
use doma::DomaError;
use doma::backend::BackendKind;
use doma::data::Trajectories;
use doma::data::synthetic::{Motion, benchmark_sequence};
use doma::field::{DomaFieldConfig, MotionField, Variant};
use doma::prelude::*;
use doma::train::{FitConfig, SmoothnessSampling, fit};

/// A small piece of the synthetic protocol: 64 training points, 5 frames.
fn small_data() -> (Trajectories, Trajectories) {
    let seq = benchmark_sequence(Motion::Shearing, 0).unwrap();
    let frames: Vec<usize> = (0..seq.train.frames()).step_by(4).collect();
    let cut = |t: &Trajectories, n: usize| {
        let pos: Vec<f32> = frames
            .iter()
            .flat_map(|&k| t.frame(k)[..3 * n].to_vec())
            .collect();
        Trajectories::new(frames.len(), n, pos).unwrap()
    };
    (cut(&seq.train, 64), cut(&seq.test, 64))
}

fn config(variant: Variant, iters: usize) -> FitConfig {
    FitConfig::doma(DomaFieldConfig::new(variant).with_hidden(32)).with_iterations(iters)
}

fn predictions(field: &dyn MotionField, data: &Trajectories, device: &Device) -> Vec<f64> {
    to_vec(field.warp(data.frame_tensor(0, device), data.time(3)))
}

#[test]
fn a_fit_reduces_the_loss_and_counts_its_steps() {
    let _g = backward_lock();
    let (train, _) = small_data();
    let device = Device::flex();
    let fitted = fit(
        &config(Variant::Trans, 40).with_learning_rate(1e-3),
        &train,
        &device,
    )
    .unwrap();
    assert_eq!(fitted.history.len(), 40);
    assert_eq!(fitted.steps, 40 * 5);
    let first = fitted.history[0].trajectory_loss;
    let last = fitted.history[39].trajectory_loss;
    assert!(last < 0.5 * first, "L1 went from {first} to {last}");
}

/// A budget of frames per iteration: at least the frame count is the paper's iteration,
/// bit for bit; fewer visits that many frames an iteration (and counts them as steps).
#[test]
fn frames_per_iteration_caps_the_steps_and_keeps_the_paper_s_iteration_above_the_frames() {
    let _g = backward_lock();
    let (train, test) = small_data();
    let device = Device::flex();
    let run = |f: Option<usize>| {
        let mut c = config(Variant::Trans, 6).with_learning_rate(1e-3);
        c.frames_per_iteration = f;
        fit(&c, &train, &device).unwrap()
    };
    let (all, above, two) = (run(None), run(Some(50)), run(Some(2)));
    let warp =
        |f: &doma::train::Fitted<doma::field::model::Model>| predictions(&f.field, &test, &device);
    assert_eq!(warp(&all), warp(&above));
    assert_eq!((all.steps, above.steps, two.steps), (6 * 5, 6 * 5, 6 * 2));
    assert_ne!(warp(&all), warp(&two));
    let mut bad = config(Variant::Trans, 1);
    bad.frames_per_iteration = Some(0);
    assert!(matches!(
        fit(&bad, &train, &device),
        Err(DomaError::InvalidConfig(m)) if m.contains("frames per iteration")
    ));
}

#[test]
fn the_smoothness_term_is_added_to_the_loss() {
    let _g = backward_lock();
    let (train, _) = small_data();
    let device = Device::flex();
    for variant in Variant::ALL {
        let h = fit(
            &config(variant, 1).with_smoothness_weight(0.1),
            &train,
            &device,
        )
        .unwrap();
        let r = &h.history[0];
        assert!(r.total_loss > r.trajectory_loss, "{variant:?}: {r:?}");
        let e = fit(
            &config(variant, 1).with_elasticity_weight(0.1),
            &train,
            &device,
        )
        .unwrap();
        let r = &e.history[0];
        assert!(r.total_loss > r.trajectory_loss, "{variant:?}: {r:?}");
    }
}

#[test]
fn the_temporal_term_is_added_to_the_loss_where_there_are_three_frames() {
    let _g = backward_lock();
    let (train, _) = small_data();
    let device = Device::flex();
    let mut c = config(Variant::Affinity, 2);
    c.loss.temporal_weight = Some(0.01);
    let t = fit(&c, &train, &device).unwrap();
    for r in &t.history {
        assert!(r.total_loss > r.trajectory_loss, "{r:?}");
        assert!(r.total_loss.is_finite());
    }
    // With two frames there is no second difference: the term is left out.
    let two = train.select_frames(0..2, 1).unwrap();
    let r = fit(&c, &two, &device).unwrap();
    assert_eq!(r.history[0].total_loss, r.history[0].trajectory_loss);
    // A weight of 0 is the fit without it, bit for bit.
    c.loss.temporal_weight = Some(0.0);
    let zero = fit(&c, &train, &device).unwrap();
    c.loss.temporal_weight = None;
    let none = fit(&c, &train, &device).unwrap();
    let losses = |h: &[doma::train::IterationRecord]| -> Vec<(f64, f64)> {
        h.iter()
            .map(|r| (r.trajectory_loss, r.total_loss))
            .collect()
    };
    assert_eq!(losses(&zero.history), losses(&none.history));
}

#[test]
fn the_same_seed_gives_the_same_fit() {
    let _g = backward_lock();
    let (train, test) = small_data();
    let device = Device::flex();
    let c = config(Variant::Affinity, 3).with_smoothness_weight(0.1);
    let a = fit(&c, &train, &device).unwrap();
    let b = fit(&c, &train, &device).unwrap();
    assert_eq!(
        predictions(&a.field, &test, &device),
        predictions(&b.field, &test, &device)
    );
    let other = fit(&c.clone().with_seed(1), &train, &device).unwrap();
    assert_ne!(
        predictions(&a.field, &test, &device),
        predictions(&other.field, &test, &device)
    );
}

#[test]
fn the_learning_rate_schedule_is_the_authors_lambda_lr() {
    let c = config(Variant::Trans, 1000).schedule;
    assert_eq!(c.lr_factor(0), 1.0);
    assert_eq!(c.lr_factor(10), 1.0);
    assert!((c.lr_factor(11) - (1.0 - 1.0 / 991.0)).abs() < 1e-15);
    assert!((c.lr_factor(999) - 2.0 / 991.0).abs() < 1e-15);
    // Short runs never decay, and never divide by zero.
    let short = config(Variant::Trans, 9).schedule;
    assert!((0..9).all(|e| short.lr_factor(e) == 1.0));
}

#[test]
fn bad_configs_are_refused() {
    let (train, _) = small_data();
    let device = Device::flex();
    for c in [
        config(Variant::Trans, 0),
        config(Variant::Trans, 1).with_learning_rate(-1.0),
        config(Variant::Trans, 1).with_smoothness_weight(f64::NAN),
        config(Variant::Trans, 1)
            .with_smoothness_sampling(SmoothnessSampling::new().with_max_points(Some(0))),
        // A model far over the size limit is refused, not allocated.
        FitConfig::doma(DomaFieldConfig::new(Variant::Trans).with_hidden(200_000)),
    ] {
        assert!(matches!(
            fit(&c, &train, &device),
            Err(DomaError::InvalidConfig(_))
        ));
    }
}

#[test]
fn a_non_finite_loss_stops_the_fit_and_names_the_iteration() {
    let _g = backward_lock();
    // Finite f32 coordinates whose L1 sum overflows to +inf.
    let huge = Trajectories::new(2, 16, vec![3.0e38; 96]).unwrap();
    let err = fit(&config(Variant::Trans, 5), &huge, &Device::flex()).unwrap_err();
    match err {
        DomaError::NonFiniteLoss { iteration, .. } => assert_eq!(iteration, 0),
        other => panic!("expected NonFiniteLoss, got {other}"),
    }
    assert!(err_message_names_iteration());
}

fn err_message_names_iteration() -> bool {
    let msg = DomaError::NonFiniteLoss {
        iteration: 7,
        frame: 3,
        value: f64::NAN,
    }
    .to_string();
    msg.contains("iteration 7") && msg.contains("NaN")
}

/// Fits Affinity-H for 3 iterations on `backend` and returns the test predictions.
fn short_fit_on(backend: BackendKind) -> Vec<f64> {
    let (train, test) = small_data();
    let device = backend.device().unwrap();
    let c = config(Variant::Affinity, 3).with_smoothness_weight(0.1);
    let fitted = fit(&c, &train, &device).unwrap();
    predictions(&fitted.field, &test, &device)
}

#[test]
fn ndarray_agrees_with_flex() {
    let _g = backward_lock();
    let e = rel_err(
        &short_fit_on(BackendKind::Ndarray),
        &short_fit_on(BackendKind::Flex),
    );
    assert!(e < 1e-4, "ndarray vs flex: relative difference {e:e}");
}

#[test]
fn wgpu_agrees_with_flex() {
    let _g = backward_lock();
    if common::wgpu_device_or_skip("wgpu_agrees_with_flex").is_none() {
        return;
    }
    let e = rel_err(
        &short_fit_on(BackendKind::Wgpu),
        &short_fit_on(BackendKind::Flex),
    );
    eprintln!("wgpu vs flex after 3 Affinity-H iterations: relative difference {e:e}");
    assert!(e < 1e-4, "wgpu vs flex: relative difference {e:e}");
}

#[test]
fn an_observed_fit_sees_every_kth_iteration_and_the_last_and_ends_where_a_plain_fit_ends() {
    let _g = backward_lock();
    let (train, test) = small_data();
    let device = Device::flex();
    let config = config(Variant::Affinity, 5).with_learning_rate(1e-3);
    let mut seen = Vec::new();
    let mut last_prediction = Vec::new();
    let observed = doma::train::Trainer::from_config(&config, &train, &device)
        .unwrap()
        .run_observed(2, |r, f| {
            seen.push(r.iteration + 1);
            last_prediction = predictions(&f, &test, &device);
            Ok(())
        })
        .unwrap();
    assert_eq!(seen, vec![2, 4, 5]);
    let plain = fit(&config, &train, &device).unwrap();
    let (a, b) = (
        predictions(&observed.field, &test, &device),
        predictions(&plain.field, &test, &device),
    );
    // Observing must not change the fit, and the last observation is the result.
    assert_eq!(a, b);
    assert_eq!(last_prediction, a);
    // An error from the observer stops the fit.
    let err = doma::train::Trainer::from_config(&config, &train, &device)
        .unwrap()
        .run_observed(1, |_, _| Err(DomaError::InvalidConfig("stop".into())));
    assert!(matches!(err, Err(DomaError::InvalidConfig(_))));
}

#[test]
fn a_config_file_with_a_field_no_fit_config_has_is_refused_naming_it() {
    let dir = common::scratch("doma-fit-config");
    let write = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    // An earlier flat layout (every field of it unknown: the first in key order is
    // named), a typo, and a misplaced model field.
    for (name, text, field) in [
        (
            "flat.json",
            r#"{"iterations": 0, "learning_rate": -1, "field": {"hidden": 100000}}"#,
            "`field`",
        ),
        (
            "typo.json",
            r#"{"schedule": {"iterations": 5, "learnig_rate": 0.1}}"#,
            "`schedule.learnig_rate`",
        ),
        (
            "model.json",
            r#"{"model": {"doma": {"variant": "trans", "hiden": 16}}}"#,
            "`model.doma.hiden`",
        ),
    ] {
        let path = write(name, text);
        let err = FitConfig::load_partial(&path).unwrap_err().to_string();
        assert!(err.contains(name) && err.contains(field), "{name}: {err}");
    }
    // A partial file of known fields still takes the defaults for the rest.
    let path = write(
        "partial.json",
        r#"{"model": {"doma": {"variant": "trans"}}, "schedule": {"iterations": 200}}"#,
    );
    let config = FitConfig::load_partial(&path).unwrap();
    assert_eq!(config.schedule.iterations, 200);
    // The fill's validation is a part of the config like the schedule: one field set, the
    // others today's defaults; an unknown one or one that cannot run refused by name.
    let path = write("validation.json", r#"{"validation": {"max_draws": 12}}"#);
    let config = FitConfig::load_partial(&path).unwrap();
    let defaults = doma::gaps::blend::Validation::default();
    assert_eq!(config.validation().max_draws, 12);
    assert_eq!(config.validation().min_draws, defaults.min_draws);
    assert_eq!(config.validation().lean_shares, defaults.lean_shares);
    // A config saved before the field existed reads as today's defaults.
    let none = FitConfig::load_partial(&write("none.json", "{}")).unwrap();
    assert_eq!(none.validation(), defaults);
    for (name, text, needle) in [
        ("folds.json", r#"{"validation": {"folds": 3}}"#, "`folds`"),
        (
            "fraction.json",
            r#"{"validation": {"fraction": 1.5}}"#,
            "validation.fraction",
        ),
    ] {
        let path = write(name, text);
        let err = FitConfig::load_partial(&path).unwrap_err().to_string();
        assert!(err.contains(name) && err.contains(needle), "{name}: {err}");
    }
}
