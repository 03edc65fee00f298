//! The symmetric eigenproblem (Jacobi rotations; Householder and QL) and the principal
//! components of a PCA: for the iterative PCA fill, the Kalman smoother, Gløersen's fill
//! (which finds only the leading ones, [`principal_spectrum`]) and SOAP's preconditioner
//! basis. Plain `f64` arithmetic on slices, no tensors.

// Index loops over small matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

use std::ops::Range;

use super::linalg::column_gram;

/// The eigenvalues and eigenvectors (columns of the returned `[n, n]`) of the symmetric
/// `a` (`[n, n]`, row-major), by cyclic Jacobi rotations, until the off-diagonal squares
/// sum to at most 10⁻²⁴ of all squares.
pub fn symmetric_eigen(a: Vec<f64>, n: usize) -> (Vec<f64>, Vec<f64>) {
    symmetric_eigen_to(a, n, 1e-24)
}

/// [`symmetric_eigen`] until the off-diagonal squares sum to at most `tolerance` of all
/// squares (at most 60 sweeps): a small eigenvalue's vector is only as accurate as the
/// off-diagonal left, relative to the gap to its neighbours.
pub fn symmetric_eigen_to(mut a: Vec<f64>, n: usize, tolerance: f64) -> (Vec<f64>, Vec<f64>) {
    let mut v = vec![0f64; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    let scale: f64 = a.iter().map(|x| x * x).sum::<f64>().max(1e-300);
    for _sweep in 0..60 {
        let off: f64 = (0..n)
            .flat_map(|p| (0..n).filter(move |&q| q != p).map(move |q| (p, q)))
            .map(|(p, q)| a[p * n + q] * a[p * n + q])
            .sum();
        if off <= tolerance * scale {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[p * n + q];
                if apq.abs() <= 1e-300 {
                    continue;
                }
                let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                let tan = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let tan = if theta == 0.0 { 1.0 } else { tan };
                let cos = 1.0 / (tan * tan + 1.0).sqrt();
                let sin = tan * cos;
                for k in 0..n {
                    let (akp, akq) = (a[k * n + p], a[k * n + q]);
                    a[k * n + p] = cos * akp - sin * akq;
                    a[k * n + q] = sin * akp + cos * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p * n + k], a[q * n + k]);
                    a[p * n + k] = cos * apk - sin * aqk;
                    a[q * n + k] = sin * apk + cos * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = cos * vkp - sin * vkq;
                    v[k * n + q] = sin * vkp + cos * vkq;
                }
            }
        }
    }
    ((0..n).map(|i| a[i * n + i]).collect(), v)
}

