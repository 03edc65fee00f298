//! The analytic op from Burn's tensor primitives: the oracle. It holds the elementwise
//! passes of a sine layer (docs/design.md §2.2), which are the default bodies of
//! [`SirenBackend`]'s activations and what the CubeCL kernels are tested against, and the
//! whole network ([`siren`], [`siren_backward`]), which wgpu runs around its kernels and
//! the CPU backends fall back to for float types other than f32 and f64.

use burn::backend::{Backend, Scalar, Slice, tensor::FloatTensor};
use burn::tensor::Shape;

use burn::backend::TensorMetadata;

use super::{OpSpec, SirenBackend};

/// Rows `[from, to)` of a `[R, d]` primitive.
fn rows<B: Backend>(t: FloatTensor<B>, from: usize, to: usize, d: usize) -> FloatTensor<B> {
    B::float_slice(t, &[Slice::from(from..to), Slice::from(0..d)])
}

/// `(z, ż)` from `zs = S W` and the bias: `z = ω(zs[0..N] + b)` (`[N, d]`),
/// `ż = ω zs[N..4N]` (`[3, N, d]`).
pub(crate) fn pre_activation<B: Backend>(
    zs: FloatTensor<B>,
    bias: FloatTensor<B>,
    omega: f64,
) -> (FloatTensor<B>, FloatTensor<B>, usize, usize) {
    let [r, d] = zs.shape().dims::<2>();
    let n = r / 4;
    let bias = B::float_reshape(bias, Shape::new([1, d]));
    let z = B::float_mul_scalar(
        B::float_add(rows::<B>(zs.clone(), 0, n, d), bias),
        Scalar::from(omega),
    );
    let zdot = B::float_mul_scalar(rows::<B>(zs, n, r, d), Scalar::from(omega));
    (z, B::float_reshape(zdot, Shape::new([3, n, d])), n, d)
}

/// `[sin z; cos z ⊙ ż]`.
pub fn activation<B: Backend>(
    zs: FloatTensor<B>,
    bias: FloatTensor<B>,
    omega: f64,
) -> FloatTensor<B> {
    let (z, zdot, n, d) = pre_activation::<B>(zs, bias, omega);
    let cos = B::float_reshape(B::float_cos(z.clone()), Shape::new([1, n, d]));
    let hdot = B::float_reshape(B::float_mul(zdot, cos), Shape::new([3 * n, d]));
    B::float_cat(vec![B::float_sin(z), hdot], 0)
}

/// `ω [g_h ⊙ cos z − sin z ⊙ Σ_k g_ḣ,k ⊙ ż_k ; g_ḣ ⊙ cos z]`.
pub fn activation_backward<B: Backend>(
    zs: FloatTensor<B>,
    bias: FloatTensor<B>,
    grad: FloatTensor<B>,
    omega: f64,
) -> FloatTensor<B> {
    let (z, zdot, n, d) = pre_activation::<B>(zs, bias, omega);
    let g_h = rows::<B>(grad.clone(), 0, n, d);
    let g_hdot = B::float_reshape(rows::<B>(grad, n, 4 * n, d), Shape::new([3, n, d]));
    let (sin, cos) = (B::float_sin(z.clone()), B::float_cos(z));
    let mixed = B::float_reshape(
        B::float_sum_dim(B::float_mul(g_hdot.clone(), zdot), 0),
        Shape::new([n, d]),
    );
    let g_z = B::float_sub(B::float_mul(g_h, cos.clone()), B::float_mul(sin, mixed));
    let cos = B::float_reshape(cos, Shape::new([1, n, d]));
    let g_zdot = B::float_reshape(B::float_mul(g_hdot, cos), Shape::new([3 * n, d]));
    B::float_mul_scalar(B::float_cat(vec![g_z, g_zdot], 0), Scalar::from(omega))
}

