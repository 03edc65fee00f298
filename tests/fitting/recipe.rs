//! Recipes: the cosine schedule's values, the convergence rule, a fit that stops on
//! convergence, and the fast recipe's settings wherever a fit is started.

use crate::common;

use burn::tensor::Device;
use common::backward_lock;
use doma::data::Trajectories;
use doma::data::synthetic::{Motion, benchmark_sequence};
use doma::field::{DomaFieldConfig, Variant};
use doma::run::RunSpec;
use doma::siren::WithSirenShape;
use doma::train::{
    Convergence, Decay, FAST_LR_FACTOR, FAST_POINTS_PER_STEP, FAST_SMOOTHNESS_POINTS, FitConfig,
    Recipe, RecipeChoice, SOAP_ITERATIONS, SOAP_LR_FACTOR, ScheduleConfig, SoapConfig, Trainer,
    WithSchedule,
};

#[test]
fn the_cosine_schedule_warms_up_linearly_then_follows_half_a_cosine() {
    let s = ScheduleConfig::new()
        .with_iterations(105)
        .with_decay(Some(Decay::Cosine))
        .with_warmup_iterations(Some(5));
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
    // Warm-up: 1/5, 2/5, …, 5/5.
    for e in 0..5 {
        assert!(close(s.lr_factor(e), (e + 1) as f64 / 5.0), "{e}");
    }
    // Then ½(1 + cos(π (e − 5) / 100)): 1 at 5, ½ at 55, ½(1 + cos(0.99π)) at 104.
    assert!(close(s.lr_factor(5), 1.0));
    assert!(close(s.lr_factor(55), 0.5));
    assert!(close(
        s.lr_factor(104),
        0.5 * (1.0 + (0.99 * std::f64::consts::PI).cos())
    ));
    // No warm-up starts at the full rate; a warm-up as long as the budget is refused.
    let plain = ScheduleConfig::new()
        .with_iterations(10)
        .with_decay(Some(Decay::Cosine));
    assert!(close(plain.lr_factor(0), 1.0));
    assert!(plain.validate().is_ok());
    assert!(plain.with_warmup_iterations(Some(10)).validate().is_err());
    // Without a decay, the authors' LambdaLR is untouched.
    assert_eq!(ScheduleConfig::new().lr_factor(500), 1.0 - 490.0 / 991.0);
}

#[test]
fn convergence_is_patience_iterations_without_a_one_percent_improvement() {
    let c = Convergence::new(30);
    // Improving by more than 1 % every 10 iterations: never converged.
    assert!(!c.converged([(10, 1.0), (20, 0.9), (30, 0.8), (40, 0.7)]));
    // Best at 20; 30 iterations later with no 1 % gain: converged.
    assert!(c.converged([(10, 1.0), (20, 0.5), (30, 0.499), (40, 0.6), (50, 0.5)]));
    // 29 iterations are not enough.
    assert!(!c.converged([(20, 0.5), (49, 0.5)]));
    // A gain of 2 % resets the count.
    assert!(!c.converged([(20, 0.5), (40, 0.49), (60, 0.49)]));
    // NaN never counts as the best; no measurement never converges.
    assert!(!c.converged([(10, f64::NAN), (50, 1.0)]));
    assert!(!c.converged([]));
    assert!(Convergence::new(0).validate().is_err());
    assert!(
        Convergence::new(5)
            .with_validation_fraction(1.0)
            .validate()
            .is_err()
    );
    assert!(Convergence::new(5).with_every(0).validate().is_err());
    // The plateau is where the rule first held.
    let curve = [
        (10, 1.0),
        (20, 0.5),
        (30, 0.5),
        (40, 0.5),
        (50, 0.5),
        (60, 0.2),
    ];
    assert_eq!(c.plateau(curve), Some(50));
    assert_eq!(c.plateau(curve[..4].iter().copied()), None);
    assert_eq!(c.cooldown_iterations(), 30);
    assert_eq!(c.clone().with_cooldown(Some(0)).cooldown_iterations(), 0);
}

/// A small piece of the synthetic protocol: 96 training points, 5 frames.
fn small_train() -> Trajectories {
    let seq = benchmark_sequence(Motion::Shearing, 0).unwrap();
    let frames: Vec<usize> = (0..seq.train.frames()).step_by(4).collect();
    let pos: Vec<f32> = frames
        .iter()
        .flat_map(|&k| seq.train.frame(k)[..3 * 96].to_vec())
        .collect();
    Trajectories::new(frames.len(), 96, pos).unwrap()
}

