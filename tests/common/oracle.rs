//! Independent oracles for the forward-mode Jacobian: Burn's reverse mode (one backward
//! per output channel) and central finite differences.

use burn::tensor::{Device, Tensor};
use doma::prelude::*;

use super::{random_points, rel_err, tensor2, to_vec};
use doma::field::{DomaField, DomaFieldConfig, MotionField, Variant};
use doma::jacobian::{Autodiff, JacobianMethod};
use doma::loss::{self, SmoothnessNorm};
use doma::siren::Siren;

pub const N: usize = 8;
pub const T: f64 = 0.37;

#[derive(Clone, Copy, Debug)]
pub enum Output {
    /// The raw SIREN outputs `o` (what `L_H` penalises).
    Raw,
    /// The warped points `y` (what the elasticity loss uses).
    Warp,
}

fn pick(
    field: &DomaField,
    x: Tensor<2>,
    which: Output,
    jac: Option<&dyn JacobianMethod>,
) -> (Tensor<2>, Option<Tensor<3>>) {
    // No method: the plain forward pass (no tangents).
    let out = match jac {
        Some(method) => field.warp_dual(x, T, method),
        None => field.warp_values(x, T, &Autodiff),
    };
    let d = match which {
        Output::Raw => out.raw,
        Output::Warp => out.warped,
    };
    (d.value, d.tangent)
}

pub fn small_field(variant: Variant, device: &Device) -> DomaField {
    DomaFieldConfig::new(variant)
        .with_hidden(16)
        .init(11, device)
}

/// The forward-mode Jacobian of `method`, laid out `[3, N, C]`.
pub fn method_jacobian(
    field: &DomaField,
    x: &[f64],
    which: Output,
    method: &dyn JacobianMethod,
    device: &Device,
) -> Vec<f64> {
    let (_, tangent) = pick(
        field,
        tensor2(x.to_vec(), [N, 3], device),
        which,
        Some(method),
    );
    to_vec(tangent.expect("tangents"))
}

/// The outputs computed alongside `method`'s Jacobian, `[N, C]`.
pub fn method_outputs(
    field: &DomaField,
    x: &[f64],
    which: Output,
    method: &dyn JacobianMethod,
    device: &Device,
) -> Vec<f64> {
    to_vec(
        pick(
            field,
            tensor2(x.to_vec(), [N, 3], device),
            which,
            Some(method),
        )
        .0,
    )
}

/// The plain outputs (no Jacobian requested), `[N, C]`.
pub fn plain_outputs(field: &DomaField, x: &[f64], which: Output, device: &Device) -> Vec<f64> {
    to_vec(pick(field, tensor2(x.to_vec(), [N, 3], device), which, None).0)
}

/// The forward-mode Jacobian of [`Autodiff`], laid out `[3, N, C]`.
pub fn forward_jacobian(field: &DomaField, x: &[f64], which: Output, device: &Device) -> Vec<f64> {
    method_jacobian(field, x, which, &Autodiff, device)
}

/// The Jacobian from reverse mode, one backward per output channel, `[3, N, C]`.
pub fn reverse_jacobian(field: &DomaField, x: &[f64], which: Output, ad: &Device) -> Vec<f64> {
    let probe = tensor2(x.to_vec(), [N, 3], ad);
    let channels = pick(field, probe, which, None).0.dims()[1];
    let mut jac = vec![0.0; 3 * N * channels];
    for c in 0..channels {
        let xt = tensor2(x.to_vec(), [N, 3], ad).require_grad();
        let (value, _) = pick(field, xt.clone(), which, None);
        let grads = value.narrow(1, c, 1).sum().backward();
        let g = to_vec(xt.grad(&grads).expect("x takes part in the graph"));
        for n in 0..N {
            for k in 0..3 {
                jac[(k * N + n) * channels + c] = g[3 * n + k];
            }
        }
    }
    jac
}

/// Central differences of the outputs in `x`, `[3, N, C]`.
pub fn fd_jacobian(
    field: &DomaField,
    x: &[f64],
    which: Output,
    device: &Device,
    h: f64,
) -> Vec<f64> {
    let eval = |p: Vec<f64>| to_vec(pick(field, tensor2(p, [N, 3], device), which, None).0);
    let channels = eval(x.to_vec()).len() / N;
    let mut jac = vec![0.0; 3 * N * channels];
    for k in 0..3 {
        // Every point moves along axis k at once: the field acts point by point.
        let shifted = |s: f64| -> Vec<f64> {
            x.iter()
                .enumerate()
                .map(|(i, v)| if i % 3 == k { v + s } else { *v })
                .collect()
        };
        let (plus, minus) = (eval(shifted(h)), eval(shifted(-h)));
        for i in 0..N * channels {
            jac[k * N * channels + i] = (plus[i] - minus[i]) / (2.0 * h);
        }
    }
    jac
}

