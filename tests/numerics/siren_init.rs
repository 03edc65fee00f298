//! The SIREN initialiser against docs/reference.md §1, and the parameter counts.

use doma::field::{DomaFieldConfig, MotionField, Variant};
use doma::prelude::*;
use doma::siren::{LayerRole, SirenConfig, SirenInitializer};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn check_uniform(values: &[f64], bound: f64, what: &str) {
    let n = values.len() as f64;
    let max = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        max <= bound,
        "{what}: |value| {max} exceeds the bound {bound}"
    );
    // The sample should fill the interval: the largest |value| is close to the bound.
    assert!(
        max > 0.9 * bound,
        "{what}: max |value| {max} far below the bound {bound}"
    );
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let expected_var = bound * bound / 3.0;
    // Standard error of a uniform's sample variance: sqrt(4/45)·b²/sqrt(n) ≈ 0.3·b²/sqrt(n).
    let tol = 5.0 * 0.3 * bound * bound / n.sqrt();
    assert!(
        (var - expected_var).abs() < tol,
        "{what}: variance {var} vs U(±{bound}) variance {expected_var} (tol {tol})"
    );
    let mean_tol = 5.0 * bound / (3.0 * n).sqrt();
    assert!(
        mean.abs() < mean_tol,
        "{what}: mean {mean} (tol {mean_tol})"
    );
}

#[test]
fn every_layer_follows_the_reference_distributions() {
    let config = SirenConfig::new(12).with_hidden(256).with_n_hidden(2);
    let init = SirenInitializer::new(30.0);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let layers = init.init(&config, &mut rng);
    assert_eq!(layers.len(), 4);

    // First layer: W ~ U(±1/4), b ~ U(±1/2). Its 1024 weights are enough for the test.
    assert_eq!((layers[0].fan_in, layers[0].fan_out), (4, 256));
    check_uniform(&layers[0].weight, 0.25, "first weight");
    assert!((init.weight_bound(LayerRole::First, 4) - 0.25).abs() < 1e-15);
    assert!((init.bias_bound(4) - 0.5).abs() < 1e-15);

    // Hidden layers: W ~ U(±√(6/256)/30), b ~ U(±1/16).
    let hidden_bound = (6.0f64 / 256.0).sqrt() / 30.0;
    for (i, layer) in layers[1..3].iter().enumerate() {
        check_uniform(&layer.weight, hidden_bound, &format!("hidden {i} weight"));
    }
    // Output layer: the same weight bound as the hidden layers (not zero-initialised).
    check_uniform(&layers[3].weight, hidden_bound, "output weight");
    assert!((init.weight_bound(LayerRole::Output, 128) - 0.007_216_878).abs() < 1e-8);

    // Biases keep PyTorch's fan-in bound. Pool the hidden biases for a usable sample.
    let biases: Vec<f64> = layers[1..].iter().flat_map(|l| l.bias.clone()).collect();
    check_uniform(&biases, 1.0 / 16.0, "hidden and output biases");
    let first_biases = &layers[0].bias;
    assert!(first_biases.iter().all(|b| b.abs() <= 0.5));
}

#[test]
fn a_weight_scale_widens_the_sine_layers_and_leaves_the_output_layer() {
    let config = SirenConfig::new(12).with_hidden(256);
    let draw = |scale: f64| {
        SirenInitializer::new(30.0)
            .with_scale(scale)
            .init(&config, &mut ChaCha8Rng::seed_from_u64(7))
    };
    let (plain, scaled) = (draw(1.0), draw(2.5));
    // The same stream, so every sine weight is 2.5 times the authors' (to rounding), and
    // the output layer and every bias are the authors' draws exactly.
    for (p, s) in plain[..3].iter().zip(&scaled[..3]) {
        for (a, b) in p.weight.iter().zip(&s.weight) {
            // Rounding of `low + (high − low)·u` is relative to the bound, not to the value.
            assert!((b - 2.5 * a).abs() <= 1e-14, "{a} {b}");
        }
        assert_eq!(p.bias, s.bias);
    }
    assert_eq!(plain[3], scaled[3]);
    check_uniform(&scaled[0].weight, 2.5 * 0.25, "scaled first weight");
    // A scale of 1 is the authors' initialisation bit for bit, through the config too.
    assert_eq!(
        plain,
        SirenInitializer::new(30.0).init(&config, &mut ChaCha8Rng::seed_from_u64(7))
    );
    let field = |scale: f64| {
        DomaFieldConfig::new(Variant::Affinity)
            .with_init_scale(scale)
            .init(3, &burn::tensor::Device::flex())
            .siren
            .to_weights()
    };
    assert_eq!(
        field(1.0),
        DomaFieldConfig::new(Variant::Affinity)
            .init(3, &burn::tensor::Device::flex())
            .siren
            .to_weights()
    );
    assert_ne!(field(1.0), field(1.5));
    // A scale that is not a positive number is refused.
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let c = DomaFieldConfig::new(Variant::Affinity).with_init_scale(bad);
        assert!(c.shape.validate().is_err(), "{bad}");
    }
}

#[test]
fn the_same_seed_gives_the_same_weights() {
    let config = SirenConfig::new(3).with_hidden(16);
    let init = SirenInitializer::new(30.0);
    let a = init.init(&config, &mut ChaCha8Rng::seed_from_u64(3));
    let b = init.init(&config, &mut ChaCha8Rng::seed_from_u64(3));
    let c = init.init(&config, &mut ChaCha8Rng::seed_from_u64(4));
    assert_eq!(a, b);
    assert_ne!(a, c);
}

#[test]
fn parameter_counts_equal_the_authors_code() {
    let device = burn::tensor::Device::flex();
    let count = |v: Variant| DomaFieldConfig::new(v).init(0, &device).param_count();
    assert_eq!(count(Variant::Affinity), 35_212);
    assert_eq!(count(Variant::Trans), 34_051);
    // 4·128+128 + 2·(128²+128) + 128·O + O.
    assert_eq!(count(Variant::Se3), 33_664 + 129 * 9);
    assert_eq!(count(Variant::ScaledSe3), 33_664 + 129 * 10);
    assert_eq!(SirenConfig::new(12).num_params(), 35_212);
}

#[test]
fn weights_survive_a_round_trip_through_the_device() {
    let device = burn::tensor::Device::flex();
    let config = SirenConfig::new(12).with_hidden(8).with_n_hidden(1);
    let layers = SirenInitializer::new(30.0).init(&config, &mut ChaCha8Rng::seed_from_u64(1));
    let siren = doma::siren::Siren::from_weights(&layers, 30.0, &device);
    let back = siren.to_weights();
    for (a, b) in layers.iter().zip(&back) {
        assert_eq!((a.fan_in, a.fan_out), (b.fan_in, b.fan_out));
        for (x, y) in a.weight.iter().zip(&b.weight) {
            assert_eq!(*x as f32, *y as f32);
        }
    }
}