/// The eigenvalues and eigenvectors (columns of the returned `[n, n]`) of the symmetric
/// `a` (`[n, n]`, row-major), by Householder reduction to tridiagonal form and the
/// implicit QL iteration (EISPACK's `tred2` and `tql2`): about `10 n³` operations where
/// cyclic Jacobi rotations take `6 n³` per sweep, for the many eigenproblems of
/// Gløersen's fill (two per gapped marker).
///
/// The working matrix is held transposed: every `O(n³)` loop of `tred2` and `tql2` walks
/// down a column, which is then a contiguous row, several times faster than strided
/// reads. The arithmetic, and so every bit of the result, is the textbook order's.
pub fn symmetric_eigen_householder(a: Vec<f64>, n: usize) -> (Vec<f64>, Vec<f64>) {
    if n == 0 {
        return (Vec::new(), Vec::new());
    }
    // `w[j * n + k]` holds the textbook's `V[k][j]`.
    let mut w = transpose(&a, n);
    drop(a);
    let at = |i: usize, j: usize| j * n + i;
    let (mut d, mut e) = (vec![0f64; n], vec![0f64; n]);
    tridiagonalize(&mut w, n, &mut d, &mut e);
    // Accumulate the transformations.
    for i in 0..n - 1 {
        w[at(n - 1, i)] = w[at(i, i)];
        w[at(i, i)] = 1.0;
        let h = d[i + 1];
        if h != 0.0 {
            for k in 0..=i {
                d[k] = w[at(k, i + 1)] / h;
            }
            // Columns 0..=i of V are rows of `w` before row i + 1.
            let (before, from) = w.split_at_mut((i + 1) * n);
            let next = &from[..=i];
            for j in 0..=i {
                let column = &mut before[j * n..j * n + i + 1];
                let g: f64 = next.iter().zip(column.iter()).map(|(a, b)| a * b).sum();
                for (x, &dk) in column.iter_mut().zip(&d[..=i]) {
                    *x -= g * dk;
                }
            }
        }
        for k in 0..=i {
            w[at(k, i + 1)] = 0.0;
        }
    }
    for j in 0..n {
        d[j] = w[at(n - 1, j)];
        w[at(n - 1, j)] = 0.0;
    }
    w[at(n - 1, n - 1)] = 1.0;
    e[0] = 0.0;
    implicit_ql(&mut d, &mut e, |i, c, s| {
        // Columns i and i + 1 of V, rotated: rows i and i + 1 of `w`.
        let (left, right) = w[i * n..(i + 2) * n].split_at_mut(n);
        for (vi, vi1) in left.iter_mut().zip(right.iter_mut()) {
            let h = *vi1;
            *vi1 = s * *vi + c * h;
            *vi = c * *vi - s * h;
        }
    });
    (d, transpose(&w, n))
}

/// `tred2`'s Householder reduction of the symmetric matrix held (transposed) in `w` to
/// tridiagonal form, in place: afterwards `w[j * n + j]` is the tridiagonal's `j`-th
/// diagonal entry, `e[i]` (`i ≥ 1`) its entry below the diagonal in row `i`, and row `i`
/// of `w` up to `i` holds the Householder vector `u` that reduced row `i`, `d[i]` its
/// `h = uᵀu / 2` (0: none).
pub(crate) fn tridiagonalize(w: &mut [f64], n: usize, d: &mut [f64], e: &mut [f64]) {
    let at = |i: usize, j: usize| j * n + i;
    // Householder reduction to tridiagonal form.
    for j in 0..n {
        d[j] = w[at(n - 1, j)];
    }
    for i in (1..n).rev() {
        let scale: f64 = d[..i].iter().map(|x| x.abs()).sum();
        let mut h = 0f64;
        if scale == 0.0 {
            e[i] = d[i - 1];
            for j in 0..i {
                d[j] = w[at(i - 1, j)];
                w[at(i, j)] = 0.0;
                w[at(j, i)] = 0.0;
            }
        } else {
            for k in 0..i {
                d[k] /= scale;
                h += d[k] * d[k];
            }
            let f = d[i - 1];
            let g = if f > 0.0 { -h.sqrt() } else { h.sqrt() };
            e[i] = scale * g;
            h -= f * g;
            d[i - 1] = f - g;
            e[..i].fill(0.0);
            for j in 0..i {
                let f = d[j];
                w[at(j, i)] = f;
                let mut g = e[j] + w[at(j, j)] * f;
                // V[j+1..i][j], a column: row j of `w`.
                let column = &w[j * n + j + 1..j * n + i];
                for ((&x, &dk), ek) in column.iter().zip(&d[j + 1..i]).zip(&mut e[j + 1..i]) {
                    g += x * dk;
                    *ek += x * f;
                }
                e[j] = g;
            }
            let mut f = 0f64;
            for j in 0..i {
                e[j] /= h;
                f += e[j] * d[j];
            }
            let hh = f / (h + h);
            for j in 0..i {
                e[j] -= hh * d[j];
            }
            for j in 0..i {
                let (f, g) = (d[j], e[j]);
                let column = &mut w[j * n + j..j * n + i];
                for ((x, &ek), &dk) in column.iter_mut().zip(&e[j..i]).zip(&d[j..i]) {
                    *x -= f * ek + g * dk;
                }
                d[j] = w[at(i - 1, j)];
                w[at(i, j)] = 0.0;
            }
        }
        d[i] = h;
    }
}