/// The loss whose θ-gradient is checked: `L_H` (squared) on the raw Jacobian, plus the
/// elasticity of the warp's Jacobian when `elastic`.
pub fn jacobian_loss(
    field: &DomaField,
    x: &[f64],
    elastic: bool,
    method: &dyn JacobianMethod,
    device: &Device,
) -> Tensor<1> {
    let out = field.warp_dual(tensor2(x.to_vec(), [N, 3], device), T, method);
    let mut l = loss::smoothness(out.raw.tangent.unwrap(), SmoothnessNorm::Squared);
    if elastic {
        l = l + loss::elasticity(out.warped.tangent.unwrap());
    }
    l
}

/// (layer, is_bias, flat index) of the parameters probed by the θ-gradient test.
pub fn probes(field: &DomaField) -> Vec<(usize, bool, usize)> {
    let layers = field.siren.to_weights();
    let mut out = Vec::new();
    for (l, w) in layers.iter().enumerate() {
        let nw = w.weight.len();
        for i in [0, nw / 3, nw / 2 + 1, nw - 1] {
            out.push((l, false, i));
        }
        for i in [0, w.bias.len() - 1] {
            out.push((l, true, i));
        }
    }
    out
}

/// Every (layer, is_bias, flat index) of the SIREN: all of θ.
pub fn all_parameters(field: &DomaField) -> Vec<(usize, bool, usize)> {
    let mut out = Vec::new();
    for (l, w) in field.siren.to_weights().iter().enumerate() {
        out.extend((0..w.weight.len()).map(|i| (l, false, i)));
        out.extend((0..w.bias.len()).map(|i| (l, true, i)));
    }
    out
}

/// The θ-gradient from Burn's reverse mode through the Jacobian of [`Autodiff`].
pub fn autodiff_theta_grad(field: &DomaField, x: &[f64], elastic: bool, ad: &Device) -> Vec<f64> {
    theta_grad_at(field, x, elastic, &Autodiff, ad, &probes(field))
}

/// The θ-gradient through the Jacobian of `method`, at the given parameters.
pub fn theta_grad_at(
    field: &DomaField,
    x: &[f64],
    elastic: bool,
    method: &dyn JacobianMethod,
    ad: &Device,
    params: &[(usize, bool, usize)],
) -> Vec<f64> {
    let grads = jacobian_loss(field, x, elastic, method, ad).backward();
    let siren = &field.siren;
    let layers: Vec<&burn::nn::Linear> = siren
        .sine
        .iter()
        .chain(std::iter::once(&siren.output))
        .collect();
    // No gradient means the loss does not depend on the parameter (for example the
    // output bias under L_H, which only sees ∂o/∂x): its derivative is 0.
    let host = |t: Option<Tensor<2>>, len: usize| t.map_or(vec![0.0; len], to_vec);
    let per_layer: Vec<(Vec<f64>, Vec<f64>)> = layers
        .iter()
        .map(|layer| {
            let w = layer.weight.val();
            let nw = w.dims()[0] * w.dims()[1];
            let b = layer.bias.as_ref().unwrap().val();
            let nb = b.dims()[0];
            let gb = b.grad(&grads).map_or(vec![0.0; nb], to_vec);
            (host(w.grad(&grads), nw), gb)
        })
        .collect();
    params
        .iter()
        .map(|&(l, bias, i)| {
            if bias {
                per_layer[l].1[i]
            } else {
                per_layer[l].0[i]
            }
        })
        .collect()
}

/// The θ-gradient by central differences on the host weights.
pub fn fd_theta_grad(
    field: &DomaField,
    x: &[f64],
    elastic: bool,
    device: &Device,
    h: f64,
) -> Vec<f64> {
    fd_theta_grad_at(field, x, elastic, device, h, &probes(field))
}

/// Central differences of the loss at the given parameters.
pub fn fd_theta_grad_at(
    field: &DomaField,
    x: &[f64],
    elastic: bool,
    device: &Device,
    h: f64,
    params: &[(usize, bool, usize)],
) -> Vec<f64> {
    let base = field.siren.to_weights();
    let loss_at = |l: usize, bias: bool, i: usize, s: f64| {
        let mut w = base.clone();
        if bias {
            w[l].bias[i] += s;
        } else {
            w[l].weight[i] += s;
        }
        let f = DomaField {
            siren: Siren::from_weights(&w, field.siren.omega, device),
            variant: field.variant,
            time_scale: field.time_scale,
        };
        to_vec(jacobian_loss(&f, x, elastic, &Autodiff, device))[0]
    };
    params
        .iter()
        .map(|&(l, b, i)| (loss_at(l, b, i, h) - loss_at(l, b, i, -h)) / (2.0 * h))
        .collect()
}

/// Checks forward mode against reverse mode for every variant and both outputs.
pub fn check_against_reverse(device: &Device, tol: f64) {
    let ad = device.clone().autodiff();
    let x = random_points(N, 21);
    for variant in Variant::ALL {
        let field = small_field(variant, &ad);
        for which in [Output::Raw, Output::Warp] {
            let fwd = forward_jacobian(&field, &x, which, &ad);
            let rev = reverse_jacobian(&field, &x, which, &ad);
            let e = rel_err(&fwd, &rev);
            assert!(
                e < tol,
                "{variant:?} {which:?}: forward vs reverse relative error {e:e} ≥ {tol:e}"
            );
        }
    }
}
