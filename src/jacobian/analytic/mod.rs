//! `Analytic`: the hand-derived SIREN Jacobian (paper Eq. 6; docs/design.md §2.2) as
//! custom Burn operations with a hand-written backward.
//!
//! The network works on the *stacked* matrix `S = [h; ḣ_x; ḣ_y; ḣ_z]` (`[4N, d]`): the
//! values and their three spatial tangents. Per sine layer, one matmul `Z = S W` gives
//! both the pre-activation `z = ω(Z[0..N] + b)` and its tangents `ż = ω Z[N..4N]`, and the
//! layer returns `[sin z; cos z ⊙ ż]`. The output layer is one more matmul. The backward
//! is two matmuls and one elementwise pass per layer, with no autodiff graph inside.
//!
//! The op is a Burn backend extension ([`SirenBackend`]), shelved by backend:
//!
//! | path | used by | files |
//! |---|---|---|
//! | the whole SIREN as one op on raw buffers | flex, ndarray | `cpu/` (`real`, `gemm`, `rows`, `net`, `host`) |
//! | one op per sine layer, CubeCL kernels, Burn's matmuls | wgpu | `wgpu/` (`kernels.rs`: the `#[cube]` functions) |
//! | the op from Burn's tensor primitives: the oracle | tests; other float types | `reference.rs` |
//! | the backward nodes on Burn's `Autodiff` graph | every backend | `autodiff.rs` |
//!
//! [`analytic_siren`] picks the path for a device; [`Analytic`] is the
//! [`JacobianMethod`] on top.

#![allow(deprecated)] // `NdArray` stays selectable although Burn deprecates it.

mod autodiff;
pub(crate) mod cpu;
mod reference;
#[cfg(feature = "wgpu")]
mod wgpu;

#[cfg(feature = "wgpu")]
pub use wgpu::kernel_launches;

use burn::backend::{Dispatch, backend_extension, tensor::FloatTensor};
use burn::tensor::Tensor;

use super::{Dual, JacobianMethod};
use crate::siren::Siren;

/// What the whole-SIREN op is asked for: the layers' shapes, `ω`, and whether tangents
/// ride along.
#[derive(Clone, Debug, PartialEq)]
pub struct OpSpec {
    /// Each layer's `[d_in, d_out]`: the sine layers, then the output layer.
    pub shapes: Vec<[usize; 2]>,
    /// SIREN's `ω` (Eq. 1), shared by every sine layer.
    pub omega: f64,
    /// Whether the input's first three columns are seeded with `e_x, e_y, e_z` and the
    /// output stacks the values and the three tangents (Eq. 6).
    pub dual: bool,
}

impl OpSpec {
    /// The spec of `siren`'s layers.
    pub fn of(siren: &Siren, dual: bool) -> Self {
        let shapes = siren
            .sine
            .iter()
            .chain(std::iter::once(&siren.output))
            .map(|layer| layer.weight.dims())
            .collect();
        OpSpec {
            shapes,
            omega: siren.omega,
            dual,
        }
    }

    /// The number of parameters, weights and biases.
    pub fn param_count(&self) -> usize {
        self.shapes.iter().map(|[i, o]| i * o + o).sum()
    }

    /// The output's rows for `n` points: `4n` when dual, else `n`.
    pub fn rows(&self, n: usize) -> usize {
        if self.dual { 4 * n } else { n }
    }

    /// The output's columns (the output layer's width).
    pub fn outputs(&self) -> usize {
        self.shapes.last().map_or(0, |s| s[1])
    }
}

/// The six elementwise passes of a sine layer: what a CubeCL kernel implements, what
/// [`activation`] runs, and (for a forward pass) what kind of layer an autodiff node holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SineKernel {
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

impl SineKernel {
    /// The backward pass of a forward pass (a backward pass is its own).
    pub fn backward(self) -> Self {
        match self {
            SineKernel::DualForward => SineKernel::DualBackward,
            SineKernel::Forward => SineKernel::Backward,
            SineKernel::DualInputForward => SineKernel::DualInputBackward,
            other => other,
        }
    }
}

/// One backend's implementation of the whole-SIREN operation: the forward, which keeps
/// what the backward needs, and the hand-written backward (docs/design.md §2.2).
///
/// `params` is one flat tensor, `[W_0, b_0, W_1, b_1, …, W_o, b_o]`: the sine layers'
/// weights (`[d_in, d_out]`, row-major) and biases (`[d_out]`), then the output layer's,
/// of the shapes in [`OpSpec::shapes`]. (Burn 0.22's backend extensions take no `Vec` of
/// tensors, and an autodiff node has a fixed number of parents: one flat tensor serves any
/// depth, for the price of one copy of the ~50k parameters per call.) The input is
/// `[N, c]`; when [`OpSpec::dual`], its first three columns are seeded with
/// `e_x, e_y, e_z` and the output stacks the values and the three tangents, `[4N, O]`;
/// otherwise it is `[N, O]`.
pub trait SirenOps: burn::backend::Backend {
    /// The activations the backward reads.
    type Saved: Clone + Send + std::fmt::Debug + 'static;