/// What `S_0 W` is for the first layer, whose stacked input is `[X; e_x; e_y; e_z]` (the
/// seeds on the first three columns): `[z_v; W[0]; W[1]; W[2]]` (`[4N, d]`), each of
/// `W`'s first three rows repeated for the `N` points.
fn input_stacked<B: Backend>(zv: FloatTensor<B>, weight: FloatTensor<B>) -> FloatTensor<B> {
    let [n, d] = zv.shape().dims::<2>();
    let rows = B::float_slice(weight, &[Slice::from(0..3), Slice::from(0..d)]);
    let rows = B::float_repeat_dim(B::float_reshape(rows, Shape::new([3, 1, d])), 1, n);
    B::float_cat(vec![zv, B::float_reshape(rows, Shape::new([3 * n, d]))], 0)
}

/// The first layer's `[sin z; cos z ⊙ ż]` from `z_v = X W` (`[N, d]`): [`activation`] of
/// the stacked pre-activation that the seeds would give.
pub fn input_activation<B: Backend>(
    zv: FloatTensor<B>,
    weight: FloatTensor<B>,
    bias: FloatTensor<B>,
    omega: f64,
) -> FloatTensor<B> {
    activation::<B>(input_stacked::<B>(zv, weight), bias, omega)
}

/// Its backward: [`activation_backward`] of the same stacked pre-activation.
pub fn input_activation_backward<B: Backend>(
    zv: FloatTensor<B>,
    weight: FloatTensor<B>,
    bias: FloatTensor<B>,
    grad: FloatTensor<B>,
    omega: f64,
) -> FloatTensor<B> {
    activation_backward::<B>(input_stacked::<B>(zv, weight), bias, grad, omega)
}

/// The value-only sine layer's activation: `sin(ω(zs + b))` for `zs = X W` (`[N, d]`).
pub fn plain_activation<B: Backend>(
    zs: FloatTensor<B>,
    bias: FloatTensor<B>,
    omega: f64,
) -> FloatTensor<B> {
    B::float_sin(plain_pre_activation::<B>(zs, bias, omega))
}

/// Its backward: `ω g ⊙ cos(ω(zs + b))`.
pub fn plain_activation_backward<B: Backend>(
    zs: FloatTensor<B>,
    bias: FloatTensor<B>,
    grad: FloatTensor<B>,
    omega: f64,
) -> FloatTensor<B> {
    let cos = B::float_cos(plain_pre_activation::<B>(zs, bias, omega));
    B::float_mul_scalar(B::float_mul(grad, cos), Scalar::from(omega))
}

fn plain_pre_activation<B: Backend>(
    zs: FloatTensor<B>,
    bias: FloatTensor<B>,
    omega: f64,
) -> FloatTensor<B> {
    let d = zs.shape().dims::<2>()[1];
    let bias = B::float_reshape(bias, Shape::new([1, d]));
    B::float_mul_scalar(B::float_add(zs, bias), Scalar::from(omega))
}

/// The seeds `e_x, e_y, e_z` of an `[n, c]` input, stacked `[3n, c]`.
fn seeds<B: Backend>(
    n: usize,
    c: usize,
    device: &B::Device,
    dtype: burn::tensor::DType,
) -> FloatTensor<B> {
    let mut eye = vec![0.0f32; 3 * n * c];
    for k in 0..3 {
        for r in 0..n {
            eye[(k * n + r) * c + k] = 1.0;
        }
    }
    let data = burn::tensor::TensorData::new(eye, [3 * n, c]).convert_dtype(dtype);
    B::float_from_data(data, device)
}

/// `[W_0, b_0, …, W_o, b_o]` from the flat parameter tensor (see [`super::SirenOps`]).
fn unflatten<B: Backend>(params: FloatTensor<B>, shapes: &[[usize; 2]]) -> Vec<FloatTensor<B>> {
    let mut at = 0;
    let mut out = Vec::with_capacity(2 * shapes.len());
    for &[d_in, d_out] in shapes {
        let w = B::float_slice(params.clone(), &[Slice::from(at..at + d_in * d_out)]);
        out.push(B::float_reshape(w, Shape::new([d_in, d_out])));
        at += d_in * d_out;
        out.push(B::float_slice(
            params.clone(),
            &[Slice::from(at..at + d_out)],
        ));
        at += d_out;
    }
    out
}

