//! The CPU backends' side of [`SirenOps`]: flex and ndarray lend their buffers to the one
//! implementation on slices ([`super::net`]), so each kernel is written once.
//! A tensor is read in place when it is contiguous, and copied once otherwise.

#![allow(deprecated)] // `NdArray` stays selectable although Burn deprecates it.

use std::borrow::Cow;
use std::sync::Arc;

use burn::backend::flex::FlexTensor;
use burn::backend::ndarray::NdArrayTensor;
use burn::backend::{TensorMetadata, tensor::FloatTensor};
use burn::tensor::{DType, TensorData};

use super::net::{Activations, Net};
use super::real::Real;
use crate::jacobian::analytic::{OpSpec, SirenBackend, SirenOps, reference};

/// A CPU tensor whose elements can be borrowed as a slice.
pub(crate) trait HostTensor: Clone + TensorMetadata {
    /// The elements, row-major, as `E` (borrowed when contiguous and of type `E`).
    fn host<E: Real>(&self) -> Cow<'_, [E]>;
    /// A tensor owning `v` (no copy).
    fn from_host<E: Real>(v: Vec<E>, shape: Vec<usize>) -> Self;
}

/// Copies the elements of `t` in row-major order, converted to `E`.
fn copied<E: Real>(t: TensorData) -> Vec<E> {
    t.convert::<E>()
        .into_vec::<E>()
        .expect("converted to the requested element type")
}

impl HostTensor for FlexTensor {
    fn host<E: Real>(&self) -> Cow<'_, [E]> {
        match self.as_slice::<E>() {
            Some(s) => Cow::Borrowed(s),
            None => Cow::Owned(copied(self.clone().into_data())),
        }
    }

    fn from_host<E: Real>(v: Vec<E>, shape: Vec<usize>) -> Self {
        FlexTensor::from_data(TensorData::new(v, shape))
    }
}

impl HostTensor for NdArrayTensor {
    fn host<E: Real>(&self) -> Cow<'_, [E]> {
        let borrowed: Option<&[E]> = match self {
            NdArrayTensor::F32(s) if E::dtype() == DType::F32 => {
                s.view().to_slice().map(bytemuck::cast_slice)
            }
            NdArrayTensor::F64(s) if E::dtype() == DType::F64 => {
                s.view().to_slice().map(bytemuck::cast_slice)
            }
            _ => None,
        };
        if let Some(s) = borrowed {
            return Cow::Borrowed(s);
        }
        // Strided or of another float type: one copy, in row-major order.
        let to_e = |v: f64| E::from_f64(v);
        Cow::Owned(match self {
            NdArrayTensor::F32(s) => s.view().iter().map(|v| to_e(*v as f64)).collect(),
            NdArrayTensor::F64(s) => s.view().iter().map(|v| to_e(*v)).collect(),
            other => panic!(
                "the SIREN op reads f32 or f64 tensors, not {:?}",
                other.dtype()
            ),
        })
    }

    fn from_host<E: Real>(v: Vec<E>, shape: Vec<usize>) -> Self {
        NdArrayTensor::from_data(TensorData::new(v, shape))
    }
}

/// What the CPU op keeps for its backward (opaque).
#[derive(Clone, Debug)]
pub struct CpuSaved<T>(Saved<T>);

#[derive(Clone, Debug)]
enum Saved<T> {
    /// f32 activations on raw buffers.
    F32(Arc<Activations<f32>>),
    /// f64 activations on raw buffers.
    F64(Arc<Activations<f64>>),
    /// Other float types go through the tensor-primitive implementation.
    Tensors(Vec<T>),
}

fn forward_typed<E: Real, T: HostTensor>(
    input: &T,
    params: &T,
    spec: &OpSpec,
) -> (T, Activations<E>) {
    let n = input.shape().dims::<2>()[0];
    let (x, flat) = (input.host::<E>(), params.host::<E>());
    let (out, acts) = Net::new(&flat, spec).forward(&x);
    (T::from_host(out, vec![spec.rows(n), spec.outputs()]), acts)
}

