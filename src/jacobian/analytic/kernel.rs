//! The wgpu implementation of the analytic op: hand-written CubeCL kernels for the
//! elementwise part of every sine layer, forward and backward, dual and value-only.
//!
//! Each kernel does one layer's elementwise work in one pass over `[N, d]` (dual: four
//! blocks), one thread per value-row element: `sin z`, and `ω cos z · Z_k` for the three
//! tangents, in one pass; the backward `g_z = ω (g_h cos z − ω sin z Σ_k g_ḣ,k Z_k)` and
//! `g_Ż_k = ω cos z g_ḣ,k`; and their value-only forms. The first layer's pair reads the
//! tangent pre-activations `Z_k` from `W`'s rows (its input's tangents are the seeds
//! `e_x, e_y, e_z`), so that layer's matmul has `N` rows, not `4N`. The matmuls stay Burn's (CubeCL's
//! tuned matmul), and the network around them is [`super::forward::siren`].
//!
//! **Where they run.** Burn 0.22 runs wgpu as `Fusion<CubeBackend>`. The kernels are
//! written for `CubeBackend`; for `Fusion<CubeBackend>` each call is registered in the
//! fusion stream as one custom operation (`OperationIr::Custom`, Burn's own mechanism for
//! opaque ops, the way `burn-linalg` registers its SVD), which the stream executes lazily
//! in order, with the inputs it resolves from its handle container. So a kernel call costs
//! no host sync and no stream drain. The backend extension macro can generate this wrapper
//! too, but only with Burn's `fusion` feature, which would rebuild the Burn stack here;
//! the hand-written wrapper is 40 lines.
//!
//! The reference is the tensor-primitive composition in [`super::forward`] (the trait's
//! default bodies); `tests/analytic_kernels.rs` checks each kernel against it on random
//! inputs.

use burn::backend::TensorMetadata;
use burn::backend::cubecl::dtype_to_storage_type;
use burn::backend::tensor::FloatTensor;
use burn::backend::wgpu::CubeBackend;
use burn::tensor::Shape;
use burn_cubecl::fusion::FusionCubeRuntime;
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::ops::numeric::empty_device_contiguous_dtype;
use burn_cubecl::tensor::CubeTensor;
use burn_fusion::custom::{CustomOpIr, HandleContainer, OperationIr, ScalarIr, StreamId, TensorIr};
use burn_fusion::stream::Operation;
use burn_fusion::{ExecutionError, Fusion, FusionRuntime, FusionTensor};
use cubecl::{calculate_cube_count_elemwise, prelude::*};

use super::{SirenBackend, SirenOps, forward};

/// One dual sine layer: `out = [sin z; ω cos z ⊙ Z_1; ω cos z ⊙ Z_2; ω cos z ⊙ Z_3]` with
/// `z = ω(Z_0 + b)`, for the stacked `zs = [Z_0; Z_1; Z_2; Z_3]` (`[4N, d]`).
///
/// Every kernel here reads and writes vectors of `N` elements along a row (`N = 4` when
/// `d` is a multiple of 4, as the value and tangent blocks and `W`'s rows then are); the
/// indices below count vectors.
#[cube(launch)]
fn sine_dual_forward_kernel<F: Float, N: Size>(
    zs: &Tensor<Vector<F, N>>,
    bias: &Tensor<Vector<F, N>>,
    out: &mut Tensor<Vector<F, N>>,
    omega: f32,
    #[define(F)] _dtype: ElemType,
) {
    let v = out.vector_size();
    let nd = out.shape(0) / 4 * out.shape(1) / v;
    let i = ABSOLUTE_POS;
    if i >= nd {
        terminate!();
    }
    let w = Vector::<F, N>::new(F::cast_from(omega));
    let z = w * (zs[i] + bias[i % (bias.shape(0) / v)]);
    write_dual(out, i, nd, z, w, zs[i + nd], zs[i + 2 * nd], zs[i + 3 * nd]);
}