/// `tql2`'s implicit QL iteration on the tridiagonal of diagonal `d` and subdiagonal
/// `e[1..]` (as [`tridiagonalize`] leaves it, `e[0] = 0`): `d` becomes the eigenvalues.
/// Each plane rotation of rows `i` and `i + 1` of the eigenvector matrix is handed to
/// `rotate(i, c, s)`; the eigenvalues do not depend on what it does.
pub(crate) fn implicit_ql(d: &mut [f64], e: &mut [f64], mut rotate: impl FnMut(usize, f64, f64)) {
    let n = d.len();
    for i in 1..n {
        e[i - 1] = e[i];
    }
    e[n - 1] = 0.0;
    let (mut f, mut tst1) = (0f64, 0f64);
    let eps = f64::EPSILON;
    for l in 0..n {
        tst1 = tst1.max(d[l].abs() + e[l].abs());
        let mut m = l;
        while m < n - 1 && e[m].abs() > eps * tst1 {
            m += 1;
        }
        if m > l {
            for _iteration in 0..60 {
                let g = d[l];
                let p = (d[l + 1] - g) / (2.0 * e[l]);
                let r = if p < 0.0 { -p.hypot(1.0) } else { p.hypot(1.0) };
                d[l] = e[l] / (p + r);
                d[l + 1] = e[l] * (p + r);
                let dl1 = d[l + 1];
                let h = g - d[l];
                for x in &mut d[l + 2..n] {
                    *x -= h;
                }
                f += h;
                let mut p = d[m];
                let (mut c, mut c2, mut c3) = (1f64, 1f64, 1f64);
                let el1 = e[l + 1];
                let (mut s, mut s2) = (0f64, 0f64);
                for i in (l..m).rev() {
                    c3 = c2;
                    c2 = c;
                    s2 = s;
                    let g = c * e[i];
                    let h = c * p;
                    let r = p.hypot(e[i]);
                    e[i + 1] = s * r;
                    s = e[i] / r;
                    c = p / r;
                    p = c * d[i] - s * g;
                    d[i + 1] = h + s * (c * g + s * d[i]);
                    rotate(i, c, s);
                }
                p = -s * s2 * c3 * el1 * e[l] / dl1;
                e[l] = s * p;
                d[l] = c * p;
                if e[l].abs() <= eps * tst1 {
                    break;
                }
            }
        }
        d[l] += f;
        e[l] = 0.0;
    }
}

/// The transpose of the `[n, n]` row-major `a`.
fn transpose(a: &[f64], n: usize) -> Vec<f64> {
    let mut t = vec![0f64; n * n];
    for r in 0..n {
        for c in 0..n {
            t[c * n + r] = a[r * n + c];
        }
    }
    t
}

/// A principal component analysis: the singular values of a matrix, largest first, and
/// their right singular vectors.
pub struct Components {
    /// The singular values, largest first.
    pub singular: Vec<f64>,
    /// `vectors[j][c]`: component `j`'s loading on column `c`.
    pub vectors: Vec<Vec<f64>>,
}

/// The components of `x` (`rows × cols`, row-major, `rows ≥ 2`) with the columns `zeroed`
/// set to 0, as the SVD of `X / √(rows − 1)` (numpy's and MATLAB's economy SVD):
/// `min(rows, cols)` of them. From
/// the eigenvectors of `Xᵀ X`, or, for fewer rows than columns (a short clip of many
/// markers), of the smaller `X Xᵀ`, each `u` giving the vector `Xᵀ u / ‖Xᵀ u‖`.
pub fn principal_components(
    x: &[f64],
    rows: usize,
    cols: usize,
    zeroed: Option<Range<usize>>,
) -> Components {
    let zeroed = zeroed.unwrap_or(0..0);
    let (n, gram) = gram_of(x, rows, cols, &zeroed);
    let (values, vectors) = symmetric_eigen_householder(gram, n);
    let vectors = if rows >= cols {
        vectors
    } else {
        // Column o of the result: Xᵀ u_o, normalised (0 for a null direction).
        let mut wide = vec![0f64; cols * rows];
        for o in 0..rows {
            let u: Vec<f64> = (0..rows).map(|r| vectors[r * rows + o]).collect();
            for (c, v) in wide_vector(x, rows, cols, &zeroed, &u)
                .into_iter()
                .enumerate()
            {
                wide[c * rows + o] = v;
            }
        }
        wide
    };
    let (order, singular) = singular_values(&values, rows, cols);
    Components {
        singular,
        vectors: order
            .iter()
            .map(|&o| (0..cols).map(|c| vectors[c * n + o]).collect())
            .collect(),
    }
}

