//! `Analytic`: the hand-derived SIREN Jacobian (paper Eq. 6; DESIGN §2) as one custom
//! Burn operation for the whole network, with a hand-written backward.
//!
//! The network works on the *stacked* matrix `S = [h; ḣ_x; ḣ_y; ḣ_z]` (`[4N, d]`): the
//! values and their three spatial tangents. Per sine layer, one matmul `Z = S W` gives
//! both the pre-activation `z = ω(Z[0..N] + b)` and its tangents `ż = ω Z[N..4N]`, and the
//! layer returns `[sin z; cos z ⊙ ż]`. The output layer is one more matmul. The backward
//! is two matmuls and one elementwise pass per layer, with no autodiff graph inside the
//! network: the whole SIREN is one node.
//!
//! The operation is a Burn backend extension ([`SirenBackend`], one method, [`SirenBackend::siren`]),
//! split like Burn's `custom-cubecl-kernel` example:
//! - [`SirenOps`] is the per-backend forward (keeping what the backward needs) and backward;
//! - [`net`] implements it once on raw CPU buffers, with workspaces reused between steps,
//!   and [`host`] lends it flex's and ndarray's buffers;
//! - [`forward`] implements it from tensor primitives (the wgpu path, [`kernel`]);
//! - [`backward`] records it on the `Autodiff` graph.

#![allow(deprecated)] // `NdArray` stays selectable although Burn deprecates it.

pub mod backward;
pub mod cpu;
pub mod forward;
pub mod host;
pub mod kernel;
pub mod net;

use burn::backend::{Dispatch, backend_extension, tensor::FloatTensor};
use burn::tensor::Tensor;

use super::{Dual, JacobianMethod};
use crate::siren::Siren;

/// One backend's implementation of the whole-SIREN operation: the forward, which keeps
/// what the backward needs, and the hand-written backward (DESIGN §2).
///
/// `params` is one flat tensor, `[W_0, b_0, W_1, b_1, …, W_o, b_o]`: the sine layers'
/// weights (`[d_in, d_out]`, row-major) and biases (`[d_out]`), then the output layer's;
/// `shapes` gives each layer's `[d_in, d_out]`. (Burn 0.22's backend extensions take no
/// `Vec` of tensors, and an autodiff node has a fixed number of parents: one flat tensor
/// serves any depth, for the price of one copy of the ~50k parameters per call.)
/// The input is `[N, c]`; when
/// `dual`, its first three columns are seeded with `e_x, e_y, e_z` and the output stacks
/// the values and the three tangents, `[4N, O]`; otherwise it is `[N, O]`.
pub trait SirenOps: burn::backend::Backend {
    /// The activations the backward reads.
    type Saved: Clone + Send + std::fmt::Debug + 'static;

    /// The SIREN's output (Eq. 1), with its spatial tangents when `dual` (Eq. 6).
    fn siren_forward(
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        shapes: &[[usize; 2]],
        omega: f64,
        dual: bool,
    ) -> (FloatTensor<Self>, Self::Saved);

    /// From the output's gradient `grad`: the input's gradient (when `input_grad`) and
    /// the parameters' (flat, laid out like `params`).
    #[allow(clippy::too_many_arguments)]
    fn siren_backward(
        saved: Self::Saved,
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        shapes: &[[usize; 2]],
        grad: FloatTensor<Self>,
        omega: f64,
        dual: bool,
        input_grad: bool,
    ) -> (Option<FloatTensor<Self>>, FloatTensor<Self>);
}

/// The analytic SIREN as a backend operation, reachable from high-level tensors through
/// Burn's `Dispatch` ([`fused_siren`]), and the elementwise part of its sine layers, which
/// the tensor-primitive network ([`forward::siren`]) calls. The activations' default
/// bodies compose Burn primitives and are the reference; wgpu overrides them with CubeCL
/// kernels ([`kernel`]).
#[backend_extension(Flex, NdArray, Cube, Autodiff)]
pub trait SirenBackend: burn::backend::Backend {
    /// The whole SIREN (see [`SirenOps`] for the layout of `params` and the output).
    fn siren(
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        shapes: Vec<[usize; 2]>,
        omega: f64,
        dual: bool,
    ) -> FloatTensor<Self>;

    /// A dual sine layer's activation (Eq. 6): from `zs = S W` (`[4N, d]`, values then the
    /// three tangents) and the bias, `[sin z; cos z ⊙ ż]` with `z = ω(zs[0..N] + b)` and
    /// `ż = ω zs[N..4N]`.
    fn sine_dual_activation(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        forward::activation::<Self>(zs, bias, omega)
    }

