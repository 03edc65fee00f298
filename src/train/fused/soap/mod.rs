//! SOAP (Vyas et al., 2024, "SOAP: Improving and Stabilizing Shampoo using Adam",
//! Algorithm 3) on the fused step's flat parameters: Adam run in the eigenbasis of
//! Shampoo's two Kronecker factors of each weight matrix. For a weight `W` with gradient
//! `G` (`[d_in, d_out]`), the factors are running averages `L ← β₂ L + (1 − β₂) G Gᵀ` and
//! `R ← β₂ R + (1 − β₂) Gᵀ G`, with eigenvectors `Q_L`, `Q_R`; Adam's moments `M'`, `V'`
//! follow the rotated gradient `G' = Q_Lᵀ G Q_R`, and the step is
//! `Q_L (M' / (√V' + ε)) Q_Rᵀ`. The bases start as the
//! first gradient's exact eigenvectors (a step that moves no weight) and are refreshed
//! every `every` steps by one power iteration and a QR decomposition, sorted by the
//! estimated eigenvalues. Biases take plain Adam steps with the same `β` and bias
//! correction. docs/speed.md ("Time to accuracy") measures it against Adam.
//!
//! | file | what it holds |
//! |---|---|
//! | `config.rs` | [`SoapConfig`], its settings, read by the fit's config |
//! | `basis.rs` | the eigenbases: first found exactly, then refreshed (power iteration, QR) |
//! | `record.rs` | the state as a checkpoint stores it |
//! | `tests.rs` | against an independent transcription, and by hand |

mod basis;
mod config;
mod record;
#[cfg(test)]
mod tests;

use rayon::prelude::*;

use super::Float;
use crate::jacobian::analytic::cpu::{Mat, gemm, serial};
use basis::{eigenbasis, refresh_basis};
pub use config::SoapConfig;

/// One weight matrix's state.
#[derive(Clone, Debug)]
struct Matrix<E> {
    /// Where the matrix starts in the flat buffer, and its `[rows, cols]`.
    offset: usize,
    rows: usize,
    cols: usize,
    /// The factors `L` (`rows × rows`) and `R` (`cols × cols`), and their eigenbases
    /// (columns).
    left: Vec<E>,
    right: Vec<E>,
    q_left: Vec<E>,
    q_right: Vec<E>,
    /// The first and second moments, in the rotated coordinates.
    moment_1: Vec<E>,
    moment_2: Vec<E>,
    /// Two `rows × cols` buffers a step works in (not part of the state).
    scratch: [Vec<E>; 2],
}

/// A bias's Adam state.
#[derive(Clone, Debug)]
struct Vector<E> {
    offset: usize,
    moment_1: Vec<E>,
    moment_2: Vec<E>,
}

/// SOAP's state for the flat parameters of a SIREN (`[W_0, b_0, …, W_o, b_o]`, each `W`
/// `[d_in, d_out]` row-major).
#[derive(Clone, Debug)]
pub struct SoapState<E> {
    config: SoapConfig,
    /// Updates taken (the first only starts the factors).
    time: usize,
    matrices: Vec<Matrix<E>>,
    vectors: Vec<Vector<E>>,
}

impl<E: Float + Send + Sync> SoapState<E> {
    /// A fresh state for layers of `shapes` (`[d_in, d_out]`, each followed by its bias).
    pub fn new(config: SoapConfig, shapes: &[[usize; 2]]) -> Self {
        let (mut matrices, mut vectors, mut offset) = (Vec::new(), Vec::new(), 0);
        for &[rows, cols] in shapes {
            let len = rows * cols;
            matrices.push(Matrix {
                offset,
                rows,
                cols,
                scratch: [vec![E::zero(); len], vec![E::zero(); len]],
                left: vec![E::zero(); rows * rows],
                right: vec![E::zero(); cols * cols],
                q_left: Vec::new(),
                q_right: Vec::new(),
                moment_1: vec![E::zero(); len],
                moment_2: vec![E::zero(); len],
            });
            offset += len;
            vectors.push(Vector {
                offset,
                moment_1: vec![E::zero(); cols],
                moment_2: vec![E::zero(); cols],
            });
            offset += cols;
        }
        SoapState {
            config,
            time: 0,
            matrices,
            vectors,
        }
    }