/// Its backward, from the upstream gradient `g = [g_h; g_ḣ_1; g_ḣ_2; g_ḣ_3]`:
/// `[ω (g_h cos z − ω sin z Σ_k g_ḣ_k Z_k); ω cos z ⊙ g_ḣ_k]`.
#[cube(launch)]
fn sine_dual_backward_kernel<F: Float, N: Size>(
    zs: &Tensor<Vector<F, N>>,
    bias: &Tensor<Vector<F, N>>,
    g: &Tensor<Vector<F, N>>,
    out: &mut Tensor<Vector<F, N>>,
    omega: f32,
    #[define(F)] _dtype: ElemType,
) {
    let v = out.vector_size();
    let nd = out.shape(0) / 4 * out.shape(1) / v;
    let i = ABSOLUTE_POS;
    if i >= nd {
        terminate!();
    }
    let w = Vector::<F, N>::new(F::cast_from(omega));
    let z = w * (zs[i] + bias[i % (bias.shape(0) / v)]);
    write_dual_backward(
        out,
        g,
        i,
        nd,
        z,
        w,
        zs[i + nd],
        zs[i + 2 * nd],
        zs[i + 3 * nd],
    );
}

/// The first dual sine layer, whose tangent pre-activations are `W`'s rows (the input's
/// seeds are `e_x, e_y, e_z`): `out = [sin z; ω cos z ⊙ W[0]; ω cos z ⊙ W[1]; ω cos z ⊙ W[2]]`
/// with `z = ω(z_v + b)`, for `z_v = X W` (`[N, d]`); `out` is `[4N, d]`.
#[cube(launch)]
fn sine_dual_input_forward_kernel<F: Float, N: Size>(
    zv: &Tensor<Vector<F, N>>,
    bias: &Tensor<Vector<F, N>>,
    weight: &Tensor<Vector<F, N>>,
    out: &mut Tensor<Vector<F, N>>,
    omega: f32,
    #[define(F)] _dtype: ElemType,
) {
    let v = out.vector_size();
    let d = bias.shape(0) / v;
    let nd = zv.shape(0) * zv.shape(1) / v;
    let i = ABSOLUTE_POS;
    if i >= nd {
        terminate!();
    }
    let j = i % d;
    let w = Vector::<F, N>::new(F::cast_from(omega));
    let z = w * (zv[i] + bias[j]);
    write_dual(
        out,
        i,
        nd,
        z,
        w,
        weight[j],
        weight[d + j],
        weight[2 * d + j],
    );
}

/// Its backward, from `g = [g_h; g_ḣ_1; g_ḣ_2; g_ḣ_3]` (`[4N, d]`):
/// `[ω (g_h cos z − ω sin z Σ_k g_ḣ_k W[k]); ω cos z ⊙ g_ḣ_k]`.
#[cube(launch)]
fn sine_dual_input_backward_kernel<F: Float, N: Size>(
    zv: &Tensor<Vector<F, N>>,
    bias: &Tensor<Vector<F, N>>,
    g: &Tensor<Vector<F, N>>,
    weight: &Tensor<Vector<F, N>>,
    out: &mut Tensor<Vector<F, N>>,
    omega: f32,
    #[define(F)] _dtype: ElemType,
) {
    let v = out.vector_size();
    let d = bias.shape(0) / v;
    let nd = zv.shape(0) * zv.shape(1) / v;
    let i = ABSOLUTE_POS;
    if i >= nd {
        terminate!();
    }
    let j = i % d;
    let w = Vector::<F, N>::new(F::cast_from(omega));
    let z = w * (zv[i] + bias[j]);
    write_dual_backward(
        out,
        g,
        i,
        nd,
        z,
        w,
        weight[j],
        weight[d + j],
        weight[2 * d + j],
    );
}

/// A dual layer's output at vector `i` of the value block (`nd` vectors a block): `sin z`,
/// and `ω cos z ⊙ Z_k` for the tangent pre-activations `Z_1, Z_2, Z_3` (`ż_k = ω Z_k`).
#[cube]
#[allow(clippy::too_many_arguments)]
fn write_dual<F: Float, N: Size>(
    out: &mut Tensor<Vector<F, N>>,
    i: usize,
    nd: usize,
    z: Vector<F, N>,
    w: Vector<F, N>,
    z1: Vector<F, N>,
    z2: Vector<F, N>,
    z3: Vector<F, N>,
) {
    let wc = w * Vector::cos(z);
    out[i] = Vector::sin(z);
    out[i + nd] = wc * z1;
    out[i + 2 * nd] = wc * z2;
    out[i + 3 * nd] = wc * z3;
}

