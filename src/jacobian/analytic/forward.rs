//! The elementwise parts of the analytic sine layer, from backend tensor primitives.
//! These are the default bodies of [`super::SirenBackend`], used by the CPU backends.

use burn::backend::{Backend, Scalar, Slice, tensor::FloatTensor};
use burn::tensor::Shape;

use burn::backend::TensorMetadata;

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
