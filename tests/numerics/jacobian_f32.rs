//! The `Autodiff` Jacobian in f32 against Burn's reverse mode (1e-3 relative).

use crate::common;

use burn::tensor::Device;
use common::oracle::{
    N, Output, check_against_reverse, forward_jacobian, reverse_jacobian, small_field,
};
use common::{backward_lock, random_points, rel_err};
use doma::field::Variant;

#[test]
fn forward_mode_matches_reverse_mode_on_flex() {
    let _guard = backward_lock();
    check_against_reverse(&Device::flex(), 1e-3);
}

#[test]
#[allow(deprecated)]
fn forward_mode_matches_reverse_mode_on_ndarray() {
    let _guard = backward_lock();
    check_against_reverse(&Device::ndarray(), 1e-3);
}

#[test]
fn the_jacobian_is_per_point() {
    // Moving one point must not change another point's Jacobian.
    let _guard = backward_lock();
    let ad = Device::flex().autodiff();
    let field = small_field(Variant::Affinity, &ad);
    let x = random_points(N, 5);
    let mut y = x.clone();
    y[0] += 0.3;
    let a = forward_jacobian(&field, &x, Output::Raw, &ad);
    let b = forward_jacobian(&field, &y, Output::Raw, &ad);
    let c = 12; // channels
    for k in 0..3 {
        let rest = |j: &Vec<f64>| j[(k * N + 1) * c..(k + 1) * N * c].to_vec();
        assert_eq!(rest(&a), rest(&b));
    }
    assert!(rel_err(&a, &reverse_jacobian(&field, &x, Output::Raw, &ad)) < 1e-3);
}