/// Its backward at vector `i`, from the upstream gradient `g`:
/// `ω (g_h cos z − ω sin z Σ_k g_ḣ_k Z_k)` for the value and `ω cos z ⊙ g_ḣ_k` for each
/// tangent.
#[cube]
#[allow(clippy::too_many_arguments)]
fn write_dual_backward<F: Float, N: Size>(
    out: &mut Tensor<Vector<F, N>>,
    g: &Tensor<Vector<F, N>>,
    i: usize,
    nd: usize,
    z: Vector<F, N>,
    w: Vector<F, N>,
    z1: Vector<F, N>,
    z2: Vector<F, N>,
    z3: Vector<F, N>,
) {
    let c = Vector::cos(z);
    let wc = w * c;
    let mixed = g[i + nd] * z1 + g[i + 2 * nd] * z2 + g[i + 3 * nd] * z3;
    out[i] = w * (g[i] * c - Vector::sin(z) * w * mixed);
    out[i + nd] = wc * g[i + nd];
    out[i + 2 * nd] = wc * g[i + 2 * nd];
    out[i + 3 * nd] = wc * g[i + 3 * nd];
}

/// A value-only sine layer: `sin(ω(Z + b))`.
#[cube(launch)]
fn sine_forward_kernel<F: Float, N: Size>(
    zs: &Tensor<Vector<F, N>>,
    bias: &Tensor<Vector<F, N>>,
    out: &mut Tensor<Vector<F, N>>,
    omega: f32,
    #[define(F)] _dtype: ElemType,
) {
    let v = out.vector_size();
    let d = bias.shape(0) / v;
    let i = ABSOLUTE_POS;
    if i >= out.shape(0) * out.shape(1) / v {
        terminate!();
    }
    let w = Vector::<F, N>::new(F::cast_from(omega));
    out[i] = Vector::sin(w * (zs[i] + bias[i % d]));
}

/// Its backward: `ω g cos(ω(Z + b))`.
#[cube(launch)]
fn sine_backward_kernel<F: Float, N: Size>(
    zs: &Tensor<Vector<F, N>>,
    bias: &Tensor<Vector<F, N>>,
    g: &Tensor<Vector<F, N>>,
    out: &mut Tensor<Vector<F, N>>,
    omega: f32,
    #[define(F)] _dtype: ElemType,
) {
    let v = out.vector_size();
    let d = bias.shape(0) / v;
    let i = ABSOLUTE_POS;
    if i >= out.shape(0) * out.shape(1) / v {
        terminate!();
    }
    let w = Vector::<F, N>::new(F::cast_from(omega));
    out[i] = w * g[i] * Vector::cos(w * (zs[i] + bias[i % d]));
}

static LAUNCHES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// How many sine kernels this process has launched, so that a test can tell the kernels
/// from the reference path (both give the same numbers).
pub fn launches() -> usize {
    LAUNCHES.load(std::sync::atomic::Ordering::Relaxed)
}

/// The six kernels, as one value the fusion wrapper can carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SineKernel {
    DualForward,
    DualBackward,
    Forward,
    Backward,
    DualInputForward,
    DualInputBackward,
}

