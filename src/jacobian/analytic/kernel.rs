//! The wgpu implementation of [`super::SirenOps`].
//!
//! Burn 0.22 runs wgpu as `Fusion<CubeBackend>`: the primitive ops of [`super::forward`]
//! are recorded lazily and their elementwise chains (the slices, `sin`, `cos`, the tangent
//! products and the backward's `g_z`, `g_ż`) are compiled into fused CubeCL kernels by
//! Burn's fusion engine, around the one matmul per layer and direction.

use burn::backend::tensor::FloatTensor;
use burn::backend::wgpu::CubeBackend;
use burn_fusion::Fusion;

use super::{SirenOps, forward};

macro_rules! primitive_siren_ops {
    ($($backend:ty),*) => {$(
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
    )*};
}

primitive_siren_ops!(CubeBackend, Fusion<CubeBackend>);
