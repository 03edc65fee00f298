//! The two ways doma differentiates a SIREN, checked against each other the way Burn's
//! `custom-cubecl-kernel` example checks a custom op: the outputs, their spatial Jacobian
//! and the gradient of every parameter of a loss on them must agree under a tolerance.
//! Then the speed-up of the hand-derived op on a training step.
//!
//! ```text
//! cargo run --release --example analytic_vs_autodiff
//! ```
//!
//! `Autodiff` runs the network on dual tensors (automatic forward mode); `Analytic` is the
//! hand-derived Jacobian of Eq. 6 as one custom Burn operation with a hand-written backward
//! (docs/design.md §2).

use burn::tensor::{Device, Tensor, TensorData};
use doma::backend::BackendKind;
use doma::experiments::speed::fit_step_rows;
use doma::field::{DomaField, DomaFieldConfig, Variant};
use doma::jacobian::{Analytic, Autodiff, JacobianKind, JacobianMethod};
use doma::loss::{SmoothnessNorm, smoothness};
use doma::prelude::*;
use doma::readback::to_vec;

/// Relative tolerance in f32.
const TOL: f64 = 1e-4;

/// The outputs and Jacobian of `field` at `x` by `method`, then the gradient of
/// `L_H + mean(o)` (Eq. 13) with respect to every parameter, all flattened in one order.
fn outputs_and_gradients(
    field: &DomaField,
    x: &Tensor<2>,
    method: &dyn JacobianMethod,
) -> anyhow::Result<Vec<f32>> {
    let raw = field.raw_dual(x.clone(), 0.25, method);
    let tangent = raw
        .tangent
        .clone()
        .expect("a Jacobian method gives tangents");
    let loss = smoothness(tangent.clone(), SmoothnessNorm::Squared) + raw.value.clone().mean();
    let grads = loss.backward();
    let mut all = to_vec::<f32, 2, _>(raw.value)?;
    all.extend(to_vec::<f32, 3, _>(tangent)?);
    for layer in field.siren.sine.iter().chain([&field.siren.output]) {
        let weight = layer
            .weight
            .val()
            .grad(&grads)
            .expect("every weight has a gradient");
        let bias = layer.bias.as_ref().expect("SIREN layers have a bias").val();
        all.extend(to_vec::<f32, 2, _>(weight)?);
        all.extend(to_vec::<f32, 1, _>(
            bias.grad(&grads).expect("a bias gradient"),
        )?);
    }
    Ok(all)
}

/// `‖a − b‖ / ‖b‖`.
fn relative_error(a: &[f32], b: &[f32]) -> f64 {
    let (mut diff, mut norm) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        diff += (*x as f64 - *y as f64).powi(2);
        norm += (*y as f64).powi(2);
    }
    (diff / norm.max(1e-30)).sqrt()
}

fn main() -> anyhow::Result<()> {
    // glibc's allocator tuned for training loops, as `doma bench` runs (docs/speed.md).
    doma::backend::tune_allocator();
    for (name, device) in [("flex", Device::flex()), ("ndarray", ndarray())] {
        // The paper's SIREN (d = 128, two hidden layers) with the Affinity head, on the
        // autodiff device, at 500 random points.
        let ad = device.autodiff();
        let field = DomaFieldConfig::new(Variant::Affinity).init(0, &ad);
        let x: Vec<f32> = (0..1500)
            .map(|i| ((i * 7919) % 2000) as f32 / 1000.0 - 1.0)
            .collect();
        let x = Tensor::<2>::from_data(TensorData::new(x, [500, 3]), &ad);
        let reference = outputs_and_gradients(&field, &x, &Autodiff)?;
        let analytic = outputs_and_gradients(&field, &x, &Analytic)?;
        let e = relative_error(&analytic, &reference);
        println!(
            "{name}: outputs, Jacobian and {} parameter gradients: relative difference {e:.1e}",
            field.siren.sine.len() * 2 + 2
        );
        anyhow::ensure!(
            e < TOL,
            "{name}: Analytic and Autodiff differ by {e:e} (> {TOL:e})"
        );
    }

    // The speed-up on one training step of the synthetic protocol (Affinity-H), the two
    // methods' steps timed in turn so that a drifting machine does not decide the ratio.
    let methods = [JacobianKind::Autodiff, JacobianKind::Analytic];
    let rows = fit_step_rows(BackendKind::Flex, &methods, true, 5, 30)?;
    for row in &rows {
        println!(
            "flex training step, {}: {:.2} ms",
            row.method.expect("a method"),
            row.ms
        );
    }
    let speedup = rows[1]
        .speedup
        .expect("Analytic's row states its paired speed-up");
    println!("Analytic is {speedup:.2}x faster than Autodiff (median of paired steps)");
    Ok(())
}

#[allow(deprecated)] // Burn deprecates NdArray, which doma keeps selectable.
fn ndarray() -> Device {
    Device::ndarray()
}