impl SineKernel {
    fn id(self) -> &'static str {
        match self {
            SineKernel::DualForward => "doma::sine_dual_forward",
            SineKernel::DualBackward => "doma::sine_dual_backward",
            SineKernel::Forward => "doma::sine_forward",
            SineKernel::Backward => "doma::sine_backward",
            SineKernel::DualInputForward => "doma::sine_dual_input_forward",
            SineKernel::DualInputBackward => "doma::sine_dual_input_backward",
        }
    }

    /// The output's shape for inputs whose first, `zs` (or `z_v`), is `[rows, d]`: four
    /// times the rows for the input layer's forward, else `[rows, d]`.
    fn out_shape(self, rows: usize, d: usize) -> Shape {
        match self {
            SineKernel::DualInputForward | SineKernel::DualInputBackward => {
                Shape::new([4 * rows, d])
            }
            _ => Shape::new([rows, d]),
        }
    }

    /// Launches the kernel on `inputs`: `zs` (`z_v` for the input layer's), `bias`, then
    /// `g` for a backward, then `W` for the input layer's.
    fn launch(self, inputs: Vec<CubeTensor>, omega: f64) -> CubeTensor {
        let mut inputs = inputs.into_iter().map(into_contiguous);
        let zs = inputs.next().expect("zs");
        let bias = inputs.next().expect("the bias");
        let (g, weight) = match self {
            SineKernel::DualForward | SineKernel::Forward => (None, None),
            SineKernel::DualBackward | SineKernel::Backward => (inputs.next(), None),
            SineKernel::DualInputForward => (None, inputs.next()),
            SineKernel::DualInputBackward => (inputs.next(), inputs.next()),
        };
        let [rows, d] = zs.shape().dims::<2>();
        let (client, dtype) = (zs.client.clone(), zs.dtype);
        let out = empty_device_contiguous_dtype(
            client.clone(),
            zs.device.clone(),
            self.out_shape(rows, d),
            dtype,
        );
        // Vectors of 4 along a row when rows split into them (d = 128 in doma's SIRENs).
        let vector: usize = if d % 4 == 0 { 4 } else { 1 };
        // One thread per vector of the value block.
        let threads = match self {
            SineKernel::DualForward | SineKernel::DualBackward => rows / 4 * d,
            _ => rows * d,
        } / vector;
        if threads == 0 {
            return out;
        }
        LAUNCHES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let cube_dim = CubeDim::new(&client, threads);
        let cube_count = calculate_cube_count_elemwise(&client, threads, cube_dim);
        let (elem, w) = (dtype_to_storage_type(dtype), omega as f32);
        let (zs, bias, o) = (
            zs.into_tensor_arg(),
            bias.into_tensor_arg(),
            out.clone().into_tensor_arg(),
        );
        let g = || g.expect("a backward kernel takes g").into_tensor_arg();
        let weight = || {
            weight
                .expect("an input-layer kernel takes W")
                .into_tensor_arg()
        };
        match self {
            SineKernel::DualForward => sine_dual_forward_kernel::launch(
                &client, cube_count, cube_dim, vector, zs, bias, o, w, elem,
            ),
            SineKernel::DualBackward => sine_dual_backward_kernel::launch(
                &client,
                cube_count,
                cube_dim,
                vector,
                zs,
                bias,
                g(),
                o,
                w,
                elem,
            ),
            SineKernel::Forward => sine_forward_kernel::launch(
                &client, cube_count, cube_dim, vector, zs, bias, o, w, elem,
            ),
            SineKernel::Backward => sine_backward_kernel::launch(
                &client,
                cube_count,
                cube_dim,
                vector,
                zs,
                bias,
                g(),
                o,
                w,
                elem,
            ),
            SineKernel::DualInputForward => sine_dual_input_forward_kernel::launch(
                &client,
                cube_count,
                cube_dim,
                vector,
                zs,
                bias,
                weight(),
                o,
                w,
                elem,
            ),
            SineKernel::DualInputBackward => sine_dual_input_backward_kernel::launch(
                &client,
                cube_count,
                cube_dim,
                vector,
                zs,
                bias,
                g(),
                weight(),
                o,
                w,
                elem,
            ),
        }
        out
    }
}

/// A kernel call queued in the fusion stream: executed in order with the other
/// operations, on the inputs that the stream resolves.
#[derive(Debug)]
struct SineKernelOp {
    desc: CustomOpIr,
    kernel: SineKernel,
    omega: f64,
}

impl Operation<FusionCubeRuntime> for SineKernelOp {
    fn execute(
        &self,
        handles: &mut HandleContainer<<FusionCubeRuntime as FusionRuntime>::FusionHandle>,
    ) -> Result<(), ExecutionError> {
        let inputs = self
            .desc
            .inputs
            .iter()
            .map(|t| handles.get_float_tensor::<CubeBackend>(t))
            .collect();
        let out = self.kernel.launch(inputs, self.omega);
        handles.register_float_tensor::<CubeBackend>(&self.desc.outputs[0].id, out);
        Ok(())
    }
}