#[test]
fn a_fit_until_converged_stops_before_its_budget_with_the_validation_curve_flat() {
    let _g = backward_lock();
    let train = small_train();
    let device = Device::flex();
    let budget = 3000;
    let patience = 40;
    let config = |c: Convergence| {
        FitConfig::doma(DomaFieldConfig::new(Variant::Trans).with_hidden(32))
            .with_iterations(budget)
            .with_learning_rate(1e-3)
            .with_until_converged(Some(c))
    };
    let run = |c: &FitConfig| {
        Trainer::from_config(c, &train, &device)
            .unwrap()
            .run()
            .unwrap()
    };
    // No cool-down: the fit stops at the plateau.
    let fitted = run(&config(Convergence::new(patience).with_cooldown(Some(0))));
    let done = fitted.history.len();
    assert!(done < budget, "ran the whole budget of {budget}");
    assert_eq!(fitted.steps, done * train.frames());
    // Measured every 10 iterations, and nowhere else.
    let curve: Vec<(usize, f64)> = fitted
        .history
        .iter()
        .filter_map(|r| Some((r.iteration + 1, r.validation_epe?)))
        .collect();
    assert!(curve.iter().all(|(i, _)| i % 10 == 0));
    assert_eq!(curve.len(), done / 10);
    // Flat: nothing in the last `patience` iterations beat the best before them by 1 %.
    let best_before = curve
        .iter()
        .filter(|(i, _)| *i <= done - patience)
        .map(|(_, e)| *e)
        .fold(f64::INFINITY, f64::min);
    let tail = curve.iter().filter(|(i, _)| *i > done - patience);
    assert!(tail.clone().count() > 0);
    for (i, e) in tail {
        assert!(*e >= 0.99 * best_before, "{e} at {i} beat {best_before}");
    }
    // With a cool-down of `patience` iterations (the default), the same fit goes on from
    // the plateau with a learning rate falling linearly from the rate there, then stops.
    let with_cooldown = config(Convergence::new(patience));
    let cooled = run(&with_cooldown);
    assert_eq!(cooled.history.len(), done + patience);
    let at_plateau = with_cooldown.schedule.learning_rate_at(done);
    for j in 0..patience {
        let lr = cooled.history[done + j].learning_rate;
        let want = at_plateau * (1.0 - (j + 1) as f64 / (patience + 1) as f64);
        assert!(
            (lr - want).abs() <= 1e-12 * at_plateau,
            "{j}: {lr} against {want}"
        );
    }
    assert_eq!(
        fitted.history[done - 1].trajectory_loss.to_bits(),
        cooled.history[done - 1].trajectory_loss.to_bits()
    );
    // The same fit without the rule runs the whole budget of a short run.
    let plain = run(&config(Convergence::new(patience))
        .with_until_converged(None)
        .with_iterations(20));
    assert_eq!(plain.history.len(), 20);
    assert!(plain.history.iter().all(|r| r.validation_epe.is_none()));
}

#[test]
fn the_fast_recipe_sets_its_schedule_and_caps_the_capped_smoothness_sampling() {
    let paper =
        FitConfig::doma(DomaFieldConfig::new(Variant::Affinity)).with_smoothness_weight(0.1);
    let fast = Recipe::Fast.apply(paper.clone());
    // The budget is kept; the rate is scaled and decays on a cosine.
    assert_eq!(fast.schedule.iterations, paper.schedule.iterations);
    assert_eq!(fast.schedule.decay, Some(Decay::Cosine));
    let scaled = FAST_LR_FACTOR * paper.schedule.learning_rate;
    assert!((fast.schedule.learning_rate - scaled).abs() <= 1e-12 * scaled);
    assert_eq!(
        fast.smoothness_sampling.max_points,
        Some(FAST_SMOOTHNESS_POINTS)
    );
    assert_eq!(fast.points_per_step, Some(FAST_POINTS_PER_STEP));
    assert_eq!(fast.recipe, Some(Recipe::Fast));
    // The model, the weights and the seed are kept.
    assert_eq!(fast.loss, paper.loss);
    assert_eq!(fast.seed, paper.seed);
    // An uncapped sampling (every training point: the non-Affinity variants) stays so.
    let trans = Recipe::Fast.apply(FitConfig::doma(DomaFieldConfig::new(Variant::Trans)));
    assert_eq!(trans.smoothness_sampling.max_points, None);
    // The paper's recipe changes nothing but the label.
    let same = Recipe::Paper.apply(paper.clone());
    assert_eq!(
        serde_json::to_value(same.clone().with_recipe(None)).unwrap(),
        serde_json::to_value(&paper).unwrap()
    );
    // The recipe's settings are in the config, and read back.
    let text = serde_json::to_string(&fast).unwrap();
    let back: FitConfig = serde_json::from_str(&text).unwrap();
    assert_eq!(serde_json::to_string(&back).unwrap(), text);
    let choice = RecipeChoice {
        recipe: None,
        until_converged: Some(25),
    };
    assert_eq!(
        choice.apply(paper).until_converged,
        Some(Convergence::new(25))
    );
}