/// The `min(rows, cols)` largest of a Gram matrix's eigenvalues `values` (of a `rows ×
/// cols` matrix): their indices, largest first, and the singular values `√(λ / (rows − 1))`
/// they give (numpy's and MATLAB's economy SVD of `X / √(rows − 1)`).
fn singular_values(values: &[f64], rows: usize, cols: usize) -> (Vec<usize>, Vec<f64>) {
    let scale = (rows - 1) as f64;
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    order.truncate(rows.min(cols));
    let singular = order
        .iter()
        .map(|&o| (values[o].max(0.0) / scale).sqrt())
        .collect();
    (order, singular)
}

/// The Gram matrix whose eigenvectors give `x`'s components (`rows × cols`, the columns
/// `zeroed` set to 0), and its size: `Xᵀ X` (`cols`), or for fewer rows than columns the
/// smaller `X Xᵀ` (`rows`).
fn gram_of(x: &[f64], rows: usize, cols: usize, zeroed: &Range<usize>) -> (usize, Vec<f64>) {
    if rows >= cols {
        let mut gram = column_gram(x.chunks(cols), cols);
        for c in zeroed.clone() {
            for o in 0..cols {
                gram[c * cols + o] = 0.0;
                gram[o * cols + c] = 0.0;
            }
        }
        (cols, gram)
    } else {
        let kept = |c: &usize| !zeroed.contains(c);
        let mut gram = vec![0f64; rows * rows];
        for a in 0..rows {
            for b in 0..=a {
                let (ra, rb) = (&x[a * cols..(a + 1) * cols], &x[b * cols..(b + 1) * cols]);
                let dot: f64 = (0..cols).filter(kept).map(|c| ra[c] * rb[c]).sum();
                gram[a * rows + b] = dot;
                gram[b * rows + a] = dot;
            }
        }
        (rows, gram)
    }
}

/// The right singular vector `Xᵀ u / ‖Xᵀ u‖` of `x` (`rows × cols`, fewer rows than
/// columns, the columns `zeroed` set to 0) from the eigenvector `u` of `X Xᵀ` (0 for a
/// null direction).
fn wide_vector(x: &[f64], rows: usize, cols: usize, zeroed: &Range<usize>, u: &[f64]) -> Vec<f64> {
    let v: Vec<f64> = (0..cols)
        .map(|c| match zeroed.contains(&c) {
            false => (0..rows).map(|r| x[r * cols + c] * u[r]).sum(),
            true => 0.0,
        })
        .collect();
    let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
    match norm > 0.0 {
        true => v.into_iter().map(|a| a / norm).collect(),
        false => vec![0.0; cols],
    }
}

mod spectrum;

pub use spectrum::{Eigensystem, Spectrum, principal_spectrum};

#[cfg(test)]
mod tests {
    use super::*;

