//! The leading eigenvectors of a symmetric matrix alone: the eigenvalues from the
//! tridiagonal form, then an eigenvector for each one asked for, by inverse iteration on
//! the tridiagonal (LAPACK's `dstein`) carried back through the Householder reflections.
//! Gløersen's fill keeps the components that reach 99 % of the singular values' sum, a
//! fifth of them or fewer on a marker set, and on a large set (hundreds of columns) the
//! full eigenvector matrix is most of its cost.

use std::ops::Range;

use super::{gram_of, implicit_ql, singular_values, transpose, tridiagonalize, wide_vector};

/// The eigenvalues of a symmetric matrix, and the eigenvector of any of them on demand.
pub struct Eigensystem {
    n: usize,
    /// The eigenvalues, unsorted: bit for bit those of
    /// [`symmetric_eigen_householder`](super::symmetric_eigen_householder).
    pub values: Vec<f64>,
    diagonal: Vec<f64>,
    /// `below[i]`: the tridiagonal's entry at `(i + 1, i)`.
    below: Vec<f64>,
    /// Row `i` up to `i`: the Householder vector that reduced row `i`.
    reflectors: Vec<f64>,
    /// Each reflector's `uᵀu / 2` (0: none).
    halves: Vec<f64>,
}

/// Iterations of inverse iteration per eigenvector: each multiplies the error by the
/// eigenvalue's error over its distance to the next, about `ε` where they are apart.
const INVERSE_ITERATIONS: usize = 3;

/// Eigenvalues closer than this share of the tridiagonal's norm are one cluster, whose
/// eigenvectors are kept orthogonal to each other (`dstein`'s `ORTOL`).
const CLUSTER: f64 = 1e-3;

impl Eigensystem {
    /// `a` (`[n, n]`, row-major, symmetric) reduced to tridiagonal form and its eigenvalues
    /// found, `O(n³)` for the reduction and `O(n²)` for the values.
    pub fn new(a: Vec<f64>, n: usize) -> Eigensystem {
        let mut reflectors = transpose(&a, n);
        drop(a);
        let (mut halves, mut e) = (vec![0f64; n], vec![0f64; n]);
        tridiagonalize(&mut reflectors, n, &mut halves, &mut e);
        let diagonal: Vec<f64> = (0..n).map(|j| reflectors[j * n + j]).collect();
        let below = e.iter().skip(1).copied().collect();
        let mut values = diagonal.clone();
        if n > 0 {
            e[0] = 0.0;
            implicit_ql(&mut values, &mut e, |_, _, _| {});
        }
        Eigensystem {
            n,
            values,
            diagonal,
            below,
            reflectors,
            halves,
        }
    }

    /// The unit eigenvectors of `values[o]` for each `o` of `which` (distinct), in that
    /// order: `O(n²)` each. Those of eigenvalues in one cluster (closer than 10⁻³ of the
    /// matrix's norm) are made orthogonal to each other; the sign of each is its
    /// algorithm's.
    pub fn vectors(&self, which: &[usize]) -> Vec<Vec<f64>> {
        let n = self.n;
        let norm = (0..n)
            .map(|i| {
                let left = if i > 0 { self.below[i - 1].abs() } else { 0.0 };
                let right = if i + 1 < n { self.below[i].abs() } else { 0.0 };
                self.diagonal[i].abs() + left + right
            })
            .fold(0f64, f64::max);
        let tiny = (f64::EPSILON * norm).max(f64::MIN_POSITIVE);
        // By eigenvalue, so that a cluster's members are neighbours.
        let mut order: Vec<usize> = (0..which.len()).collect();
        order.sort_by(|&a, &b| self.values[which[a]].total_cmp(&self.values[which[b]]));
        let mut out: Vec<Vec<f64>> = vec![Vec::new(); which.len()];
        let (mut cluster, mut previous): (Vec<usize>, Option<f64>) = (Vec::new(), None);
        for &slot in &order {
            let mut lambda = self.values[which[slot]];
            match previous {
                Some(p) if lambda - p <= CLUSTER * norm => {
                    // Equal eigenvalues would give equal factors: move this one apart.
                    let apart = 10.0 * f64::EPSILON * lambda.abs().max(tiny);
                    lambda = lambda.max(p + apart);
                }
                _ => cluster.clear(),
            }
            previous = Some(lambda);
            let lu = ShiftedLu::new(&self.diagonal, &self.below, lambda, tiny);
            let mut z = start(n, which[slot]);
            for _ in 0..INVERSE_ITERATIONS {
                lu.solve(&mut z);
                for &other in &cluster {
                    let v: &Vec<f64> = &out[other];
                    let dot: f64 = v.iter().zip(&z).map(|(a, b)| a * b).sum();
                    for (x, a) in z.iter_mut().zip(v) {
                        *x -= dot * a;
                    }
                }
                let length = z.iter().map(|x| x * x).sum::<f64>().sqrt();
                if length > 0.0 {
                    z.iter_mut().for_each(|x| *x /= length);
                }
            }
            out[slot] = z;
            cluster.push(slot);
        }
        // Back through the reflections once all are found (the orthogonalisation above
        // is of the tridiagonal's vectors).
        self.back_transform(&mut out);
        out
    }

