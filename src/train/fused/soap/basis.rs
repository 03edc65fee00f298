//! SOAP's eigenbases: the first found exactly (Householder and QL, `numeric/eigen.rs`), then
//! refreshed by one power iteration and a Householder QR, sorted by the estimated
//! eigenvalues.

use super::Float;
use crate::jacobian::analytic::cpu::{Mat, gemm};
use crate::numeric::eigen::symmetric_eigen_householder;

/// The eigenvectors (columns) of the symmetric `f` (`[n, n]`), by descending eigenvalue.
pub(super) fn eigenbasis<E: Float>(f: &[E], n: usize) -> Vec<E> {
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
pub(super) fn refresh_basis<E: Float>(f: &[E], q: &mut [E], n: usize) -> Vec<usize> {
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
    use crate::train::fused::soap::tests::{mm, tr};

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
        let qtq = mm(&tr(&qm, n, n), &qm, n, n, n);
        for i in 0..n {
            for j in 0..n {
                let want = f64::from(u8::from(i == j));
                assert!((qtq[i * n + j] - want).abs() < 1e-12, "QᵀQ[{i},{j}]");
            }
        }
        // R = Qᵀ A is upper triangular.
        let am: Vec<f64> = (0..n * n).map(|k| cols[k % n][k / n]).collect();
        let r = mm(&tr(&qm, n, n), &am, n, n, n);
        for i in 0..n {
            for j in 0..i {
                assert!(r[i * n + j].abs() < 1e-10, "R[{i},{j}] = {}", r[i * n + j]);
            }
        }
    }
}