    /// Fewer rows than columns: the components from `X Xᵀ` are those from `Xᵀ X`, up to
    /// sign, with and without zeroed columns.
    #[test]
    fn components_of_a_wide_matrix_are_those_of_its_column_gram() {
        let (rows, cols) = (4, 9);
        let x: Vec<f64> = (0..rows * cols)
            .map(|v| ((v * 7919) % 101) as f64 / 50.0 - 1.0)
            .collect();
        for zeroed in [None, Some(3..6)] {
            let wide = principal_components(&x, rows, cols, zeroed.clone());
            // The same matrix padded with zero rows to be tall has the same components.
            let mut tall = x.clone();
            tall.resize(cols * cols, 0.0);
            let reference = principal_components(&tall, cols, cols, zeroed.clone());
            let rescale = ((cols - 1) as f64 / (rows - 1) as f64).sqrt();
            assert_eq!(wide.singular.len(), rows);
            for o in 0..rows {
                let (a, b) = (wide.singular[o], reference.singular[o] * rescale);
                assert!((a - b).abs() < 1e-12 * b.max(1.0), "{o}: {a} {b}");
                if b > 1e-9 {
                    let dot: f64 = wide.vectors[o]
                        .iter()
                        .zip(&reference.vectors[o])
                        .map(|(p, q)| p * q)
                        .sum();
                    assert!((dot.abs() - 1.0).abs() < 1e-9, "{o}: {dot}");
                }
            }
        }
    }

    /// Householder and QL: `A v = λ v` with orthonormal vectors, and Jacobi's eigenvalues,
    /// on matrices of sizes 1 to 40 (one of them rank-deficient, as a Gram matrix of few
    /// rows is).
    #[test]
    fn householder_eigenpairs_satisfy_a_v_equals_lambda_v() {
        for n in [1usize, 2, 3, 7, 40] {
            let b: Vec<f64> = (0..n * n)
                .map(|v| (((v * 7919 + 13) % 97) as f64) / 48.0 - 1.0)
                .collect();
            // A = Bᵀ B over the first min(n, 3) rows of B: rank ≤ 3.
            let rows = n.min(3);
            let mut a = vec![0f64; n * n];
            for i in 0..n {
                for j in 0..n {
                    a[i * n + j] = (0..rows).map(|r| b[r * n + i] * b[r * n + j]).sum::<f64>()
                        + if n < 7 {
                            b[i.min(j) * n + i.max(j)]
                        } else {
                            0.0
                        };
                }
            }
            let (values, vectors) = symmetric_eigen_householder(a.clone(), n);
            let scale = a.iter().map(|x| x.abs()).fold(1f64, f64::max);
            for o in 0..n {
                for i in 0..n {
                    let av: f64 = (0..n).map(|j| a[i * n + j] * vectors[j * n + o]).sum();
                    assert!(
                        (av - values[o] * vectors[i * n + o]).abs() < 1e-12 * scale,
                        "{n} {o}"
                    );
                }
                for q in 0..n {
                    let dot: f64 = (0..n)
                        .map(|i| vectors[i * n + o] * vectors[i * n + q])
                        .sum();
                    let want = if o == q { 1.0 } else { 0.0 };
                    assert!((dot - want).abs() < 1e-12, "{n} {o} {q}");
                }
            }
            let mut ours = values.clone();
            let mut theirs = symmetric_eigen(a, n).0;
            ours.sort_by(f64::total_cmp);
            theirs.sort_by(f64::total_cmp);
            for (x, y) in ours.iter().zip(&theirs) {
                assert!((x - y).abs() < 1e-12 * scale, "{n}: {ours:?} {theirs:?}");
            }
        }
    }

    #[test]
    fn jacobi_diagonalises_a_known_matrix() {
        // [[2, 1], [1, 2]]: eigenvalues 1 and 3.
        let (values, vectors) = symmetric_eigen(vec![2.0, 1.0, 1.0, 2.0], 2);
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        assert!((sorted[0] - 1.0).abs() < 1e-12 && (sorted[1] - 3.0).abs() < 1e-12);
        // A v = λ v for each column.
        for j in 0..2 {
            let v = [vectors[j], vectors[2 + j]];
            let av = [2.0 * v[0] + v[1], v[0] + 2.0 * v[1]];
            assert!((av[0] - values[j] * v[0]).abs() < 1e-12);
            assert!((av[1] - values[j] * v[1]).abs() < 1e-12);
        }
    }
}
