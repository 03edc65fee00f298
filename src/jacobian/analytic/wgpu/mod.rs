//! The analytic op on wgpu: the CubeCL kernels of [`kernels`] launched, registered in
//! Burn's fusion stream, and plugged into [`SirenBackend`] and [`SirenOps`] for the CubeCL
//! backend. The matmuls stay Burn's (CubeCL's tuned matmul), and the network around the
//! kernels is [`reference::siren`] (through [`crate::jacobian::analytic::layered_siren`] in
//! production: one autodiff node per layer).
//!
//! **Where they run.** Burn 0.22 runs wgpu as `Fusion<CubeBackend>`. The kernels are
//! written for `CubeBackend`; for `Fusion<CubeBackend>` each call is registered in the
//! fusion stream as one custom operation (`OperationIr::Custom`, Burn's own mechanism for
//! opaque ops, the way `burn-linalg` registers its SVD), which the stream executes lazily
//! in order, with the inputs it resolves from its handle container. So a kernel call costs
//! no host sync and no stream drain. The backend extension macro can generate this wrapper
//! too, but only with Burn's `fusion` feature, which would rebuild the Burn stack; the
//! hand-written wrapper is 40 lines.
//!
//! The value-only kernels ([`SineKernel::Forward`], [`SineKernel::Backward`]) have no
//! production caller: without tangents, wgpu runs Burn's own layers, whose fusion folds
//! the bias and the sine into the matmul (docs/speed.md). They are kept, tested against
//! the reference, for the whole-network op on wgpu and for a GPU where they may pay.
//!
//! The reference is the tensor-primitive composition in [`reference`] (the trait's
//! default bodies); the kernel test (`tests/numerics/analytic_kernels.rs`) checks each
//! kernel against it on random inputs.

mod kernels;

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

use super::{OpSpec, SineKernel, SirenBackend, SirenOps, reference};
use kernels::*;

static LAUNCHES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// How many sine kernels this process has launched, so that a test can tell the kernels
/// from the reference path (both give the same numbers).
pub fn kernel_launches() -> usize {
    LAUNCHES.load(std::sync::atomic::Ordering::Relaxed)
}

/// The kernel's wgpu side: its fusion id, output shape and launch.
trait Launch {
    fn id(self) -> &'static str;
    fn out_shape(self, rows: usize, d: usize) -> Shape;
    fn threads(self, rows: usize, d: usize) -> (usize, usize);
    fn launch(self, inputs: Vec<CubeTensor>, omega: f64) -> CubeTensor;
}

impl Launch for SineKernel {
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

    /// The vector width along a row and the threads, one per vector of the value block,
    /// for inputs `[rows, d]`: vectors of 4 when rows split into them (d = 128 in doma's
    /// SIRENs).
    fn threads(self, rows: usize, d: usize) -> (usize, usize) {
        let vector: usize = if d.is_multiple_of(4) { 4 } else { 1 };
        let threads = match self {
            SineKernel::DualForward | SineKernel::DualBackward => rows / 4 * d,
            _ => rows * d,
        } / vector;
        (vector, threads)
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
        let (vector, threads) = self.threads(rows, d);
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
/// [`reference`], its activations from the kernels; `$call` runs one kernel.
macro_rules! kernel_backend {
    ($backend:ty, $call:expr) => {
        impl SirenBackend for $backend {
            fn siren(
                input: FloatTensor<Self>,
                params: FloatTensor<Self>,
                spec: OpSpec,
            ) -> FloatTensor<Self> {
                <Self as SirenOps>::siren_forward(input, params, &spec).0
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
                spec: &OpSpec,
            ) -> (FloatTensor<Self>, Self::Saved) {
                reference::siren::<Self>(input, params, spec)
            }

            fn siren_backward(
                saved: Self::Saved,
                _input: FloatTensor<Self>,
                params: FloatTensor<Self>,
                spec: &OpSpec,
                grad: FloatTensor<Self>,
                input_grad: bool,
            ) -> (Option<FloatTensor<Self>>, FloatTensor<Self>) {
                let (g_input, grads) = reference::siren_backward::<Self>(saved, params, spec, grad);
                (input_grad.then_some(g_input), grads)
            }
        }
    };
}

kernel_backend!(CubeBackend, |k: SineKernel, inputs, omega| k
    .launch(inputs, omega));
kernel_backend!(Fusion<CubeBackend>, fused_call);
