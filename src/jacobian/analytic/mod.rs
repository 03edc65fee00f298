//! `Analytic`: the hand-derived SIREN Jacobian (paper Eq. 6; DESIGN §2) as one custom
//! Burn operation per sine layer, with a hand-written backward.
//!
//! A sine layer works on the *stacked* matrix `S = [h; ḣ_x; ḣ_y; ḣ_z]` (`[4N, d_in]`): the
//! values and their three spatial tangents. One matmul `Z = S W` gives both the
//! pre-activation `z = ω(Z[0..N] + b)` and its tangents `ż = ω Z[N..4N]`, and the layer
//! returns `[sin z; cos z ⊙ ż]`. The backward ([`backward`]) is two matmuls and one
//! elementwise pass, with no autodiff graph over the inside of the layer.
//!
//! The operation is a Burn backend extension ([`SirenBackend`]), split like Burn's
//! `custom-cubecl-kernel` example: [`forward`] holds the tensor-primitive implementation
//! used by ndarray, [`cpu`] the fused raw-buffer loops used by flex, [`backward`] the
//! `Autodiff` implementation,
//! and [`kernel`] the CubeCL kernels that fuse the elementwise work on wgpu.

#![allow(deprecated)] // `NdArray` stays selectable although Burn deprecates it.

pub mod backward;
pub mod cpu;
pub mod forward;
pub mod kernel;

use burn::backend::{Dispatch, backend_extension, tensor::FloatTensor};
use burn::tensor::Tensor;

use super::{Dual, JacobianMethod};
use crate::siren::Siren;

/// The backend operations of the analytic SIREN Jacobian.
#[backend_extension(Flex, NdArray, Cube, Autodiff)]
pub trait SirenBackend: burn::backend::Backend {
    /// The elementwise part of a sine layer: from `zs = S W` (`[4N, d]`) and the bias `[d]`,
    /// `[sin z; cos z ⊙ ż]` with `z = ω(zs[0..N] + b)` and `ż = ω zs[N..4N]`.
    fn sine_dual_activation(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        forward::activation::<Self>(zs, bias, omega)
    }

    /// The elementwise part of the backward: from `zs`, the bias and the upstream
    /// gradient `G = [g_h; g_ḣ]` (`[4N, d]`), the gradient with respect to `zs`,
    /// `ω [g_h ⊙ cos z − sin z ⊙ Σ_k g_ḣ,k ⊙ ż_k ; g_ḣ ⊙ cos z]`.
    fn sine_dual_activation_backward(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        forward::activation_backward::<Self>(zs, bias, grad, omega)
    }

    /// One sine layer on the stacked values and tangents: `S [4N, d_in]`, `W [d_in, d_out]`,
    /// `b [d_out]` → `[sin z; cos z ⊙ ż]` (`[4N, d_out]`).
    fn sine_dual_layer(
        stacked: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        let zs = Self::float_matmul(stacked, weight);
        Self::sine_dual_activation(zs, bias, omega)
    }

    /// The elementwise part of a value-only sine layer: `sin(ω(zs + b))`.
    fn sine_activation(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        forward::plain_activation::<Self>(zs, bias, omega)
    }

    /// Its backward: `ω g ⊙ cos(ω(zs + b))`.
    fn sine_activation_backward(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        forward::plain_activation_backward::<Self>(zs, bias, grad, omega)
    }

    /// A value-only sine layer (Eq. 1): `sin(ω(X W + b))`, one matmul and one fused pass,
    /// for evaluations that need no Jacobian.
    fn sine_layer(
        input: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        let zs = Self::float_matmul(input, weight);
        Self::sine_activation(zs, bias, omega)
    }
}

/// flex: the elementwise parts as fused raw-buffer loops ([`cpu`]).
impl SirenBackend for burn::backend::Flex {
    fn sine_dual_activation(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        cpu::activation(zs, bias, omega)
    }

    fn sine_dual_activation_backward(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        cpu::activation_backward(zs, bias, grad, omega)
    }

    fn sine_activation(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        cpu::plain_activation(zs, bias, omega)
    }

    fn sine_activation_backward(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        cpu::plain_activation_backward(zs, bias, grad, omega)
    }
}

impl SirenBackend for burn::backend::NdArray {}

/// One sine layer of the analytic method on high-level tensors (see [`SirenBackend::sine_dual_layer`]).
pub fn sine_dual_layer(
    stacked: Tensor<2>,
    weight: Tensor<2>,
    bias: Tensor<1>,
    omega: f64,
) -> Tensor<2> {
    let out = Dispatch::sine_dual_layer(
        stacked.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
        omega,
    );
    Tensor::from_dispatch(out)
}

/// One value-only sine layer on high-level tensors (see [`SirenBackend::sine_layer`]).
pub fn sine_layer(input: Tensor<2>, weight: Tensor<2>, bias: Tensor<1>, omega: f64) -> Tensor<2> {
    let out = Dispatch::sine_layer(
        input.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
        omega,
    );
    Tensor::from_dispatch(out)
}

/// The hand-derived Jacobian (Eq. 6): forward-mode tangents through fused sine layers
/// with a hand-written backward for every weight and bias.
#[derive(Clone, Copy, Debug, Default)]
pub struct Analytic;

impl JacobianMethod for Analytic {
    fn name(&self) -> &'static str {
        "analytic"
    }

    fn forward(&self, siren: &Siren, xt: Tensor<2>) -> Tensor<2> {
        let mut h = xt;
        for layer in &siren.sine {
            let bias = layer.bias.as_ref().expect("SIREN layers have a bias").val();
            h = sine_layer(h, layer.weight.val(), bias, siren.omega);
        }
        siren.output.forward(h)
    }

    fn forward_dual(&self, siren: &Siren, xt: Tensor<2>) -> Dual {
        let [n, c] = xt.dims();
        // The input tangents are e_x, e_y, e_z (the time column has none).
        let seed = Dual::seed_spatial(xt);
        let tangent = seed
            .tangent
            .expect("a seed has tangents")
            .reshape([3 * n, c]);
        let mut stacked = Tensor::cat(vec![seed.value, tangent], 0);
        for layer in &siren.sine {
            let bias = layer.bias.as_ref().expect("SIREN layers have a bias").val();
            stacked = sine_dual_layer(stacked, layer.weight.val(), bias, siren.omega);
        }
        let out = stacked.matmul(siren.output.weight.val());
        let d_out = out.dims()[1];
        let bias = siren
            .output
            .bias
            .as_ref()
            .expect("SIREN layers have a bias")
            .val();
        Dual {
            value: out.clone().narrow(0, 0, n) + bias.unsqueeze_dim(0),
            tangent: Some(out.narrow(0, n, 3 * n).reshape([3, n, d_out])),
        }
    }
}