    /// `z ← Q z` for each `z`, `Q` the product of the reduction's reflections
    /// (`A = Q T Qᵀ`): each reflection applied to every vector in turn, read once.
    fn back_transform(&self, vectors: &mut [Vec<f64>]) {
        let n = self.n;
        for i in 1..n {
            let h = self.halves[i];
            if h != 0.0 {
                let u = &self.reflectors[i * n..i * n + i];
                for z in vectors.iter_mut() {
                    let f = u.iter().zip(&z[..i]).map(|(a, b)| a * b).sum::<f64>() / h;
                    for (x, a) in z[..i].iter_mut().zip(u) {
                        *x -= f * a;
                    }
                }
            }
        }
    }
}

/// A start vector for inverse iteration, fixed by `seed` (so every run gives the same
/// vectors), its entries spread over (−1, 1).
fn start(n: usize, seed: usize) -> Vec<f64> {
    let mut state = (seed as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0x2545_f491_4f6c_dd1d;
    (0..n)
        .map(|_| {
            // SplitMix64.
            state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut x = state;
            x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            x ^= x >> 31;
            (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        })
        .collect()
}

/// `T − λ I` for a symmetric tridiagonal `T`, factored with partial pivoting (LAPACK's
/// `dgttrf`), its pivots no smaller than `tiny` so that an eigenvalue's shift solves.
struct ShiftedLu {
    lower: Vec<f64>,
    diagonal: Vec<f64>,
    upper: Vec<f64>,
    upper2: Vec<f64>,
    swapped: Vec<bool>,
}

impl ShiftedLu {
    fn new(diagonal: &[f64], below: &[f64], lambda: f64, tiny: f64) -> ShiftedLu {
        let n = diagonal.len();
        let mut d: Vec<f64> = diagonal.iter().map(|x| x - lambda).collect();
        let (mut dl, mut du) = (below.to_vec(), below.to_vec());
        let mut du2 = vec![0f64; n.saturating_sub(2)];
        let mut swapped = vec![false; n.saturating_sub(1)];
        let floor = |x: f64| if x.abs() < tiny { tiny.copysign(x) } else { x };
        for i in 0..n.saturating_sub(1) {
            if d[i].abs() >= dl[i].abs() {
                d[i] = floor(d[i]);
                let fact = dl[i] / d[i];
                dl[i] = fact;
                d[i + 1] -= fact * du[i];
            } else {
                let fact = d[i] / dl[i];
                d[i] = dl[i];
                dl[i] = fact;
                let temp = du[i];
                du[i] = d[i + 1];
                d[i + 1] = temp - fact * d[i + 1];
                if i + 2 < n {
                    du2[i] = du[i + 1];
                    du[i + 1] *= -fact;
                }
                swapped[i] = true;
            }
        }
        if let Some(last) = d.last_mut() {
            *last = floor(*last);
        }
        ShiftedLu {
            lower: dl,
            diagonal: d,
            upper: du,
            upper2: du2,
            swapped,
        }
    }

    /// `b ← (T − λ I)⁻¹ b` (`dgttrs`).
    fn solve(&self, b: &mut [f64]) {
        let n = b.len();
        for i in 0..n.saturating_sub(1) {
            if self.swapped[i] {
                let temp = b[i];
                b[i] = b[i + 1];
                b[i + 1] = temp - self.lower[i] * b[i];
            } else {
                b[i + 1] -= self.lower[i] * b[i];
            }
        }
        for i in (0..n).rev() {
            let mut x = b[i];
            if i + 1 < n {
                x -= self.upper[i] * b[i + 1];
            }
            if i + 2 < n {
                x -= self.upper2[i] * b[i + 2];
            }
            b[i] = x / self.diagonal[i];
        }
    }
}

/// The principal components of `x` as [`principal_components`](super::principal_components)
/// gives them (the same singular values, bit for bit), with the vectors of any number of
/// the leading ones found on demand ([`Spectrum::vectors`]).
pub struct Spectrum<'a> {
    x: &'a [f64],
    rows: usize,
    cols: usize,
    zeroed: Range<usize>,
    system: Eigensystem,
    /// The eigenvalues' indices, largest first, `min(rows, cols)` of them.
    order: Vec<usize>,
    /// The singular values, largest first.
    pub singular: Vec<f64>,
}

/// [`Spectrum`] of `x` (`rows × cols`, row-major, `rows ≥ 2`) with the columns `zeroed`
/// set to 0: `O(n³ + n²)` for `n = min(rows, cols)` where the whole analysis takes about
/// five times the `n³`.
pub fn principal_spectrum(
    x: &[f64],
    rows: usize,
    cols: usize,
    zeroed: Option<Range<usize>>,
) -> Spectrum<'_> {
    let zeroed = zeroed.unwrap_or(0..0);
    let (n, gram) = gram_of(x, rows, cols, &zeroed);
    let system = Eigensystem::new(gram, n);
    let (order, singular) = singular_values(&system.values, rows, cols);
    Spectrum {
        x,
        rows,
        cols,
        zeroed,
        system,
        order,
        singular,
    }
}