    /// One update of `params` by their gradient `grad` at learning rate `lr`.
    pub fn update(&mut self, params: &mut [E], grad: &[E], lr: f64) {
        self.time += 1;
        let c = self.config;
        let t = self.time;
        for v in &mut self.vectors {
            let n = v.moment_1.len();
            let p = &mut params[v.offset..v.offset + n];
            let g = &grad[v.offset..v.offset + n];
            adam_rows(p, g, &mut v.moment_1, &mut v.moment_2, c, t, lr);
        }
        // The matrices are independent: one per task, each on one thread.
        let mut views = split_matrices(params, &self.matrices);
        self.matrices
            .par_iter_mut()
            .zip(views.par_iter_mut())
            .for_each(|(m, p)| {
                let g = &grad[m.offset..m.offset + m.rows * m.cols];
                serial(|| m.update(p, g, c, t, lr));
            });
    }
}

/// Disjoint mutable views of `params` at each matrix's place.
fn split_matrices<'a, E>(mut params: &'a mut [E], matrices: &[Matrix<E>]) -> Vec<&'a mut [E]> {
    let mut views = Vec::with_capacity(matrices.len());
    let mut at = 0;
    for m in matrices {
        let (_, rest) = params.split_at_mut(m.offset - at);
        let (view, rest) = rest.split_at_mut(m.rows * m.cols);
        views.push(view);
        params = rest;
        at = m.offset + m.rows * m.cols;
    }
    views
}

/// Adam on plain coordinates with SOAP's bias correction: `m ← β₁ m + (1 − β₁) g`,
/// `v ← β₂ v + (1 − β₂) g²`, `p ← p − lr √(1 − β₂ᵗ) / (1 − β₁ᵗ) · m / (√v + ε)`.
fn adam_rows<E: Float>(
    p: &mut [E],
    g: &[E],
    m: &mut [E],
    v: &mut [E],
    c: SoapConfig,
    t: usize,
    lr: f64,
) {
    let (b1, b2) = (E::from_f64(c.beta_1), E::from_f64(c.beta_2));
    let (f1, f2) = (E::from_f64(1.0 - c.beta_1), E::from_f64(1.0 - c.beta_2));
    let eps = E::from_f64(c.epsilon);
    let size = E::from_f64(lr * step_scale(c, t));
    for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m.iter_mut()).zip(v.iter_mut()) {
        *m = *m * b1 + g * f1;
        *v = *v * b2 + g * g * f2;
        *p = *p - size * (*m / (v.sqrt() + eps));
    }
}

/// `√(1 − β₂ᵗ) / (1 − β₁ᵗ)`.
fn step_scale(c: SoapConfig, t: usize) -> f64 {
    let t = t as i32;
    (1.0 - c.beta_2.powi(t)).sqrt() / (1.0 - c.beta_1.powi(t))
}

/// `Q_Lᵀ X Q_R` (or, `back`, `Q_L X Q_Rᵀ`) of the `[r, c]` `x` into `dst`, through `tmp`.
fn rotate<E: Float>(
    (q_left, q_right): (&[E], &[E]),
    (r, c): (usize, usize),
    x: &[E],
    back: bool,
    tmp: &mut [E],
    dst: &mut [E],
) {
    let ql = Mat::new(q_left, r, r);
    let qr = Mat::new(q_right, c, c);
    let (ql, qr) = if back { (ql, qr.t()) } else { (ql.t(), qr) };
    gemm(tmp, ql, Mat::new(x, r, c), false);
    gemm(dst, Mat::new(tmp, r, c), qr, false);
}