/// Registers `kernel` on fusion tensors; the output (of [`SineKernel::out_shape`] and
/// `inputs[0]`'s type) is lazy, like any fusion tensor.
fn fused_call(
    kernel: SineKernel,
    inputs: Vec<FusionTensor<FusionCubeRuntime>>,
    omega: f64,
) -> FusionTensor<FusionCubeRuntime> {
    let client = inputs[0].client.clone();
    let [rows, d] = inputs[0].shape.dims::<2>();
    let out = TensorIr::uninit(
        client.create_empty_handle(),
        kernel.out_shape(rows, d),
        inputs[0].dtype,
    );
    let inputs: Vec<TensorIr> = inputs.into_iter().map(|t| t.into_ir()).collect();
    let desc = CustomOpIr::with_scalars(
        kernel.id(),
        &inputs,
        std::slice::from_ref(&out),
        vec![ScalarIr::Float(omega)],
    );
    let op = SineKernelOp {
        desc: desc.clone(),
        kernel,
        omega,
    };
    client
        .register(StreamId::current(), OperationIr::Custom(desc), op)
        .into_iter()
        .next()
        .expect("one output")
}

/// [`SirenBackend`] and [`SirenOps`] for a CubeCL backend: the network from
/// [`super::forward`], its activations from the kernels; `$call` runs one kernel.
macro_rules! kernel_backend {
    ($backend:ty, $call:expr) => {
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

            fn sine_dual_activation(
                zs: FloatTensor<Self>,
                bias: FloatTensor<Self>,
                omega: f64,
            ) -> FloatTensor<Self> {
                $call(SineKernel::DualForward, vec![zs, bias], omega)
            }

            fn sine_dual_activation_backward(
                zs: FloatTensor<Self>,
                bias: FloatTensor<Self>,
                grad: FloatTensor<Self>,
                omega: f64,
            ) -> FloatTensor<Self> {
                $call(SineKernel::DualBackward, vec![zs, bias, grad], omega)
            }

            fn sine_activation(
                zs: FloatTensor<Self>,
                bias: FloatTensor<Self>,
                omega: f64,
            ) -> FloatTensor<Self> {
                $call(SineKernel::Forward, vec![zs, bias], omega)
            }

            fn sine_dual_input_activation(
                zv: FloatTensor<Self>,
                weight: FloatTensor<Self>,
                bias: FloatTensor<Self>,
                omega: f64,
            ) -> FloatTensor<Self> {
                $call(SineKernel::DualInputForward, vec![zv, bias, weight], omega)
            }

            fn sine_dual_input_activation_backward(
                zv: FloatTensor<Self>,
                weight: FloatTensor<Self>,
                bias: FloatTensor<Self>,
                grad: FloatTensor<Self>,
                omega: f64,
            ) -> FloatTensor<Self> {
                $call(
                    SineKernel::DualInputBackward,
                    vec![zv, bias, grad, weight],
                    omega,
                )
            }

            fn sine_activation_backward(
                zs: FloatTensor<Self>,
                bias: FloatTensor<Self>,
                grad: FloatTensor<Self>,
                omega: f64,
            ) -> FloatTensor<Self> {
                $call(SineKernel::Backward, vec![zs, bias, grad], omega)
            }
        }

        impl SirenOps for $backend {
            type Saved = Vec<FloatTensor<Self>>;

            fn siren_forward(
                input: FloatTensor<Self>,
                params: FloatTensor<Self>,
                shapes: &[[usize; 2]],
                omega: f64,
                dual: bool,
            ) -> (FloatTensor<Self>, Self::Saved) {
                forward::siren::<Self>(input, params, shapes, omega, dual)
            }

            #[allow(clippy::too_many_arguments)]
            fn siren_backward(
                saved: Self::Saved,
                _input: FloatTensor<Self>,
                params: FloatTensor<Self>,
                shapes: &[[usize; 2]],
                grad: FloatTensor<Self>,
                omega: f64,
                dual: bool,
                input_grad: bool,
            ) -> (Option<FloatTensor<Self>>, FloatTensor<Self>) {
                let (g_input, grads) =
                    forward::siren_backward::<Self>(saved, params, shapes, grad, omega, dual);
                (input_grad.then_some(g_input), grads)
            }
        }
    };
}

kernel_backend!(CubeBackend, |k: SineKernel, inputs, omega| k
    .launch(inputs, omega));
kernel_backend!(Fusion<CubeBackend>, fused_call);