    /// Its backward: from the upstream gradient `G = [g_h; g_ḣ]`, the gradient with respect
    /// to `zs`, `ω [g_h ⊙ cos z − sin z ⊙ Σ_k g_ḣ,k ⊙ ż_k ; g_ḣ ⊙ cos z]`.
    fn sine_dual_activation_backward(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        forward::activation_backward::<Self>(zs, bias, grad, omega)
    }

    /// A value-only sine layer's activation (Eq. 1): `sin(ω(zs + b))`.
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

    /// The first dual sine layer's activation (Eq. 6 at the input). Its input's tangents
    /// are the seeds `e_x, e_y, e_z`, so every point's tangent pre-activation is a row of
    /// `W`: from `z_v = X W` (`[N, d]`, the value rows only), `W` (`[c, d]`, `c ≥ 3`) and the
    /// bias, `[sin z; ω cos z ⊙ W[0]; ω cos z ⊙ W[1]; ω cos z ⊙ W[2]]` with `z = ω(z_v + b)`
    /// (`[4N, d]`). Neither the seeds nor their `3N` matmul rows are built.
    fn sine_dual_input_activation(
        zv: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        forward::input_activation::<Self>(zv, weight, bias, omega)
    }

    /// Its backward: from the upstream gradient `G = [g_h; g_ḣ]` (`[4N, d]`), what
    /// [`SirenBackend::sine_dual_activation_backward`] gives for the stacked
    /// `[z_v; W[0]; W[1]; W[2]]`: `ω [g_h ⊙ cos z − sin z ⊙ Σ_k g_ḣ,k ⊙ ω W[k] ; g_ḣ ⊙ cos z]`.
    fn sine_dual_input_activation_backward(
        zv: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        forward::input_activation_backward::<Self>(zv, weight, bias, grad, omega)
    }

    /// The first dual sine layer (the wgpu path): the input `X [N, c]` (spatial columns
    /// first), `W [c, d]`, `b [d]` → `[sin z; cos z ⊙ ż]` (`[4N, d]`), with one `N`-row
    /// matmul instead of the `4N` rows of the stacked input and its seeds.
    fn sine_dual_input_layer(
        input: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        let zv = Self::float_matmul(input, weight.clone());
        Self::sine_dual_input_activation(zv, weight, bias, omega)
    }

    /// One dual sine layer (the wgpu path, one autodiff node per layer): `S [4N, d_in]`,
    /// `W [d_in, d_out]`, `b [d_out]` → `[sin z; cos z ⊙ ż]` (`[4N, d_out]`).
    fn sine_dual_layer(
        stacked: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        let zs = Self::float_matmul(stacked, weight);
        Self::sine_dual_activation(zs, bias, omega)
    }

    /// One value-only sine layer (Eq. 1): `sin(ω(X W + b))`.
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

/// A CPU backend (no gradient tracking) runs the forward and drops the saved activations;
/// its activations keep the reference bodies (the fused op does not call them).
macro_rules! untracked_siren {
    ($($backend:ty),*) => {$(
        impl SirenBackend for $backend {
            fn siren(
                input: FloatTensor<Self>,
                params: FloatTensor<Self>,
                shapes: Vec<[usize; 2]>,
                omega: f64,
                dual: bool,
            ) -> FloatTensor<Self> {
                <Self as SirenOps>::siren_forward(input, params, &shapes, omega, dual).0
            }
        }
    )*};
}

untracked_siren!(burn::backend::Flex, burn::backend::NdArray);

/// The CPU backends lend their buffers to [`net`].
macro_rules! cpu_siren_ops {
    ($($backend:ty),*) => {$(
        impl SirenOps for $backend {
            type Saved = host::CpuSaved<FloatTensor<Self>>;

            fn siren_forward(
                input: FloatTensor<Self>,
                params: FloatTensor<Self>,
                shapes: &[[usize; 2]],
                omega: f64,
                dual: bool,
            ) -> (FloatTensor<Self>, Self::Saved) {
                host::siren_forward::<Self>(input, params, shapes, omega, dual)
            }

            fn siren_backward(
                saved: Self::Saved,
                input: FloatTensor<Self>,
                params: FloatTensor<Self>,
                shapes: &[[usize; 2]],
                grad: FloatTensor<Self>,
                omega: f64,
                dual: bool,
                input_grad: bool,
            ) -> (Option<FloatTensor<Self>>, FloatTensor<Self>) {
                host::siren_backward::<Self>(
                    saved, input, params, shapes, grad, omega, dual, input_grad,
                )
            }
        }
    )*};
}

cpu_siren_ops!(burn::backend::Flex, burn::backend::NdArray);

/// Which elementwise pass of a sine layer [`activation`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activation {
    /// [`SirenBackend::sine_dual_activation`] on `zs` (`[4N, d]`).
    DualForward,
    /// [`SirenBackend::sine_dual_activation_backward`] on `zs` and `grad` (`[4N, d]`).
    DualBackward,
    /// [`SirenBackend::sine_activation`] on `zs` (`[N, d]`).
    Forward,
    /// [`SirenBackend::sine_activation_backward`] on `zs` and `grad` (`[N, d]`).
    Backward,
    /// [`SirenBackend::sine_dual_input_activation`] on `zs = z_v` (`[N, d]`) and `weight`.
    DualInputForward,
    /// [`SirenBackend::sine_dual_input_activation_backward`] on `zs = z_v` (`[N, d]`),
    /// `weight` and `grad` (`[4N, d]`).
    DualInputBackward,
}

