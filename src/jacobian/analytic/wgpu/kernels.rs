//! The CubeCL kernels of the analytic op: the elementwise pass of every sine layer,
//! forward and backward, dual and value-only (docs/design.md §2.2). `#[cube]` functions
//! only, as in Burn's `custom-cubecl-kernel` example; their launch and registration are in
//! [`super`].
//!
//! Each kernel does one layer's elementwise work in one pass over `[N, d]` (dual: four
//! blocks), one thread per value-row element: `sin z`, and `ω cos z · Z_k` for the three
//! tangents; the backward `g_z = ω (g_h cos z − ω sin z Σ_k g_ḣ,k Z_k)` and
//! `g_Ż_k = ω cos z g_ḣ,k`; and their value-only forms. The first layer's pair reads the
//! tangent pre-activations `Z_k` from `W`'s rows (its input's tangents are the seeds
//! `e_x, e_y, e_z`), so that layer's matmul has `N` rows, not `4N`.

use cubecl::prelude::*;

/// One dual sine layer: `out = [sin z; ω cos z ⊙ Z_1; ω cos z ⊙ Z_2; ω cos z ⊙ Z_3]` with
/// `z = ω(Z_0 + b)`, for the stacked `zs = [Z_0; Z_1; Z_2; Z_3]` (`[4N, d]`).
///
/// Every kernel here reads and writes vectors of `N` elements along a row (`N = 4` when
/// `d` is a multiple of 4, as the value and tangent blocks and `W`'s rows then are); the
/// indices below count vectors.
#[cube(launch)]
pub(super) fn sine_dual_forward_kernel<F: Float, N: Size>(
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
pub(super) fn sine_dual_backward_kernel<F: Float, N: Size>(
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
pub(super) fn sine_dual_input_forward_kernel<F: Float, N: Size>(
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
pub(super) fn sine_dual_input_backward_kernel<F: Float, N: Size>(
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
pub(super) fn sine_forward_kernel<F: Float, N: Size>(
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
pub(super) fn sine_backward_kernel<F: Float, N: Size>(
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
