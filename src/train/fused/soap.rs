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
//! correction. docs/speed.md ("Fourth round") measures it against Adam.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::Float;
use crate::gaps::eigen::symmetric_eigen_householder;
use crate::jacobian::analytic::cpu::{Mat, gemm, serial};

/// SOAP's hyper-parameters: the paper's defaults `β = (0.95, 0.95)` and `ε = 10⁻⁸`, and
/// a refresh every 100 steps where the paper refreshes every 10 (on these small networks
/// a refresh costs several steps, and the rarer one fitted as well or better:
/// docs/speed.md, "Fourth round").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SoapConfig {
    /// `β₁`, the first moment's decay.
    #[serde(default = "default_beta")]
    pub beta_1: f64,
    /// `β₂`, the second moment's and the factors' decay.
    #[serde(default = "default_beta")]
    pub beta_2: f64,
    /// `ε`.
    #[serde(default = "default_epsilon")]
    pub epsilon: f64,
    /// Steps between refreshes of the eigenbases (the paper's default: 10).
    #[serde(default = "default_every")]
    pub every: usize,
}

fn default_beta() -> f64 {
    0.95
}
fn default_epsilon() -> f64 {
    1e-8
}
fn default_every() -> usize {
    100
}

impl Default for SoapConfig {
    fn default() -> Self {
        SoapConfig {
            beta_1: default_beta(),
            beta_2: default_beta(),
            epsilon: default_epsilon(),
            every: default_every(),
        }
    }
}

impl SoapConfig {
    /// Why these settings cannot run, if they cannot.
    pub fn check(&self) -> Result<(), String> {
        let beta = |b: f64| b.is_finite() && (0.0..1.0).contains(&b);
        if !beta(self.beta_1) || !beta(self.beta_2) {
            return Err(format!(
                "SOAP's betas must lie in [0, 1), got {} and {}",
                self.beta_1, self.beta_2
            ));
        }
        if !(self.epsilon.is_finite() && self.epsilon > 0.0) {
            return Err(format!(
                "SOAP's epsilon must be positive, got {}",
                self.epsilon
            ));
        }
        if self.every == 0 {
            return Err("SOAP's refresh interval must be at least 1 step".into());
        }
        Ok(())
    }
}

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

/// The first bytes of a checkpoint's SOAP state (Burn's Adam record is a burnpack, and
/// the fused Adam state has a magic of its own).
const MAGIC: &[u8; 16] = b"DOMA-FUSED-SOAP1";

impl SoapState<f32> {
    /// The state as a checkpoint stores it: the magic, the settings, `t`, then every
    /// buffer (each matrix's factors, bases and moments, each bias's moments) as a
    /// little-endian length and f32 values.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        let c = self.config;
        for x in [c.beta_1, c.beta_2, c.epsilon] {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.extend_from_slice(&(c.every as u64).to_le_bytes());
        out.extend_from_slice(&(self.time as u64).to_le_bytes());
        for b in self.buffers() {
            out.extend_from_slice(&(b.len() as u64).to_le_bytes());
            b.iter()
                .for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
        }
        out
    }

    /// Whether `bytes` were written by [`SoapState::to_bytes`].
    pub fn is_fused(bytes: &[u8]) -> bool {
        bytes.starts_with(MAGIC)
    }

    /// Reads [`SoapState::to_bytes`] back into a state for the same layers; a message
    /// when the bytes are not such a state or hold other shapes.
    pub fn read_bytes(&mut self, bytes: &[u8]) -> Result<(), String> {
        let mut rest = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or("the optimiser state was not written by the fused SOAP step")?;
        let word = |rest: &mut &[u8]| -> Result<[u8; 8], String> {
            let (w, r) = rest
                .split_first_chunk::<8>()
                .ok_or("the fused SOAP state is truncated")?;
            *rest = r;
            Ok(*w)
        };
        let config = SoapConfig {
            beta_1: f64::from_le_bytes(word(&mut rest)?),
            beta_2: f64::from_le_bytes(word(&mut rest)?),
            epsilon: f64::from_le_bytes(word(&mut rest)?),
            every: usize::try_from(u64::from_le_bytes(word(&mut rest)?))
                .map_err(|_| "the SOAP refresh interval overflows")?,
        };
        config.check()?;
        let time = usize::try_from(u64::from_le_bytes(word(&mut rest)?))
            .map_err(|_| "the SOAP step count overflows")?;
        let mut fresh = self.clone();
        let sizes = fresh.sizes();
        for (k, (buffer, (size, may_be_empty))) in
            fresh.buffers_mut().into_iter().zip(sizes).enumerate()
        {
            let len = u64::from_le_bytes(word(&mut rest)?);
            if len != size as u64 && !(may_be_empty && len == 0) {
                return Err(format!(
                    "the SOAP state's buffer {k} holds {len} values where the model has {size}"
                ));
            }
            let (values, r) = rest
                .split_at_checked(4 * size.min(len as usize))
                .ok_or("the fused SOAP state is truncated")?;
            rest = r;
            *buffer = values
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
        }
        if !rest.is_empty() {
            return Err(format!(
                "the fused SOAP state has {} bytes too many",
                rest.len()
            ));
        }
        fresh.config = config;
        fresh.time = time;
        *self = fresh;
        Ok(())
    }
}