    /// The SIREN's output (Eq. 1), with its spatial tangents when dual (Eq. 6).
    fn siren_forward(
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        spec: &OpSpec,
    ) -> (FloatTensor<Self>, Self::Saved);

    /// From the output's gradient `grad`: the input's gradient (when `input_grad`) and
    /// the parameters' (flat, laid out like `params`).
    fn siren_backward(
        saved: Self::Saved,
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        spec: &OpSpec,
        grad: FloatTensor<Self>,
        input_grad: bool,
    ) -> (Option<FloatTensor<Self>>, FloatTensor<Self>);
}

/// The analytic SIREN as a backend operation, reachable from high-level tensors through
/// Burn's `Dispatch` ([`fused_siren`]), and the elementwise part of its sine layers, which
/// the tensor-primitive network calls. The activations' default bodies compose Burn
/// primitives and are the reference; wgpu overrides them with CubeCL kernels.
#[cfg_attr(feature = "wgpu", backend_extension(Flex, NdArray, Cube, Autodiff))]
#[cfg_attr(not(feature = "wgpu"), backend_extension(Flex, NdArray, Autodiff))]
pub trait SirenBackend: burn::backend::Backend {
    /// The whole SIREN (see [`SirenOps`] for the layout of `params` and the output).
    fn siren(
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        spec: OpSpec,
    ) -> FloatTensor<Self>;

    /// A dual sine layer's activation (Eq. 6): from `zs = S W` (`[4N, d]`, values then the
    /// three tangents) and the bias, `[sin z; cos z ⊙ ż]` with `z = ω(zs[0..N] + b)` and
    /// `ż = ω zs[N..4N]`.
    fn sine_dual_activation(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        reference::activation::<Self>(zs, bias, omega)
    }

    /// Its backward: from the upstream gradient `G = [g_h; g_ḣ]`, the gradient with respect
    /// to `zs`, `ω [g_h ⊙ cos z − sin z ⊙ Σ_k g_ḣ,k ⊙ ż_k ; g_ḣ ⊙ cos z]`.
    fn sine_dual_activation_backward(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        reference::activation_backward::<Self>(zs, bias, grad, omega)
    }

    /// A value-only sine layer's activation (Eq. 1): `sin(ω(zs + b))`.
    fn sine_activation(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        reference::plain_activation::<Self>(zs, bias, omega)
    }

    /// Its backward: `ω g ⊙ cos(ω(zs + b))`.
    fn sine_activation_backward(
        zs: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        omega: f64,
    ) -> FloatTensor<Self> {
        reference::plain_activation_backward::<Self>(zs, bias, grad, omega)
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
        reference::input_activation::<Self>(zv, weight, bias, omega)
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
        reference::input_activation_backward::<Self>(zv, weight, bias, grad, omega)
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

    /// One value-only sine layer (Eq. 1): `sin(ω(X W + b))`. Not on a production path
    /// (the value path uses Burn's layers on wgpu and the whole-network op on the CPU);
    /// kept for the per-layer op's completeness and tested.
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

/// Runs the pass `kernel` on primitives of backend `B`: `grad` is read by the backward
/// passes only, `weight` (the layer's `W`) by the first layer's only.
pub(crate) fn sine_pass<B: SirenBackend>(
    kernel: SineKernel,
    zs: FloatTensor<B>,
    bias: FloatTensor<B>,
    grad: Option<FloatTensor<B>>,
    weight: Option<FloatTensor<B>>,
    omega: f64,
) -> FloatTensor<B> {
    let grad = || grad.expect("a backward pass takes the upstream gradient");
    let weight = || weight.expect("the first layer's pass takes W");
    match kernel {
        SineKernel::DualForward => B::sine_dual_activation(zs, bias, omega),
        SineKernel::DualBackward => B::sine_dual_activation_backward(zs, bias, grad(), omega),
        SineKernel::Forward => B::sine_activation(zs, bias, omega),
        SineKernel::Backward => B::sine_activation_backward(zs, bias, grad(), omega),
        SineKernel::DualInputForward => B::sine_dual_input_activation(zs, weight(), bias, omega),
        SineKernel::DualInputBackward => {
            B::sine_dual_input_activation_backward(zs, weight(), bias, grad(), omega)
        }
    }
}

/// One sine layer's elementwise pass on high-level tensors, on whatever backend `zs` lives
/// (the CubeCL kernels on wgpu, the primitive reference on the CPU backends); `grad` is
/// used by the backward passes only, `weight` (the layer's `W`) by the input layer's only.
pub fn activation(
    which: SineKernel,
    zs: Tensor<2>,
    bias: Tensor<1>,
    grad: Tensor<2>,
    weight: Tensor<2>,
    omega: f64,
) -> Tensor<2> {
    Tensor::from_dispatch(sine_pass::<Dispatch>(
        which,
        zs.into_dispatch(),
        bias.into_dispatch(),
        Some(grad.into_dispatch()),
        Some(weight.into_dispatch()),
        omega,
    ))
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
/// kernels).
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
    let spec = OpSpec {
        shapes,
        omega: siren.omega,
        dual,
    };
    Tensor::from_dispatch(Dispatch::siren(
        xt.into_dispatch(),
        params.into_dispatch(),
        spec,
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
