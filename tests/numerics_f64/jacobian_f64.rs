//! The `Autodiff` Jacobian in f64 against both oracles, to 1e-6 relative: Burn's
//! reverse mode, and central finite differences of J and of the θ-gradient of the
//! smoothness (and elasticity) loss. Its own test binary, because a device's float
//! type is set once per process.

use crate::common;

use common::oracle::{
    N, Output, autodiff_theta_grad, check_against_reverse, fd_jacobian, fd_theta_grad,
    forward_jacobian, small_field,
};
use common::{backward_lock, f64_flex, random_points, rel_err};
use doma::field::Variant;

#[test]
fn forward_mode_matches_reverse_mode() {
    let _guard = backward_lock();
    check_against_reverse(&f64_flex(), 1e-6);
}

#[test]
fn forward_mode_matches_finite_differences() {
    let device = f64_flex();
    let x = random_points(N, 31);
    for variant in Variant::ALL {
        let field = small_field(variant, &device);
        for which in [Output::Raw, Output::Warp] {
            let fwd = forward_jacobian(&field, &x, which, &device);
            let fd = fd_jacobian(&field, &x, which, &device, 1e-6);
            let e = rel_err(&fwd, &fd);
            assert!(
                e < 1e-6,
                "{variant:?} {which:?}: J vs finite differences {e:e}"
            );
        }
    }
}

fn check_theta_gradient(elastic: bool) {
    let _guard = backward_lock();
    let device = f64_flex();
    let ad = device.clone().autodiff();
    let x = random_points(N, 41);
    for variant in Variant::ALL {
        let field = small_field(variant, &ad);
        let auto = autodiff_theta_grad(&field, &x, elastic, &ad);
        let plain = small_field(variant, &device);
        let fd = fd_theta_grad(&plain, &x, elastic, &device, 1e-6);
        let e = rel_err(&auto, &fd);
        assert!(
            e < 1e-6,
            "{variant:?} (elastic {elastic}): θ-gradient vs finite differences {e:e}\n auto {auto:?}\n fd   {fd:?}"
        );
    }
}

#[test]
fn smoothness_theta_gradient_matches_finite_differences() {
    check_theta_gradient(false);
}

#[test]
fn elasticity_theta_gradient_matches_finite_differences() {
    check_theta_gradient(true);
}
