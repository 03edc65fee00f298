//! The heads of Eq. 4 and 10–12 on raw rows, values and their backward: from the SIREN's
//! raw outputs `o` (`[n, O]`) and the canonical points `x` (`[n, 3]`), the warp
//! `y = A x + u` (`[n, 3]`), and from `∂L/∂y` the gradient `∂L/∂o`.
//!
//! The same maths as `field::{trans, se3, scaled_se3, affinity}` (which run on duals
//! through Burn), in the same order of operations, so that both give the same `y` up to
//! f32 round-off.

use super::Float;
use crate::field::Variant;
use crate::field::rotation::NORM_EPS;

/// `y = A x + u` for every point (Eq. 4).
pub(super) fn warp<E: Float>(variant: Variant, raw: &[E], x: &[E], y: &mut [E]) {
    let o = variant.outputs();
    for ((r, x), y) in raw
        .chunks_exact(o)
        .zip(x.chunks_exact(3))
        .zip(y.chunks_exact_mut(3))
    {
        let (a, u) = transform(variant, r);
        for i in 0..3 {
            y[i] = a[i][0] * x[0] + a[i][1] * x[1] + a[i][2] * x[2] + u[i];
        }
    }
}

/// `∂L/∂o` (`[n, O]`, overwritten) from `∂L/∂y` (`[n, 3]`).
pub(super) fn warp_backward<E: Float>(
    variant: Variant,
    raw: &[E],
    x: &[E],
    g_y: &[E],
    g_raw: &mut [E],
) {
    let o = variant.outputs();
    let rows = raw
        .chunks_exact(o)
        .zip(x.chunks_exact(3))
        .zip(g_y.chunks_exact(3))
        .zip(g_raw.chunks_exact_mut(o));
    for (((r, x), g), gr) in rows {
        // ∂L/∂A[i][j] = g_i x_j, ∂L/∂u = g.
        let g_a = |i: usize, j: usize| g[i] * x[j];
        match variant {
            Variant::Trans => gr.copy_from_slice(g),
            Variant::Affinity => {
                for i in 0..3 {
                    for j in 0..3 {
                        gr[3 * i + j] = g_a(i, j);
                    }
                    gr[9 + i] = g[i];
                }
            }
            Variant::Se3 => {
                // Column j of Q gets g · x_j.
                let g_cols = [0, 1, 2].map(|j| [0, 1, 2].map(|i| g_a(i, j)));
                gram_schmidt_backward(&r[0..6], g_cols, &mut gr[0..6]);
                gr[6..9].copy_from_slice(g);
            }
            Variant::ScaledSe3 => {
                let q = gram_schmidt(&r[1..7]);
                let s = softplus(r[0]);
                // A = s Q: ∂L/∂Q = s ∂L/∂A, ∂L/∂s = Σ ∂L/∂A ⊙ Q.
                let mut g_s = E::zero();
                let g_cols = [0, 1, 2].map(|j| {
                    [0, 1, 2].map(|i| {
                        g_s = g_s + g_a(i, j) * q[j][i];
                        g_a(i, j) * s
                    })
                });
                gr[0] = g_s * sigmoid(r[0]);
                gram_schmidt_backward(&r[1..7], g_cols, &mut gr[1..7]);
                gr[7..10].copy_from_slice(g);
            }
        }
    }
}

/// `(A, u)` of one point's raw outputs, `A` row-major.
fn transform<E: Float>(variant: Variant, r: &[E]) -> ([[E; 3]; 3], [E; 3]) {
    let (one, zero) = (E::one(), E::zero());
    let rows_of = |cols: [[E; 3]; 3]| [0, 1, 2].map(|i| [cols[0][i], cols[1][i], cols[2][i]]);
    match variant {
        Variant::Trans => (
            [[one, zero, zero], [zero, one, zero], [zero, zero, one]],
            [r[0], r[1], r[2]],
        ),
        Variant::Affinity => (
            [[r[0], r[1], r[2]], [r[3], r[4], r[5]], [r[6], r[7], r[8]]],
            [r[9], r[10], r[11]],
        ),
        Variant::Se3 => (rows_of(gram_schmidt(&r[0..6])), [r[6], r[7], r[8]]),
        Variant::ScaledSe3 => {
            let s = softplus(r[0]);
            let cols = gram_schmidt(&r[1..7]).map(|c| c.map(|v| v * s));
            (rows_of(cols), [r[7], r[8], r[9]])
        }
    }
}

