//! The `Analytic` Jacobian (hand-written backward) against `Autodiff` in f32 (1e-3
//! relative, docs/design.md §2): the outputs, J of the raw outputs and of the warp, and the
//! gradient of every parameter θ of `L_H` and of `L_H + L_E`, for every variant, on
//! flex, ndarray and wgpu (skipped
//! without an adapter, except under CI, where that fails).

use crate::common;

use burn::tensor::Device;
use common::oracle::{
    N, Output, all_parameters, method_jacobian, method_outputs, plain_outputs, small_field,
    theta_grad_at,
};
use common::{backward_lock, random_points, rel_err};
use doma::field::Variant;
use doma::jacobian::{Analytic, Autodiff};

const TOL: f64 = 1e-3;

fn check_device(device: &Device) {
    let _guard = backward_lock();
    let ad = device.clone().autodiff();
    let x = random_points(N, 77);
    for variant in Variant::ALL {
        let field = small_field(variant, &ad);
        for which in [Output::Raw, Output::Warp] {
            let plain = plain_outputs(&field, &x, which, &ad);
            let out = method_outputs(&field, &x, which, &Analytic, &ad);
            let e = rel_err(&out, &plain);
            assert!(e < TOL, "{variant:?} {which:?}: outputs {e:e}");
            let jac = method_jacobian(&field, &x, which, &Analytic, &ad);
            let reference = method_jacobian(&field, &x, which, &Autodiff, &ad);
            let e = rel_err(&jac, &reference);
            assert!(e < TOL, "{variant:?} {which:?}: J {e:e}");
        }
        let params = all_parameters(&field);
        for elastic in [false, true] {
            let g = theta_grad_at(&field, &x, elastic, &Analytic, &ad, &params);
            let reference = theta_grad_at(&field, &x, elastic, &Autodiff, &ad, &params);
            let e = rel_err(&g, &reference);
            assert!(
                e < TOL,
                "{variant:?} (elastic {elastic}): θ-gradient of all {} parameters {e:e}",
                params.len()
            );
        }
    }
}

#[test]
fn analytic_matches_autodiff_on_flex() {
    check_device(&Device::flex());
}

#[test]
#[allow(deprecated)]
fn analytic_matches_autodiff_on_ndarray() {
    check_device(&Device::ndarray());
}

#[test]
fn analytic_matches_autodiff_on_wgpu() {
    if let Some(device) = common::wgpu_device_or_skip("analytic_matches_autodiff_on_wgpu") {
        check_device(&device);
    }
}

/// The value-only path (`Analytic::forward`, fused sine layers with their own backward)
/// against the plain SIREN: outputs, and the gradient of every parameter of a loss on them.
fn check_value_path(device: &Device) {
    use burn::tensor::{Tensor, TensorData};
    use doma::field::time_input;
    use doma::jacobian::JacobianMethod;
    let _guard = backward_lock();
    let ad = device.clone().autodiff();
    let field = small_field(Variant::Affinity, &ad);
    let x = random_points(N, 99);
    let xt = || {
        let x = Tensor::<2>::from_data(TensorData::new(x.clone(), [N, 3]), &ad);
        time_input(x, 0.25)
    };
    let grads_of = |out: Tensor<2>| {
        let grads = out.clone().mul(out).sum().backward();
        let mut g = Vec::new();
        for layer in field
            .siren
            .sine
            .iter()
            .chain(std::iter::once(&field.siren.output))
        {
            g.extend(common::to_vec(
                layer.weight.val().grad(&grads).expect("a weight gradient"),
            ));
            let b = layer.bias.as_ref().expect("a bias").val();
            g.extend(common::to_vec(b.grad(&grads).expect("a bias gradient")));
        }
        g
    };
    let fused = Analytic.forward(&field.siren, xt());
    let plain = field.siren.forward(xt());
    let e = rel_err(
        &common::to_vec(fused.clone()),
        &common::to_vec(plain.clone()),
    );
    assert!(e < 1e-5, "value path outputs {e:e}");
    let e = rel_err(&grads_of(fused), &grads_of(plain));
    assert!(e < TOL, "value path θ-gradient {e:e}");
}

#[test]
fn value_path_matches_the_plain_siren_on_flex() {
    check_value_path(&Device::flex());
}

#[test]
#[allow(deprecated)]
fn value_path_matches_the_plain_siren_on_ndarray() {
    check_value_path(&Device::ndarray());
}

#[test]
fn value_path_matches_the_plain_siren_on_wgpu() {
    if let Some(device) = common::wgpu_device_or_skip("value_path_matches_the_plain_siren_on_wgpu")
    {
        check_value_path(&device);
    }
}

/// The two shapes of the analytic op, the whole network as one node (the CPU path) and one
/// node per layer (the wgpu path), agree on every backend: outputs with tangents, and the
/// gradient of every parameter of a loss on them.
fn check_both_paths(device: &Device) {
    use burn::tensor::{Tensor, TensorData};
    use doma::field::time_input;
    use doma::jacobian::analytic::{fused_siren, layered_siren};
    let _guard = backward_lock();
    let ad = device.clone().autodiff();
    let field = small_field(Variant::Affinity, &ad);
    let x = random_points(N, 5);
    let run = |path: fn(&doma::siren::Siren, Tensor<2>, bool) -> Tensor<2>| {
        let x = Tensor::<2>::from_data(TensorData::new(x.clone(), [N, 3]), &ad);
        let out = path(&field.siren, time_input(x, 0.75), true);
        let grads = out.clone().mul(out.clone()).sum().backward();
        let mut g = common::to_vec(out);
        for layer in field.siren.sine.iter().chain([&field.siren.output]) {
            g.extend(common::to_vec(
                layer.weight.val().grad(&grads).expect("g_W"),
            ));
            let b = layer.bias.as_ref().expect("a bias").val();
            g.extend(common::to_vec(b.grad(&grads).expect("g_b")));
        }
        g
    };
    let e = rel_err(&run(fused_siren), &run(layered_siren));
    assert!(e < TOL, "whole-network op vs per-layer ops: {e:e}");
}

#[test]
fn both_paths_of_the_op_agree_on_flex() {
    check_both_paths(&Device::flex());
}

#[test]
fn both_paths_of_the_op_agree_on_wgpu() {
    if let Some(device) = common::wgpu_device_or_skip("both_paths_of_the_op_agree_on_wgpu") {
        check_both_paths(&device);
    }
}