impl Spectrum<'_> {
    /// The right singular vectors of the `k` largest singular values (`vectors[j][c]`:
    /// component `j`'s loading on column `c`), each up to sign.
    pub fn vectors(&self, k: usize) -> Vec<Vec<f64>> {
        let which = &self.order[..k.min(self.order.len())];
        let found = self.system.vectors(which);
        if self.rows >= self.cols {
            found
        } else {
            found
                .iter()
                .map(|u| wide_vector(self.x, self.rows, self.cols, &self.zeroed, u))
                .collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{principal_components, symmetric_eigen_householder};
    use super::*;

    /// A symmetric `[n, n]` matrix `Bᵀ B` of rank `rank`, and one with a cluster of three
    /// equal eigenvalues and one of two close ones, as a Gram matrix of markers that move
    /// together has.
    fn matrices(n: usize) -> Vec<Vec<f64>> {
        let b: Vec<f64> = (0..n * n)
            .map(|v| (((v * 7919 + 13) % 97) as f64) / 48.0 - 1.0)
            .collect();
        let gram = |rank: usize| -> Vec<f64> {
            let mut a = vec![0f64; n * n];
            for i in 0..n {
                for j in 0..n {
                    a[i * n + j] = (0..rank).map(|r| b[r * n + i] * b[r * n + j]).sum();
                }
            }
            a
        };
        // Q diag(λ) Qᵀ with Q from the eigenvectors of a full-rank Gram matrix.
        let (_, q) = symmetric_eigen_householder(gram(n), n);
        let lambda: Vec<f64> = (0..n)
            .map(|i| match i {
                0..=2 => 5.0,
                3 => 4.0,
                4 => 4.0 + 1e-9,
                _ => 1.0 / (i as f64 + 1.0),
            })
            .collect();
        let mut clustered = vec![0f64; n * n];
        for i in 0..n {
            for j in 0..n {
                clustered[i * n + j] = (0..n)
                    .map(|o| q[i * n + o] * lambda[o] * q[j * n + o])
                    .sum();
            }
        }
        vec![gram(n.min(4)), gram(n), clustered]
    }

    /// The eigenvalues are the full solver's bit for bit; each vector asked for satisfies
    /// `A v = λ v`, and those asked for together are orthonormal, in clusters too.
    #[test]
    fn leading_eigenvectors_by_inverse_iteration_are_eigenvectors() {
        for n in [1usize, 2, 3, 9, 40] {
            for a in matrices(n) {
                let (values, _) = symmetric_eigen_householder(a.clone(), n);
                let system = Eigensystem::new(a.clone(), n);
                assert_eq!(system.values, values, "{n}");
                let mut by_size: Vec<usize> = (0..n).collect();
                by_size.sort_by(|&x, &y| values[y].total_cmp(&values[x]));
                let which = &by_size[..n.min(7)];
                let vectors = system.vectors(which);
                let scale = a.iter().map(|x| x.abs()).fold(1f64, f64::max);
                for (v, &o) in vectors.iter().zip(which) {
                    for i in 0..n {
                        let av: f64 = (0..n).map(|j| a[i * n + j] * v[j]).sum();
                        assert!(
                            (av - values[o] * v[i]).abs() < 1e-11 * scale,
                            "{n} {o}: {av}"
                        );
                    }
                }
                for (p, u) in vectors.iter().enumerate() {
                    for (q, v) in vectors.iter().enumerate() {
                        let dot: f64 = u.iter().zip(v).map(|(a, b)| a * b).sum();
                        let want = if p == q { 1.0 } else { 0.0 };
                        assert!((dot - want).abs() < 1e-10, "{n} {p} {q}: {dot}");
                    }
                }
            }
        }
    }

    /// The leading components on demand span what the whole analysis gives, tall and wide,
    /// with and without zeroed columns: the projections on the first `k` agree.
    #[test]
    fn a_spectrum_s_leading_components_are_the_whole_analysis_s() {
        for (rows, cols) in [(30, 12), (5, 12)] {
            let x: Vec<f64> = (0..rows * cols)
                .map(|v| ((v * 7919) % 101) as f64 / 50.0 - 1.0)
                .collect();
            for zeroed in [None, Some(3..6)] {
                let whole = principal_components(&x, rows, cols, zeroed.clone());
                let spectrum = principal_spectrum(&x, rows, cols, zeroed);
                assert_eq!(spectrum.singular, whole.singular);
                let k = 4;
                let ours = spectrum.vectors(k);
                for i in 0..cols {
                    for j in 0..cols {
                        let p = |v: &[Vec<f64>]| (0..k).map(|o| v[o][i] * v[o][j]).sum::<f64>();
                        let (a, b) = (p(&ours), p(&whole.vectors));
                        assert!((a - b).abs() < 1e-10, "{rows}x{cols} ({i}, {j}): {a} {b}");
                    }
                }
            }
        }
    }
}