fn backward_typed<E: Real, T: HostTensor>(
    acts: &Activations<E>,
    input: &T,
    params: &T,
    spec: &OpSpec,
    grad: &T,
    input_grad: bool,
) -> (Option<T>, T) {
    let [n, c] = input.shape().dims::<2>();
    let (x, flat, g) = (input.host::<E>(), params.host::<E>(), grad.host::<E>());
    let mut g_params = vec![E::zero(); spec.param_count()];
    let g_x = Net::new(&flat, spec).backward(acts, &x, &g, input_grad, &mut g_params);
    let len = g_params.len();
    (
        g_x.map(|v| T::from_host(v, vec![n, c])),
        T::from_host(g_params, vec![len]),
    )
}

/// [`SirenOps::siren_forward`] for a CPU backend `B`.
fn siren_forward<B>(
    input: FloatTensor<B>,
    params: FloatTensor<B>,
    spec: &OpSpec,
) -> (FloatTensor<B>, CpuSaved<FloatTensor<B>>)
where
    B: SirenBackend,
    FloatTensor<B>: HostTensor,
{
    match input.dtype() {
        DType::F32 => {
            let (out, acts) = forward_typed::<f32, _>(&input, &params, spec);
            (out, CpuSaved(Saved::F32(Arc::new(acts))))
        }
        DType::F64 => {
            let (out, acts) = forward_typed::<f64, _>(&input, &params, spec);
            (out, CpuSaved(Saved::F64(Arc::new(acts))))
        }
        _ => {
            let (out, saved) = reference::siren::<B>(input, params, spec);
            (out, CpuSaved(Saved::Tensors(saved)))
        }
    }
}

/// [`SirenOps::siren_backward`] for a CPU backend `B`.
fn siren_backward<B>(
    saved: CpuSaved<FloatTensor<B>>,
    input: FloatTensor<B>,
    params: FloatTensor<B>,
    spec: &OpSpec,
    grad: FloatTensor<B>,
    input_grad: bool,
) -> (Option<FloatTensor<B>>, FloatTensor<B>)
where
    B: SirenBackend,
    FloatTensor<B>: HostTensor,
{
    match saved.0 {
        Saved::F32(acts) => {
            backward_typed::<f32, _>(&acts, &input, &params, spec, &grad, input_grad)
        }
        Saved::F64(acts) => {
            backward_typed::<f64, _>(&acts, &input, &params, spec, &grad, input_grad)
        }
        Saved::Tensors(saved) => {
            let (g_x, g) = reference::siren_backward::<B>(saved, params, spec, grad);
            (input_grad.then_some(g_x), g)
        }
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
                spec: OpSpec,
            ) -> FloatTensor<Self> {
                <Self as SirenOps>::siren_forward(input, params, &spec).0
            }
        }
    )*};
}

untracked_siren!(burn::backend::Flex, burn::backend::NdArray);

/// The CPU backends lend their buffers to [`super::net`].
macro_rules! cpu_siren_ops {
    ($($backend:ty),*) => {$(
        impl SirenOps for $backend {
            type Saved = CpuSaved<FloatTensor<Self>>;

            fn siren_forward(
                input: FloatTensor<Self>,
                params: FloatTensor<Self>,
                spec: &OpSpec,
            ) -> (FloatTensor<Self>, Self::Saved) {
                siren_forward::<Self>(input, params, spec)
            }

            fn siren_backward(
                saved: Self::Saved,
                input: FloatTensor<Self>,
                params: FloatTensor<Self>,
                spec: &OpSpec,
                grad: FloatTensor<Self>,
                input_grad: bool,
            ) -> (Option<FloatTensor<Self>>, FloatTensor<Self>) {
                siren_backward::<Self>(saved, input, params, spec, grad, input_grad)
            }
        }
    )*};
}

cpu_siren_ops!(burn::backend::Flex, burn::backend::NdArray);
