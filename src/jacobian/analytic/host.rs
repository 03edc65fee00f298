//! The CPU backends' side of [`super::SirenOps`]: flex and ndarray lend their buffers to
//! the one implementation on slices ([`super::net`]), so each kernel is written once.
//! A tensor is read in place when it is contiguous, and copied once otherwise.

#![allow(deprecated)] // `NdArray` stays selectable although Burn deprecates it.

use std::borrow::Cow;
use std::sync::Arc;

use burn::backend::flex::FlexTensor;
use burn::backend::ndarray::NdArrayTensor;
use burn::backend::{TensorMetadata, tensor::FloatTensor};
use burn::tensor::{DType, TensorData};

use super::cpu::Real;
use super::forward;
use super::net::{self, Activations};

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

/// The number of parameters of layers of these shapes.
pub(crate) fn param_count(shapes: &[[usize; 2]]) -> usize {
    shapes.iter().map(|[i, o]| i * o + o).sum()
}

fn forward_typed<E: Real, T: HostTensor>(
    input: &T,
    params: &T,
    shapes: &[[usize; 2]],
    omega: f64,
    dual: bool,
) -> (T, Activations<E>) {
    let n = input.shape().dims::<2>()[0];
    let (x, flat) = (input.host::<E>(), params.host::<E>());
    let layers = net::layers_of(&flat, shapes);
    let (out, acts) = net::forward(&x, n, &layers, omega, dual);
    let rows = if dual { 4 * n } else { n };
    let o = shapes.last().expect("an output layer")[1];
    (T::from_host(out, vec![rows, o]), acts)
}

#[allow(clippy::too_many_arguments)]
fn backward_typed<E: Real, T: HostTensor>(
    acts: &Activations<E>,
    input: &T,
    params: &T,
    shapes: &[[usize; 2]],
    grad: &T,
    omega: f64,
    dual: bool,
    input_grad: bool,
) -> (Option<T>, T) {
    let [n, c] = input.shape().dims::<2>();
    let (x, flat, g) = (input.host::<E>(), params.host::<E>(), grad.host::<E>());
    let layers = net::layers_of(&flat, shapes);
    let mut g_params = vec![E::zero(); param_count(shapes)];
    let g_x = net::backward(
        acts,
        &x,
        n,
        &layers,
        omega,
        dual,
        &g,
        input_grad,
        &mut g_params,
    );
    let len = g_params.len();
    (
        g_x.map(|v| T::from_host(v, vec![n, c])),
        T::from_host(g_params, vec![len]),
    )
}

/// [`super::SirenOps::siren_forward`] for a CPU backend `B`.
pub(crate) fn siren_forward<B>(
    input: FloatTensor<B>,
    params: FloatTensor<B>,
    shapes: &[[usize; 2]],
    omega: f64,
    dual: bool,
) -> (FloatTensor<B>, CpuSaved<FloatTensor<B>>)
where
    B: super::SirenBackend,
    FloatTensor<B>: HostTensor,
{
    match input.dtype() {
        DType::F32 => {
            let (out, acts) = forward_typed::<f32, _>(&input, &params, shapes, omega, dual);
            (out, CpuSaved(Saved::F32(Arc::new(acts))))
        }
        DType::F64 => {
            let (out, acts) = forward_typed::<f64, _>(&input, &params, shapes, omega, dual);
            (out, CpuSaved(Saved::F64(Arc::new(acts))))
        }
        _ => {
            let (out, saved) = forward::siren::<B>(input, params, shapes, omega, dual);
            (out, CpuSaved(Saved::Tensors(saved)))
        }
    }
}

/// [`super::SirenOps::siren_backward`] for a CPU backend `B`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn siren_backward<B>(
    saved: CpuSaved<FloatTensor<B>>,
    input: FloatTensor<B>,
    params: FloatTensor<B>,
    shapes: &[[usize; 2]],
    grad: FloatTensor<B>,
    omega: f64,
    dual: bool,
    input_grad: bool,
) -> (Option<FloatTensor<B>>, FloatTensor<B>)
where
    B: super::SirenBackend,
    FloatTensor<B>: HostTensor,
{
    match saved.0 {
        Saved::F32(acts) => backward_typed::<f32, _>(
            &acts, &input, &params, shapes, &grad, omega, dual, input_grad,
        ),
        Saved::F64(acts) => backward_typed::<f64, _>(
            &acts, &input, &params, shapes, &grad, omega, dual, input_grad,
        ),
        Saved::Tensors(saved) => {
            let (g_x, g) = forward::siren_backward::<B>(saved, params, shapes, grad, omega, dual);
            (input_grad.then_some(g_x), g)
        }
    }
}