/// One sine layer's elementwise pass on high-level tensors, on whatever backend `zs` lives
/// (the CubeCL kernels on wgpu, the primitive reference on the CPU backends); `grad` is
/// used by the backward passes only, `weight` (the layer's `W`) by the input layer's only.
pub fn activation(
    which: Activation,
    zs: Tensor<2>,
    bias: Tensor<1>,
    grad: Tensor<2>,
    weight: Tensor<2>,
    omega: f64,
) -> Tensor<2> {
    let (zs, bias) = (zs.into_dispatch(), bias.into_dispatch());
    Tensor::from_dispatch(match which {
        Activation::DualInputForward => {
            Dispatch::sine_dual_input_activation(zs, weight.into_dispatch(), bias, omega)
        }
        Activation::DualInputBackward => Dispatch::sine_dual_input_activation_backward(
            zs,
            weight.into_dispatch(),
            bias,
            grad.into_dispatch(),
            omega,
        ),
        Activation::DualForward => Dispatch::sine_dual_activation(zs, bias, omega),
        Activation::DualBackward => {
            Dispatch::sine_dual_activation_backward(zs, bias, grad.into_dispatch(), omega)
        }
        Activation::Forward => Dispatch::sine_activation(zs, bias, omega),
        Activation::Backward => {
            Dispatch::sine_activation_backward(zs, bias, grad.into_dispatch(), omega)
        }
    })
}

/// One dual sine layer on high-level tensors (see [`SirenBackend::sine_dual_layer`]).
pub fn sine_dual_layer(
    stacked: Tensor<2>,
    weight: Tensor<2>,
    bias: Tensor<1>,
    omega: f64,
) -> Tensor<2> {
    Tensor::from_dispatch(Dispatch::sine_dual_layer(
        stacked.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
        omega,
    ))
}

/// The first dual sine layer on high-level tensors (see
/// [`SirenBackend::sine_dual_input_layer`]).
pub fn sine_dual_input_layer(
    input: Tensor<2>,
    weight: Tensor<2>,
    bias: Tensor<1>,
    omega: f64,
) -> Tensor<2> {
    Tensor::from_dispatch(Dispatch::sine_dual_input_layer(
        input.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
        omega,
    ))
}

/// One value-only sine layer on high-level tensors (see [`SirenBackend::sine_layer`]).
pub fn sine_layer(input: Tensor<2>, weight: Tensor<2>, bias: Tensor<1>, omega: f64) -> Tensor<2> {
    Tensor::from_dispatch(Dispatch::sine_layer(
        input.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
        omega,
    ))
}

/// The SIREN layer by layer (the wgpu path): one custom op per sine layer, whose
/// elementwise parts are CubeCL kernels, and Burn's linear output layer. `[N, O]`, or
/// `[4N, O]` stacked values and tangents when `dual` (see [`layered_dual`]).
pub fn layered_siren(siren: &Siren, xt: Tensor<2>, dual: bool) -> Tensor<2> {
    if !dual {
        let mut h = xt;
        for layer in &siren.sine {
            h = sine_layer(h, layer.weight.val(), bias_of(layer), siren.omega);
        }
        return h.matmul(siren.output.weight.val()) + bias_of(&siren.output).unsqueeze_dim(0);
    }
    let out = layered_dual(siren, xt);
    let [n, d_out] = out.value.dims();
    let tangent = out.tangent.expect("a dual pass has tangents");
    Tensor::cat(vec![out.value, tangent.reshape([3 * n, d_out])], 0)
}

