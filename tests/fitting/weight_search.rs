//! Choosing a regulariser's weight by validation: the chosen weight's validation EPE is the
//! grid's minimum, the validation points are training points (the test points never reach
//! the search), and bad search settings are refused naming their flag.

use crate::common;

use burn::tensor::Device;
use common::backward_lock;
use doma::data::synthetic::{Motion, benchmark_sequence};
use doma::field::{DomaFieldConfig, Variant};
use doma::prelude::*;
use doma::train::FitConfig;
use doma::train::select::{Penalty, WeightSearch, choose_weight, validation_split};

#[test]
fn the_validation_points_are_training_points_split_by_seed() {
    let (fit, val) = validation_split(750, 0.2, 3).unwrap();
    assert_eq!((fit.len(), val.len()), (600, 150));
    let mut all: Vec<usize> = fit.iter().chain(&val).copied().collect();
    all.sort_unstable();
    assert_eq!(
        all,
        (0..750).collect::<Vec<_>>(),
        "disjoint, covering the training set"
    );
    assert_eq!(validation_split(750, 0.2, 3).unwrap(), (fit, val), "seeded");
    assert_ne!(
        validation_split(750, 0.2, 4).unwrap().1,
        validation_split(750, 0.2, 3).unwrap().1
    );
}

#[test]
fn the_chosen_weight_has_the_lowest_validation_error_of_its_grid() {
    let _g = backward_lock();
    let seq = benchmark_sequence(Motion::Shearing, 0).unwrap();
    // The search is handed the training trajectories alone; the 2250 test points are not
    // an argument, so they cannot be read. A small case: 6 frames, width 16.
    let train = seq.train.select_frames(0..6, 1).unwrap();
    let base = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity).with_hidden(16))
        .with_learning_rate(1e-3);
    let search = WeightSearch {
        grid: vec![0.0, 1e-2, 1.0, 100.0],
        validation_fraction: 0.2,
        iterations: 3,
    };
    let mut seen = Vec::new();
    let choice = choose_weight(
        &base,
        Penalty::Smoothness,
        &train,
        &search,
        &Device::flex(),
        |p| seen.push(p.weight),
    )
    .unwrap();
    assert_eq!(seen, search.grid, "every weight tried, in order");
    assert_eq!(choice.grid.len(), 4);
    let best = choice
        .grid
        .iter()
        .map(|p| p.validation_epe_x1e4)
        .fold(f64::INFINITY, f64::min);
    let chosen = choice
        .grid
        .iter()
        .find(|p| p.weight == choice.weight)
        .unwrap();
    assert_eq!(chosen.validation_epe_x1e4, best);
    // A search is a function of the training data and the seed: the same twice.
    let again = choose_weight(
        &base,
        Penalty::Smoothness,
        &train,
        &search,
        &Device::flex(),
        |_| {},
    )
    .unwrap();
    assert_eq!(again, choice);
}

#[test]
fn bad_search_settings_are_refused_naming_the_flag() {
    let ok = WeightSearch::default();
    ok.validate().unwrap();
    for (search, flag) in [
        (
            WeightSearch {
                grid: vec![],
                ..ok.clone()
            },
            "--weight-grid",
        ),
        (
            WeightSearch {
                grid: vec![0.0, -1.0],
                ..ok.clone()
            },
            "--weight-grid",
        ),
        (
            WeightSearch {
                validation_fraction: 1.0,
                ..ok.clone()
            },
            "--validation-fraction",
        ),
        (
            WeightSearch {
                validation_fraction: 0.0,
                ..ok.clone()
            },
            "--validation-fraction",
        ),
        (
            WeightSearch {
                iterations: 0,
                ..ok.clone()
            },
            "--search-iters",
        ),
    ] {
        let err = search.validate().unwrap_err().to_string();
        assert!(err.contains(flag), "{err}");
    }
}

#[test]
fn a_validation_fraction_that_leaves_no_search_points_names_the_flag() {
    let err = validation_split(10, 0.999, 0).unwrap_err().to_string();
    assert!(err.contains("--validation-fraction 0.999"), "{err}");
    assert!(validation_split(10, 0.2, 0).is_ok());
}