impl<E: Float> Matrix<E> {
    /// `L ← β L + (1 − β) G Gᵀ` and `R ← β R + (1 − β) Gᵀ G`.
    fn accumulate_factors(&mut self, g: &[E], beta: f64) {
        let (r, c) = (self.rows, self.cols);
        let scaled = &mut self.scratch[0];
        let f = E::from_f64(1.0 - beta);
        scaled.iter_mut().zip(g).for_each(|(s, &x)| *s = x * f);
        let b = E::from_f64(beta);
        self.left.iter_mut().for_each(|x| *x = *x * b);
        self.right.iter_mut().for_each(|x| *x = *x * b);
        let (scaled, g) = (Mat::new(scaled, r, c), Mat::new(g, r, c));
        gemm(&mut self.left, scaled, g.t(), true);
        gemm(&mut self.right, scaled.t(), g, true);
    }

    fn update(&mut self, p: &mut [E], g: &[E], c: SoapConfig, t: usize, lr: f64) {
        let shape = (self.rows, self.cols);
        if self.q_left.is_empty() {
            // The first step starts the factors at G Gᵀ and Gᵀ G and their bases at
            // their exact eigenvectors; it moves no weight.
            self.accumulate_factors(g, 0.0);
            self.q_left = eigenbasis(&self.left, self.rows);
            self.q_right = eigenbasis(&self.right, self.cols);
            return;
        }
        // The matrices' own count: their first update only started the factors.
        let t = t - 1;
        let bases = (&self.q_left[..], &self.q_right[..]);
        let [tmp, rotated] = &mut self.scratch;
        rotate(bases, shape, g, false, tmp, rotated);
        // Both moments live in the rotated coordinates: the first is rotated to the new
        // basis at each refresh (`Q_newᵀ Q_old M' Q_oldᵀ Q_new = Q_newᵀ M Q_new`), which
        // saves rotating it every step.
        let (b1, b2) = (E::from_f64(c.beta_1), E::from_f64(c.beta_2));
        let (f1, f2) = (E::from_f64(1.0 - c.beta_1), E::from_f64(1.0 - c.beta_2));
        let eps = E::from_f64(c.epsilon);
        // The step's size folded in, so that the rotation back lands on the weights.
        let size = E::from_f64(-lr * step_scale(c, t));
        let moments = self.moment_1.iter_mut().zip(self.moment_2.iter_mut());
        for (x, (m, v)) in rotated.iter_mut().zip(moments) {
            *m = *m * b1 + *x * f1;
            *v = *v * b2 + *x * *x * f2;
            *x = size * (*m / (v.sqrt() + eps));
        }
        // W ← W + (Q_L N) Q_Rᵀ.
        let (r, cols) = shape;
        gemm(
            tmp,
            Mat::new(bases.0, r, r),
            Mat::new(rotated, r, cols),
            false,
        );
        gemm(
            p,
            Mat::new(tmp, r, cols),
            Mat::new(bases.1, cols, cols).t(),
            true,
        );
        self.accumulate_factors(g, c.beta_2);
        if t.is_multiple_of(c.every) {
            self.refresh();
        }
    }

    /// One power iteration and a QR per factor, each basis first sorted by its estimated
    /// eigenvalues `diag(Qᵀ F Q)` (descending), the second moment permuted with it.
    fn refresh(&mut self) {
        let shape @ (r, c) = (self.rows, self.cols);
        let [tmp, original] = &mut self.scratch;
        let old = (&self.q_left[..], &self.q_right[..]);
        rotate(old, shape, &self.moment_1, true, tmp, original);
        let order_l = refresh_basis(&self.left, &mut self.q_left, r);
        let order_r = refresh_basis(&self.right, &mut self.q_right, c);
        let new = (&self.q_left[..], &self.q_right[..]);
        rotate(new, shape, original, false, tmp, &mut self.moment_1);
        let old = self.moment_2.clone();
        for (i, &oi) in order_l.iter().enumerate() {
            for (j, &oj) in order_r.iter().enumerate() {
                self.moment_2[i * c + j] = old[oi * c + oj];
            }
        }
    }
}