/// The SIREN's values and spatial tangents layer by layer (the wgpu path, Eq. 6): the first
/// layer from the input itself, since its tangents are the seeds `e_x, e_y, e_z`
/// ([`sine_dual_input_layer`]); the others on the stacked `[h; ḣ_x; ḣ_y; ḣ_z]`
/// ([`sine_dual_layer`]); then one matmul of the output layer for all `4N` rows, whose bias
/// only the values take. `xt` is `[N, c]` with the spatial coordinates first.
pub fn layered_dual(siren: &Siren, xt: Tensor<2>) -> Dual {
    let [n, c] = xt.dims();
    assert!(c >= 3, "a spatial tangent needs 3 input columns, got {c}");
    let (first, rest) = siren.sine.split_first().expect("a SIREN has a sine layer");
    let mut h = sine_dual_input_layer(xt, first.weight.val(), bias_of(first), siren.omega);
    for layer in rest {
        h = sine_dual_layer(h, layer.weight.val(), bias_of(layer), siren.omega);
    }
    let out = h.matmul(siren.output.weight.val());
    let d_out = out.dims()[1];
    Dual {
        value: out.clone().narrow(0, 0, n) + bias_of(&siren.output).unsqueeze_dim(0),
        tangent: Some(out.narrow(0, n, 3 * n).reshape([3, n, d_out])),
    }
}

fn bias_of(layer: &burn::nn::Linear) -> Tensor<1> {
    layer.bias.as_ref().expect("SIREN layers have a bias").val()
}

/// The SIREN through the analytic op of its device: the whole network as one op on the
/// CPU backends ([`fused_siren`]), layer by layer on wgpu ([`layered_siren`]), where the
/// flat parameter vector of the whole-network op would cost a `cat` and eight slices per
/// call, each a kernel dispatch. Without tangents on wgpu, Burn's own layers: its fusion
/// engine folds the bias, the scaling and the sine into the matmul's epilogue, which an
/// opaque custom op prevents (lavapipe, value-only step: 32 ms against 42 ms through the
/// kernels; README, Speed).
pub fn analytic_siren(siren: &Siren, xt: Tensor<2>, dual: bool) -> Tensor<2> {
    if crate::backend::runs_on_cpu(&xt.device()) {
        fused_siren(siren, xt, dual)
    } else if dual {
        layered_siren(siren, xt, true)
    } else {
        siren.forward(xt)
    }
}

/// The whole SIREN through the fused operation, on high-level tensors: `[N, O]`, or
/// `[4N, O]` stacked values and tangents when `dual` (see [`SirenOps`]).
pub fn fused_siren(siren: &Siren, xt: Tensor<2>, dual: bool) -> Tensor<2> {
    let mut flat = Vec::with_capacity(2 * (siren.sine.len() + 1));
    let mut shapes = Vec::with_capacity(siren.sine.len() + 1);
    for layer in siren.sine.iter().chain(std::iter::once(&siren.output)) {
        let weight = layer.weight.val();
        let [d_in, d_out] = weight.dims();
        let bias = layer.bias.as_ref().expect("SIREN layers have a bias").val();
        flat.push(weight.reshape([d_in * d_out]));
        flat.push(bias);
        shapes.push([d_in, d_out]);
    }
    // On the autodiff graph, `cat`'s backward hands each parameter its slice of the
    // flat gradient.
    let params = Tensor::cat(flat, 0);
    Tensor::from_dispatch(Dispatch::siren(
        xt.into_dispatch(),
        params.into_dispatch(),
        shapes,
        siren.omega,
        dual,
    ))
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
        analytic_siren(siren, xt, false)
    }

    fn forward_dual(&self, siren: &Siren, xt: Tensor<2>) -> Dual {
        if !crate::backend::runs_on_cpu(&xt.device()) {
            // No stacking of values and tangents into one tensor that is split again.
            return layered_dual(siren, xt);
        }
        let n = xt.dims()[0];
        let out = analytic_siren(siren, xt, true);
        let d_out = out.dims()[1];
        Dual {
            value: out.clone().narrow(0, 0, n),
            tangent: Some(out.narrow(0, n, 3 * n).reshape([3, n, d_out])),
        }
    }
}