fn dot<E: Float>(a: [E; 3], b: [E; 3]) -> E {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross<E: Float>(a: [E; 3], b: [E; 3]) -> [E; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `1 / max(‖v‖, ε)`, as `rotation::normalize` divides.
fn inv_norm<E: Float>(v: [E; 3]) -> E {
    dot(v, v).sqrt().max(E::from_f64(NORM_EPS)).recip()
}

/// The columns `[b1, b2, b3]` of `rotation::gram_schmidt` for one point's six outputs.
fn gram_schmidt<E: Float>(six: &[E]) -> [[E; 3]; 3] {
    let (a1, a2) = ([six[0], six[2], six[4]], [six[1], six[3], six[5]]);
    let b1 = a1.map(|v| v * inv_norm(a1));
    let p = dot(b1, a2);
    let c = [0, 1, 2].map(|i| a2[i] - b1[i] * p);
    let b2 = c.map(|v| v * inv_norm(c));
    [b1, b2, cross(b1, b2)]
}

/// The backward of `v / max(‖v‖, ε)`: `(g − v̂ (v̂ · g)) / ‖v‖`, or `g / ε` where the norm
/// is clamped (its derivative is then zero).
fn normalize_backward<E: Float>(v: [E; 3], g: [E; 3]) -> [E; 3] {
    let norm = dot(v, v).sqrt();
    let inv = inv_norm(v);
    if norm <= E::from_f64(NORM_EPS) {
        return g.map(|x| x * inv);
    }
    let hat = v.map(|x| x * inv);
    let along = dot(hat, g);
    [0, 1, 2].map(|i| (g[i] - hat[i] * along) * inv)
}

/// `∂L/∂six` (overwritten) from the gradients of the three columns of
/// [`gram_schmidt`].
fn gram_schmidt_backward<E: Float>(six: &[E], g_cols: [[E; 3]; 3], g_six: &mut [E]) {
    let (a1, a2) = ([six[0], six[2], six[4]], [six[1], six[3], six[5]]);
    let b1 = a1.map(|v| v * inv_norm(a1));
    let p = dot(b1, a2);
    let c = [0, 1, 2].map(|i| a2[i] - b1[i] * p);
    let b2 = c.map(|v| v * inv_norm(c));
    let [mut g_b1, mut g_b2, g_b3] = g_cols;
    // b3 = b1 × b2: ∂(g·(a×b))/∂a = b × g, ∂/∂b = g × a.
    let (from_b1, from_b2) = (cross(b2, g_b3), cross(g_b3, b1));
    for i in 0..3 {
        g_b1[i] = g_b1[i] + from_b1[i];
        g_b2[i] = g_b2[i] + from_b2[i];
    }
    // b2 = normalize(c), c = a2 − p b1, p = b1 · a2.
    let g_c = normalize_backward(c, g_b2);
    let g_p = E::zero() - dot(b1, g_c);
    let g_a2 = [0, 1, 2].map(|i| g_c[i] + g_p * b1[i]);
    for i in 0..3 {
        g_b1[i] = g_b1[i] - p * g_c[i] + g_p * a2[i];
    }
    let g_a1 = normalize_backward(a1, g_b1);
    for i in 0..3 {
        g_six[2 * i] = g_a1[i];
        g_six[2 * i + 1] = g_a2[i];
    }
}

/// Burn's `softplus(x, β = 1)`: `ln(1 + eˣ)`, the identity above 20.
fn softplus<E: Float>(x: E) -> E {
    if x > E::from_f64(SOFTPLUS_THRESHOLD) {
        x
    } else {
        x.exp().ln_1p()
    }
}

/// Softplus's derivative: the logistic sigmoid, 1 where softplus is the identity.
fn sigmoid<E: Float>(x: E) -> E {
    if x > E::from_f64(SOFTPLUS_THRESHOLD) {
        E::one()
    } else {
        (E::one() + (E::zero() - x).exp()).recip()
    }
}

/// Where Burn's softplus becomes the identity (PyTorch's default).
const SOFTPLUS_THRESHOLD: f64 = 20.0;