#[test]
fn the_soap_recipe_is_the_fast_one_over_400_iterations_at_3_times_the_rate_with_soap() {
    let paper =
        FitConfig::doma(DomaFieldConfig::new(Variant::Affinity)).with_smoothness_weight(0.1);
    let fast = Recipe::Fast.apply(paper.clone());
    let soap = Recipe::Soap.apply(paper.clone());
    assert_eq!(soap.schedule.iterations, SOAP_ITERATIONS);
    // Written as a short decimal: 3e-4 from the paper's 1e-4, as config.json reads it back.
    assert_eq!(SOAP_LR_FACTOR, 3.0);
    assert_eq!(soap.schedule.learning_rate, 3e-4);
    assert_eq!(soap.soap, Some(SoapConfig::default()));
    assert_eq!(soap.recipe, Some(Recipe::Soap));
    // Everything else is fast's.
    let strip = |c: &FitConfig| {
        let mut c = c.clone();
        c.schedule.iterations = 0;
        c.schedule.learning_rate = 0.0;
        c.soap = None;
        c.recipe = None;
        serde_json::to_value(c).unwrap()
    };
    assert_eq!(strip(&soap), strip(&fast));
    // A flag wins over the recipe: --optimizer adam takes SOAP out, --step composed is
    // then allowed; with SOAP kept it is refused.
    let spec: RunSpec =
        serde_json::from_str(r#"{"recipe": "soap", "optimizer": "adam", "step": "composed"}"#)
            .unwrap();
    let fit = spec.fit_config(|| Ok(10)).unwrap();
    assert_eq!((fit.soap, fit.schedule.iterations), (None, SOAP_ITERATIONS));
    let spec: RunSpec = serde_json::from_str(r#"{"recipe": "soap", "step": "composed"}"#).unwrap();
    let fit = spec.fit_config(|| Ok(10)).unwrap();
    let err = fit.validate().unwrap_err().to_string();
    assert!(err.contains("SOAP"), "{err}");
}

#[test]
fn a_run_spec_applies_the_recipe_after_the_variant_and_before_the_flags() {
    let spec: RunSpec = serde_json::from_str(
        r#"{"model": "affinity", "recipe": "fast", "iterations": 37, "until_converged": 50}"#,
    )
    .unwrap();
    let fit = spec.fit_config(|| Ok(10)).unwrap();
    // The variant's sampling is the authors' 1024, which the recipe caps; --points-per-step
    // and --iters win over the recipe.
    assert_eq!(
        fit.smoothness_sampling.max_points,
        Some(FAST_SMOOTHNESS_POINTS)
    );
    assert_eq!(fit.schedule.decay, Some(Decay::Cosine));
    // --iters wins over the recipe's budget.
    assert_eq!(fit.schedule.iterations, 37);
    assert_eq!(fit.until_converged, Some(Convergence::new(50)));
    // An unknown recipe is refused by name.
    let bad = serde_json::from_str::<RunSpec>(r#"{"recipe": "fastest"}"#).unwrap_err();
    assert!(bad.to_string().contains("fastest"), "{bad}");
}

#[test]
fn init_scale_reaches_the_siren_of_a_doma_or_dpf_fit_and_defaults_to_the_authors() {
    let fit = |json: &str| {
        serde_json::from_str::<RunSpec>(json)
            .unwrap()
            .fit_config(|| Ok(10))
    };
    let shape = |c: &FitConfig| match &c.model {
        doma::field::model::ModelConfig::Doma(d) => d.shape.clone(),
        doma::field::model::ModelConfig::Dpf(d) => d.shape.clone(),
        other => panic!("{other:?}"),
    };
    assert_eq!(shape(&fit(r#"{}"#).unwrap()).init_scale, None);
    for json in [
        r#"{"model": "se3", "init_scale": 1.5}"#,
        r#"{"model": "dpf", "init_scale": 1.5}"#,
    ] {
        assert_eq!(shape(&fit(json).unwrap()).init_scale, Some(1.5), "{json}");
    }
    // Refused where the value cannot be a scale (JSON and Python reach here unparsed).
    let e = fit(r#"{"init_scale": -2}"#).and_then(|c| c.validate());
    assert!(e.unwrap_err().to_string().contains("initialisation scale"));
}

#[test]
fn a_recipe_file_overlays_the_config_and_refuses_a_field_no_config_has() {
    let dir = common::scratch("doma-recipe-file");
    let base = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity));
    let good = dir.join("short.json");
    std::fs::write(
        &good,
        r#"{"schedule": {"iterations": 50, "decay": "cosine"}, "until_converged": {"patience": 20}}"#,
    )
    .unwrap();
    let c = base.overlaid(&good).unwrap();
    assert_eq!(c.schedule.iterations, 50);
    assert_eq!(c.schedule.learning_rate, base.schedule.learning_rate);
    assert_eq!(c.until_converged, Some(Convergence::new(20)));
    let bad = dir.join("typo.json");
    std::fs::write(&bad, r#"{"schedule": {"iteratoins": 50}}"#).unwrap();
    let e = base.overlaid(&bad).unwrap_err().to_string();
    assert!(
        e.contains("typo.json") && e.contains("schedule.iteratoins"),
        "{e}"
    );
}
