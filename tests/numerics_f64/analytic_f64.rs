//! The `Analytic` Jacobian in f64 against central finite differences, to 1e-6 relative
//! (docs/design.md §2): J of the raw outputs and of the warp, and the gradient of every parameter
//! θ of `L_H + L_E` for every variant. Its own test binary, because a device's float type
//! is set once per process.

use crate::common;

use common::oracle::{
    N, Output, all_parameters, fd_jacobian, fd_theta_grad_at, method_jacobian, method_outputs,
    plain_outputs, small_field, theta_grad_at,
};
use common::{backward_lock, f64_flex, random_points, rel_err};
use doma::field::Variant;
use doma::jacobian::Analytic;

#[test]
fn analytic_jacobian_matches_finite_differences() {
    let device = f64_flex();
    let x = random_points(N, 131);
    for variant in Variant::ALL {
        let field = small_field(variant, &device);
        for which in [Output::Raw, Output::Warp] {
            let out = method_outputs(&field, &x, which, &Analytic, &device);
            let plain = plain_outputs(&field, &x, which, &device);
            let e = rel_err(&out, &plain);
            assert!(e < 1e-12, "{variant:?} {which:?}: outputs {e:e}");
            let jac = method_jacobian(&field, &x, which, &Analytic, &device);
            let fd = fd_jacobian(&field, &x, which, &device, 1e-6);
            let e = rel_err(&jac, &fd);
            assert!(
                e < 1e-6,
                "{variant:?} {which:?}: J vs finite differences {e:e}"
            );
        }
    }
}

#[test]
fn analytic_theta_gradient_matches_finite_differences() {
    let _guard = backward_lock();
    let device = f64_flex();
    let ad = device.clone().autodiff();
    let x = random_points(N, 141);
    for variant in Variant::ALL {
        let field = small_field(variant, &ad);
        let plain = small_field(variant, &device);
        let params = all_parameters(&field);
        let g = theta_grad_at(&field, &x, true, &Analytic, &ad, &params);
        let fd = fd_theta_grad_at(&plain, &x, true, &device, 1e-6, &params);
        let e = rel_err(&g, &fd);
        assert!(
            e < 1e-6,
            "{variant:?}: θ-gradient of all {} parameters vs finite differences {e:e}",
            params.len()
        );
    }
}