impl<E> SoapState<E> {
    /// Each buffer's size, and whether it may be empty (the bases, before the first
    /// update), in the order of [`SoapState::buffers`].
    fn sizes(&self) -> Vec<(usize, bool)> {
        let mut out = Vec::new();
        for m in &self.matrices {
            let (r, c) = (m.rows * m.rows, m.cols * m.cols);
            let n = m.rows * m.cols;
            out.extend([
                (r, false),
                (c, false),
                (r, true),
                (c, true),
                (n, false),
                (n, false),
            ]);
        }
        for v in &self.vectors {
            out.extend([(v.moment_1.len(), false), (v.moment_2.len(), false)]);
        }
        out
    }

    /// Every buffer, in the order a checkpoint writes them.
    fn buffers(&self) -> Vec<&Vec<E>> {
        let mut out = Vec::new();
        for m in &self.matrices {
            out.extend([
                &m.left,
                &m.right,
                &m.q_left,
                &m.q_right,
                &m.moment_1,
                &m.moment_2,
            ]);
        }
        for v in &self.vectors {
            out.extend([&v.moment_1, &v.moment_2]);
        }
        out
    }

    fn buffers_mut(&mut self) -> Vec<&mut Vec<E>> {
        let mut out = Vec::new();
        for m in &mut self.matrices {
            out.extend([
                &mut m.left,
                &mut m.right,
                &mut m.q_left,
                &mut m.q_right,
                &mut m.moment_1,
                &mut m.moment_2,
            ]);
        }
        for v in &mut self.vectors {
            out.extend([&mut v.moment_1, &mut v.moment_2]);
        }
        out
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

impl<E: Float> Matrix<E> {
    /// `Q_Lᵀ X Q_R` (or, `back`, `Q_L X Q_Rᵀ`) into `dst`, through `tmp`.
    fn rotate(&self, x: &[E], back: bool, tmp: &mut [E], dst: &mut [E]) {
        let (r, c) = (self.rows, self.cols);
        let ql = Mat::new(&self.q_left, r, r);
        let qr = Mat::new(&self.q_right, c, c);
        let (ql, qr) = if back { (ql, qr.t()) } else { (ql.t(), qr) };
        gemm(tmp, ql, Mat::new(x, r, c), false);
        gemm(dst, Mat::new(tmp, r, c), qr, false);
    }

    /// `f ← β f + (1 − β) X Xᵀ` (`left`) or `Xᵀ X`, for the gradient `g`.
    fn accumulate_factors(&mut self, g: &[E], beta: f64) {
        let (r, c) = (self.rows, self.cols);
        let scaled: Vec<E> = g.iter().map(|&x| x * E::from_f64(1.0 - beta)).collect();
        let b = E::from_f64(beta);
        self.left.iter_mut().for_each(|x| *x = *x * b);
        self.right.iter_mut().for_each(|x| *x = *x * b);
        gemm(
            &mut self.left,
            Mat::new(&scaled, r, c),
            Mat::new(g, r, c).t(),
            true,
        );
        gemm(
            &mut self.right,
            Mat::new(&scaled, r, c).t(),
            Mat::new(g, r, c),
            true,
        );
    }

    fn update(&mut self, p: &mut [E], g: &[E], c: SoapConfig, t: usize, lr: f64) {
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
        let len = self.rows * self.cols;
        let (mut tmp, mut rotated) = (vec![E::zero(); len], vec![E::zero(); len]);
        let (b1, b2) = (E::from_f64(c.beta_1), E::from_f64(c.beta_2));
        let (f1, f2) = (E::from_f64(1.0 - c.beta_1), E::from_f64(1.0 - c.beta_2));
        self.rotate(g, false, &mut tmp, &mut rotated);
        // Both moments live in the rotated coordinates: the first is rotated to the new
        // basis at each refresh (`Q_newᵀ Q_old M' Q_oldᵀ Q_new = Q_newᵀ M Q_new`), which
        // saves rotating it every step.
        let eps = E::from_f64(c.epsilon);
        let moments = self.moment_1.iter_mut().zip(self.moment_2.iter_mut());
        for (x, (m, v)) in rotated.iter_mut().zip(moments) {
            *m = *m * b1 + *x * f1;
            *v = *v * b2 + *x * *x * f2;
            *x = *m / (v.sqrt() + eps);
        }
        let mut step = vec![E::zero(); len];
        self.rotate(&rotated, true, &mut tmp, &mut step);
        let size = E::from_f64(lr * step_scale(c, t));
        for (p, &s) in p.iter_mut().zip(&step) {
            *p = *p - size * s;
        }
        self.accumulate_factors(g, c.beta_2);
        if t.is_multiple_of(c.every) {
            self.refresh();
        }
    }

    /// One power iteration and a QR per factor, each basis first sorted by its estimated
    /// eigenvalues `diag(Qᵀ F Q)` (descending), the second moment permuted with it.
    fn refresh(&mut self) {
        let (r, c) = (self.rows, self.cols);
        let mut tmp = vec![E::zero(); r * c];
        let mut original = vec![E::zero(); r * c];
        self.rotate(&self.moment_1, true, &mut tmp, &mut original);
        let order_l = refresh_basis(&self.left, &mut self.q_left, r);
        let order_r = refresh_basis(&self.right, &mut self.q_right, c);
        let mut rotated = vec![E::zero(); r * c];
        self.rotate(&original, false, &mut tmp, &mut rotated);
        self.moment_1 = rotated;
        let old = self.moment_2.clone();
        for (i, &oi) in order_l.iter().enumerate() {
            for (j, &oj) in order_r.iter().enumerate() {
                self.moment_2[i * c + j] = old[oi * c + oj];
            }
        }
    }
}

/// The eigenvectors (columns) of the symmetric `f` (`[n, n]`), by descending eigenvalue.
fn eigenbasis<E: Float>(f: &[E], n: usize) -> Vec<E> {
    let (values, vectors) = symmetric_eigen_householder(f.iter().map(|x| x.to_f64()).collect(), n);
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    let mut q = vec![E::zero(); n * n];
    for i in 0..n {
        for (j, &o) in order.iter().enumerate() {
            q[i * n + j] = E::from_f64(vectors[i * n + o]);
        }
    }
    q
}

/// Sorts `q`'s columns by `diag(qᵀ f q)` (descending), then replaces `q` by the Q of
/// `f q`'s QR decomposition. Returns the sorting order.
fn refresh_basis<E: Float>(f: &[E], q: &mut [E], n: usize) -> Vec<usize> {
    let mut fq = vec![E::zero(); n * n];
    gemm(&mut fq, Mat::new(f, n, n), Mat::new(q, n, n), false);
    let estimate: Vec<f64> = (0..n)
        .map(|j| {
            (0..n)
                .map(|i| (q[i * n + j] * fq[i * n + j]).to_f64())
                .sum()
        })
        .collect();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| estimate[b].total_cmp(&estimate[a]));
    // f (q sorted) = (f q) sorted: the columns of the product, in the same order.
    let columns: Vec<Vec<f64>> = order
        .iter()
        .map(|&j| (0..n).map(|i| fq[i * n + j].to_f64()).collect())
        .collect();
    let basis = householder_q(columns, n);
    for (j, col) in basis.iter().enumerate() {
        for i in 0..n {
            q[i * n + j] = E::from_f64(col[i]);
        }
    }
    order
}

/// The `n × n` orthogonal factor `Q` of `A = Q R`, `A` given by its columns, by
/// Householder reflections; returned by columns. A column that is already zero below
/// the diagonal gets no reflection (its factor is then the identity there).
fn householder_q(mut a: Vec<Vec<f64>>, n: usize) -> Vec<Vec<f64>> {
    let mut reflectors: Vec<Option<Vec<f64>>> = Vec::with_capacity(n);
    for j in 0..n {
        let x = &a[j][j..];
        let norm = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm == 0.0 {
            reflectors.push(None);
            continue;
        }
        let mut v = x.to_vec();
        let alpha = if v[0] >= 0.0 { -norm } else { norm };
        v[0] -= alpha;
        let vv: f64 = v.iter().map(|x| x * x).sum();
        if vv == 0.0 {
            reflectors.push(None);
            continue;
        }
        for col in a.iter_mut().skip(j) {
            reflect(&mut col[j..], &v, vv);
        }
        reflectors.push(Some(v));
    }
    // Q = H_0 H_1 … H_{n-1}: applied to the identity's columns, last reflector first.
    let mut q: Vec<Vec<f64>> = (0..n)
        .map(|j| (0..n).map(|i| f64::from(u8::from(i == j))).collect())
        .collect();
    for (j, v) in reflectors.iter().enumerate().rev() {
        if let Some(v) = v {
            let vv: f64 = v.iter().map(|x| x * x).sum();
            for col in q.iter_mut() {
                reflect(&mut col[j..], v, vv);
            }
        }
    }
    q
}

/// `x ← (I − 2 v vᵀ / vᵀv) x`.
fn reflect(x: &mut [f64], v: &[f64], vv: f64) {
    let s = 2.0 * x.iter().zip(v).map(|(a, b)| a * b).sum::<f64>() / vv;
    x.iter_mut().zip(v).for_each(|(a, b)| *a -= s * b);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn product(a: &[f64], b: &[f64], n: usize, ta: bool) -> Vec<f64> {
        let mut out = vec![0.0; n * n];
        let am = Mat::new(a, n, n);
        gemm(
            &mut out,
            if ta { am.t() } else { am },
            Mat::new(b, n, n),
            false,
        );
        out
    }

    #[test]
    fn householder_q_is_orthogonal_and_spans_the_columns() {
        let n = 7;
        let cols: Vec<Vec<f64>> = (0..n)
            .map(|j| {
                (0..n)
                    .map(|i| ((i * 7 + j * 3) % 11) as f64 - 5.0)
                    .collect()
            })
            .collect();
        let q = householder_q(cols.clone(), n);
        let qm: Vec<f64> = (0..n * n).map(|k| q[k % n][k / n]).collect();
        let qtq = product(&qm, &qm, n, true);
        for i in 0..n {
            for j in 0..n {
                let want = f64::from(u8::from(i == j));
                assert!((qtq[i * n + j] - want).abs() < 1e-12, "QᵀQ[{i},{j}]");
            }
        }
        // R = Qᵀ A is upper triangular.
        let am: Vec<f64> = (0..n * n).map(|k| cols[k % n][k / n]).collect();
        let r = product(&qm, &am, n, true);
        for i in 0..n {
            for j in 0..i {
                assert!(r[i * n + j].abs() < 1e-10, "R[{i},{j}] = {}", r[i * n + j]);
            }
        }
    }

    /// SOAP written out with naive f64 matrices and modified Gram–Schmidt for the QR: an
    /// independent transcription of the algorithm the module implements. `w` is `[r, c]`.
    struct Reference {
        r: usize,
        c: usize,
        l: Vec<f64>,
        rr: Vec<f64>,
        ql: Vec<f64>,
        qr: Vec<f64>,
        m: Vec<f64>,
        v: Vec<f64>,
        t: usize,
    }

    fn mm(a: &[f64], b: &[f64], n: usize, k: usize, m: usize) -> Vec<f64> {
        (0..n * m)
            .map(|ij| (0..k).map(|x| a[ij / m * k + x] * b[x * m + ij % m]).sum())
            .collect()
    }

    fn tr(a: &[f64], n: usize, m: usize) -> Vec<f64> {
        (0..n * m).map(|ij| a[(ij % n) * m + ij / n]).collect()
    }

    fn gram_schmidt(a: &[f64], n: usize) -> Vec<f64> {
        let mut q = a.to_vec();
        for j in 0..n {
            for p in 0..j {
                let d: f64 = (0..n).map(|i| q[i * n + j] * q[i * n + p]).sum();
                for i in 0..n {
                    q[i * n + j] -= d * q[i * n + p];
                }
            }
            let norm = (0..n).map(|i| q[i * n + j].powi(2)).sum::<f64>().sqrt();
            for i in 0..n {
                q[i * n + j] /= norm;
            }
        }
        q
    }

    fn jacobi_basis(f: &[f64], n: usize) -> Vec<f64> {
        let (values, vectors) = crate::gaps::eigen::symmetric_eigen(f.to_vec(), n);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
        (0..n * n)
            .map(|ij| vectors[ij / n * n + order[ij % n]])
            .collect()
    }

    impl Reference {
        fn step(&mut self, w: &mut [f64], g: &[f64], c: SoapConfig, lr: f64) {
            let (r, cc) = (self.r, self.c);
            let ggt = mm(g, &tr(g, r, cc), r, cc, r);
            let gtg = mm(&tr(g, r, cc), g, cc, r, cc);
            if self.ql.is_empty() {
                self.l = ggt;
                self.rr = gtg;
                self.ql = jacobi_basis(&self.l, r);
                self.qr = jacobi_basis(&self.rr, cc);
                return;
            }
            self.t += 1;
            let rot = |x: &[f64], ql: &[f64], qr: &[f64]| {
                mm(&mm(&tr(ql, r, r), x, r, r, cc), qr, r, cc, cc)
            };
            let gr = rot(g, &self.ql, &self.qr);
            for k in 0..r * cc {
                self.m[k] = c.beta_1 * self.m[k] + (1.0 - c.beta_1) * g[k];
                self.v[k] = c.beta_2 * self.v[k] + (1.0 - c.beta_2) * gr[k] * gr[k];
            }
            let mr = rot(&self.m, &self.ql, &self.qr);
            let n: Vec<f64> = (0..r * cc)
                .map(|k| mr[k] / (self.v[k].sqrt() + c.epsilon))
                .collect();
            let back = mm(
                &mm(&self.ql, &n, r, r, cc),
                &tr(&self.qr, cc, cc),
                r,
                cc,
                cc,
            );
            let t = self.t as i32;
            let size = lr * (1.0 - c.beta_2.powi(t)).sqrt() / (1.0 - c.beta_1.powi(t));
            for k in 0..r * cc {
                w[k] -= size * back[k];
            }
            for (l, x) in self.l.iter_mut().zip(&ggt) {
                *l = c.beta_2 * *l + (1.0 - c.beta_2) * x;
            }
            for (rr, x) in self.rr.iter_mut().zip(&gtg) {
                *rr = c.beta_2 * *rr + (1.0 - c.beta_2) * x;
            }
            if self.t.is_multiple_of(c.every) {
                let sorted = |f: &[f64], q: &[f64], n: usize| {
                    let fq = mm(f, q, n, n, n);
                    let mut order: Vec<usize> = (0..n).collect();
                    let est: Vec<f64> = (0..n)
                        .map(|j| (0..n).map(|i| q[i * n + j] * fq[i * n + j]).sum())
                        .collect();
                    order.sort_by(|&a, &b| est[b].total_cmp(&est[a]));
                    let qs: Vec<f64> = (0..n * n).map(|ij| q[ij / n * n + order[ij % n]]).collect();
                    (gram_schmidt(&mm(f, &qs, n, n, n), n), order)
                };
                let (ql, ol) = sorted(&self.l, &self.ql, r);
                let (qr, or) = sorted(&self.rr, &self.qr, cc);
                let old = self.v.clone();
                for i in 0..r {
                    for j in 0..cc {
                        self.v[i * cc + j] = old[ol[i] * cc + or[j]];
                    }
                }
                (self.ql, self.qr) = (ql, qr);
            }
        }
    }

    #[test]
    fn soap_follows_an_independent_transcription_for_30_steps() {
        let (r, c) = (3, 5);
        let config = SoapConfig {
            every: 4,
            ..SoapConfig::default()
        };
        let mut state = SoapState::<f64>::new(config, &[[r, c]]);
        let mut reference = Reference {
            r,
            c,
            l: vec![],
            rr: vec![],
            ql: vec![],
            qr: vec![],
            m: vec![0.0; r * c],
            v: vec![0.0; r * c],
            t: 0,
        };
        let mut p: Vec<f64> = (0..r * c + c).map(|k| (k as f64 * 0.37).sin()).collect();
        let mut w: Vec<f64> = p[..r * c].to_vec();
        for step in 0..30 {
            let g: Vec<f64> = (0..r * c + c)
                .map(|k| ((k * 13 + step * 7) as f64 * 0.91).cos() + 0.1 * (k % 3) as f64)
                .collect();
            state.update(&mut p, &g, 1e-2);
            reference.step(&mut w, &g[..r * c], config, 1e-2);
            if step == 0 {
                // GᵀG has a null space, where any orthonormal vectors are eigenvectors and
                // Adam's coordinates depend on the choice: the reference takes the bases
                // found here, once checked to be sorted eigenvectors.
                let m = &state.matrices[0];
                for (q, f, n) in [(&m.q_left, &reference.l, r), (&m.q_right, &reference.rr, c)] {
                    let d = mm(&tr(q, n, n), &mm(f, q, n, n, n), n, n, n);
                    let scale = (0..n).map(|i| d[i * n + i]).fold(0.0, f64::max);
                    for i in 0..n {
                        for j in 0..n {
                            if i != j {
                                assert!(d[i * n + j].abs() < 1e-12 * scale, "QᵀFQ[{i},{j}]");
                            }
                        }
                        assert!(i == 0 || d[i * n + i] <= d[(i - 1) * n + i - 1] + 1e-12);
                    }
                    let qtq = mm(&tr(q, n, n), q, n, n, n);
                    for i in 0..n {
                        assert!((qtq[i * n + i] - 1.0).abs() < 1e-12);
                    }
                }
                reference.ql = m.q_left.clone();
                reference.qr = m.q_right.clone();
            }
            for k in 0..r * c {
                assert!(
                    (p[k] - w[k]).abs() < 1e-9,
                    "step {step}, weight {k}: {} against {}",
                    p[k],
                    w[k]
                );
            }
        }
        // The weights moved: the comparison is not of two idle states.
        assert!((p[0] - (0.0f64).sin()).abs() > 1e-3);
    }

    #[test]
    fn the_state_round_trips_through_its_bytes_and_refuses_others() {
        let mut s = SoapState::<f32>::new(SoapConfig::default(), &[[2, 3], [3, 1]]);
        let mut p: Vec<f32> = (0..16).map(|k| k as f32 * 0.1).collect();
        for k in 0..3 {
            let g: Vec<f32> = (0..16).map(|i| ((i + k) as f32).sin()).collect();
            s.update(&mut p, &g, 1e-2);
        }
        let bytes = s.to_bytes();
        assert!(SoapState::is_fused(&bytes));
        let mut back = SoapState::<f32>::new(SoapConfig::default(), &[[2, 3], [3, 1]]);
        back.read_bytes(&bytes).unwrap();
        assert_eq!(back.to_bytes(), bytes);
        let mut other = SoapState::<f32>::new(SoapConfig::default(), &[[2, 4], [4, 1]]);
        let err = other.read_bytes(&bytes).unwrap_err();
        assert!(err.contains("buffer 1 holds 9 values"), "{err}");
        for cut in [10, 40, bytes.len() - 1] {
            let err = back.read_bytes(&bytes[..cut]).unwrap_err();
            assert!(
                err.contains("truncated") || err.contains("written"),
                "{err}"
            );
        }
        let mut long = bytes.clone();
        long.push(0);
        assert!(back.read_bytes(&long).unwrap_err().contains("too many"));
        // A failed read leaves the state as it was.
        assert_eq!(back.to_bytes(), bytes);
    }

    #[test]
    fn a_soap_step_by_hand() {
        // One 2×2 weight and its bias. Step 1 starts the factors; step 2 is checked
        // against the algorithm written out with the exact eigenvectors.
        let c = SoapConfig::default();
        let mut s = SoapState::<f64>::new(c, &[[2, 2]]);
        let mut p = vec![1.0, 2.0, 3.0, 4.0, 0.5, -0.5];
        let g1 = vec![0.3, 0.0, 0.0, -0.2, 0.1, 0.2];
        s.update(&mut p, &g1, 0.1);
        // The weights did not move; the bias took an Adam step of size lr (|m̂/√v̂| = 1).
        assert_eq!(&p[..4], &[1.0, 2.0, 3.0, 4.0]);
        assert!(
            (p[4] - 0.4).abs() < 1e-6 && (p[5] + 0.6).abs() < 1e-6,
            "{p:?}"
        );
        // G₁ is diagonal, so both bases are the identity, sorted: L = diag(0.09, 0.04),
        // R = diag(0.09, 0.04), already in descending order.
        let g2 = vec![0.1, 0.0, 0.0, 0.4, 0.0, 0.0];
        s.update(&mut p, &g2, 0.1);
        // t = 1 for the matrix: m = 0.05 g, v = 0.05 g², step = lr √0.05 / 0.05 · m/(√v+ε)
        // = lr · sign(g) where g ≠ 0 (up to ε).
        let expect = [1.0 - 0.1, 2.0, 3.0, 4.0 - 0.1];
        for k in 0..4 {
            assert!((p[k] - expect[k]).abs() < 1e-6, "p[{k}] = {}", p[k]);
        }
    }
}