/// The whole SIREN from tensor primitives: [`super::SirenOps::siren_forward`] on wgpu.
/// `params` is the flat parameter tensor of [`super::SirenOps`]; the output is `[n, O]`,
/// or `[4n, O]` stacked values and tangents when `spec.dual`. The saved tensors are
/// `[S_0, Z_0, S_1, Z_1, …, S_L]`: each sine layer's input and pre-activation, and the
/// output layer's input.
pub fn siren<B: SirenBackend>(
    input: FloatTensor<B>,
    params: FloatTensor<B>,
    spec: &OpSpec,
) -> (FloatTensor<B>, Vec<FloatTensor<B>>) {
    let (omega, dual) = (spec.omega, spec.dual);
    let params = unflatten::<B>(params, &spec.shapes);
    let params = &params[..];
    let [n, c] = input.shape().dims::<2>();
    let mut s = if dual {
        let seed = seeds::<B>(n, c, &input.device(), input.dtype());
        B::float_cat(vec![input, seed], 0)
    } else {
        input
    };
    let (sine, out) = params.split_last_chunk::<2>().expect("an output layer");
    let mut saved = Vec::with_capacity(sine.len() + 1);
    for layer in sine.chunks_exact(2) {
        let zs = B::float_matmul(s.clone(), layer[0].clone());
        let next = if dual {
            B::sine_dual_activation(zs.clone(), layer[1].clone(), omega)
        } else {
            B::sine_activation(zs.clone(), layer[1].clone(), omega)
        };
        saved.push(s);
        saved.push(zs);
        s = next;
    }
    saved.push(s.clone());
    let y = B::float_matmul(s, out[0].clone());
    let [r, o] = y.shape().dims::<2>();
    let bias = B::float_reshape(out[1].clone(), Shape::new([1, o]));
    let y = if dual {
        let value = B::float_add(rows::<B>(y.clone(), 0, n, o), bias);
        B::float_cat(vec![value, rows::<B>(y, n, r, o)], 0)
    } else {
        B::float_add(y, bias)
    };
    (y, saved)
}

/// The backward of [`siren`]: `(g_input, g_params)` from the output's gradient `grad`,
/// with `g_params` flat like `params`.
pub fn siren_backward<B: SirenBackend>(
    saved: Vec<FloatTensor<B>>,
    params: FloatTensor<B>,
    spec: &OpSpec,
    grad: FloatTensor<B>,
) -> (FloatTensor<B>, FloatTensor<B>) {
    let (omega, dual) = (spec.omega, spec.dual);
    let params = unflatten::<B>(params, &spec.shapes);
    let n = saved[0].shape().dims::<2>()[0] / if dual { 4 } else { 1 };
    let value_sum = |g: FloatTensor<B>| {
        let d = g.shape().dims::<2>()[1];
        B::float_reshape(B::float_sum_dim(rows::<B>(g, 0, n, d), 0), Shape::new([d]))
    };
    let mut saved = saved;
    let mut grads = vec![None; params.len()];
    let s_last = saved.pop().expect("the output layer's input");
    let out = params.len() - 2;
    grads[out + 1] = Some(value_sum(grad.clone()));
    grads[out] = Some(B::float_matmul(B::float_transpose(s_last), grad.clone()));
    let mut g_s = B::float_matmul(grad, B::float_transpose(params[out].clone()));
    for l in (0..out / 2).rev() {
        let zs = saved.pop().expect("a pre-activation");
        let s = saved.pop().expect("a layer input");
        let (w, b) = (params[2 * l].clone(), params[2 * l + 1].clone());
        let g_z = if dual {
            B::sine_dual_activation_backward(zs, b, g_s, omega)
        } else {
            B::sine_activation_backward(zs, b, g_s, omega)
        };
        grads[2 * l + 1] = Some(value_sum(g_z.clone()));
        grads[2 * l] = Some(B::float_matmul(B::float_transpose(s), g_z.clone()));
        g_s = B::float_matmul(g_z, B::float_transpose(w));
    }
    // The seeds' rows are constants: the input's gradient is the value rows'.
    let c = g_s.shape().dims::<2>()[1];
    let g_input = rows::<B>(g_s, 0, n, c);
    let flat = grads
        .into_iter()
        .map(|g| {
            let g = g.expect("every gradient");
            let len = g.shape().num_elements();
            B::float_reshape(g, Shape::new([len]))
        })
        .collect();
    (g_input, B::float_cat(flat, 0))
}
