//! The small dense solvers: the natural cubic spline's tridiagonal system, the
//! least squares on the simplex that weighs a blend, and the Gram matrix of a PCA (the
//! eigenproblems are in `eigen.rs`). Plain `f64` arithmetic on slices and fixed-size
//! arrays, no tensors.

// Index loops over small matrices read as the algebra they implement.
#![allow(clippy::needless_range_loop)]

/// The rows [`column_gram`] holds at once: enough that four rows of the Gram matrix are
/// read from memory once for many rows of `x`, few enough that those rows stay in cache.
const GRAM_BLOCK: usize = 32;

/// `Xᵀ X` (`[d, d]`, row-major) of the rows of `x` (each `d` long). Each entry sums over
/// the rows in their order; the rows are taken 32 at a time and four rows of
/// the result are updated together, so that a matrix far larger than a cache is read once
/// per block rather than once per row of `x`.
pub fn column_gram<R: AsRef<[f64]>>(rows: impl IntoIterator<Item = R>, d: usize) -> Vec<f64> {
    let mut g = vec![0f64; d * d];
    let mut rows = rows.into_iter();
    let mut block: Vec<R> = Vec::with_capacity(GRAM_BLOCK);
    loop {
        block.clear();
        block.extend(rows.by_ref().take(GRAM_BLOCK));
        if block.is_empty() {
            break;
        }
        gram_block(&mut g, &block, d);
    }
    for a in 0..d {
        for b in 0..a {
            g[a * d + b] = g[b * d + a];
        }
    }
    g
}

/// Adds the upper triangle of `Xᵀ X` over the rows of `block` to `g`.
fn gram_block<R: AsRef<[f64]>>(g: &mut [f64], block: &[R], d: usize) {
    let mut a = 0;
    while a + 4 <= d {
        let (g0, rest) = g[a * d..(a + 4) * d].split_at_mut(d);
        let (g1, rest) = rest.split_at_mut(d);
        let (g2, g3) = rest.split_at_mut(d);
        for row in block {
            let x = &row.as_ref()[..d];
            let (x0, x1, x2, x3) = (x[a], x[a + 1], x[a + 2], x[a + 3]);
            // The triangle's corner, then the four rows side by side.
            g0[a] += x0 * x0;
            g0[a + 1] += x0 * x1;
            g0[a + 2] += x0 * x2;
            g0[a + 3] += x0 * x3;
            g1[a + 1] += x1 * x1;
            g1[a + 2] += x1 * x2;
            g1[a + 3] += x1 * x3;
            g2[a + 2] += x2 * x2;
            g2[a + 3] += x2 * x3;
            g3[a + 3] += x3 * x3;
            let tail = a + 4..d;
            let rows = g0[tail.clone()]
                .iter_mut()
                .zip(&mut g1[tail.clone()])
                .zip(&mut g2[tail.clone()])
                .zip(&mut g3[tail.clone()]);
            for ((((e0, e1), e2), e3), &xb) in rows.zip(&x[tail]) {
                *e0 += x0 * xb;
                *e1 += x1 * xb;
                *e2 += x2 * xb;
                *e3 += x3 * xb;
            }
        }
        a += 4;
    }
    for a in a..d {
        let ga = &mut g[a * d + a..(a + 1) * d];
        for row in block {
            let x = row.as_ref();
            let xa = x[a];
            for (entry, &xb) in ga.iter_mut().zip(&x[a..d]) {
                *entry += xa * xb;
            }
        }
    }
}

/// The column Gram matrix of a tall matrix `[t, d]` whose entries change in place, kept
/// up to date change by change: `S = Σ (x − o)(x − o)ᵀ` about a fixed origin `o` (the
/// first column means, so that nothing large cancels) and `Σ (x − o)`. The centred Gram
/// `Σ (x − m)(x − m)ᵀ = S − t (m − o)(m − o)ᵀ` then costs `d²` where a fresh one costs
/// `t d²`: a round of the iterative PCA changes a few columns of some rows.
pub struct MovingGram {
    origin: Vec<f64>,
    gram: Vec<f64>,
    /// `Σ δ zᵀ` over the rows changed since [`MovingGram::centred`] last folded it into
    /// `gram` (as `C + Cᵀ`): each change adds one row of it per changed column, in order.
    changes: Vec<f64>,
    sum: Vec<f64>,
    rows: usize,
    /// The changed row's `z`, kept to spare an allocation per row.
    midpoint: Vec<f64>,
}

impl MovingGram {
    /// The Gram matrix of `x` (`[t, d]`, row-major).
    pub fn new(x: &[f64], d: usize) -> MovingGram {
        let rows = x.len() / d.max(1);
        let mut origin = vec![0f64; d];
        for row in x.chunks(d) {
            for (o, v) in origin.iter_mut().zip(row) {
                *o += v / rows as f64;
            }
        }
        let shifted =
            |row: &[f64]| -> Vec<f64> { row.iter().zip(&origin).map(|(v, o)| v - o).collect() };
        let gram = column_gram(x.chunks(d).map(shifted), d);
        let mut sum = vec![0f64; d];
        for row in x.chunks(d) {
            for ((s, v), o) in sum.iter_mut().zip(row).zip(&origin) {
                *s += v - o;
            }
        }
        MovingGram {
            origin,
            gram,
            changes: vec![0f64; d * d],
            sum,
            rows,
            midpoint: Vec::with_capacity(d),
        }
    }

    /// A row changes from `old` to `new` (each `d` long), in the columns of `changed` only
    /// (each named once).
    /// With `δ = new − old` and the midpoint `z = (old + new) / 2 − o`,
    /// `(new − o)(new − o)ᵀ − (old − o)(old − o)ᵀ = δ zᵀ + z δᵀ`: only the rows of `δ zᵀ`
    /// at the changed columns are added now, each a contiguous row.
    pub fn change_row(&mut self, old: &[f64], new: &[f64], changed: &[usize]) {
        let d = self.origin.len();
        self.midpoint.clear();
        self.midpoint.extend(
            old.iter()
                .zip(new)
                .zip(&self.origin)
                .map(|((x, y), o)| 0.5 * (x + y) - o),
        );
        for &a in changed {
            let delta = new[a] - old[a];
            let row = &mut self.changes[a * d..(a + 1) * d];
            for (c, z) in row.iter_mut().zip(&self.midpoint) {
                *c += delta * z;
            }
            self.sum[a] += delta;
        }
    }

    /// The column means and the centred Gram matrix `[d, d]`.
    pub fn centred(&mut self) -> (Vec<f64>, Vec<f64>) {
        let d = self.origin.len();
        for a in 0..d {
            for b in 0..d {
                self.gram[a * d + b] += self.changes[a * d + b] + self.changes[b * d + a];
            }
        }
        self.changes.fill(0.0);
        let t = self.rows.max(1) as f64;
        let shift: Vec<f64> = self.sum.iter().map(|s| s / t).collect();
        let mean = self.origin.iter().zip(&shift).map(|(o, s)| o + s).collect();
        let mut g = self.gram.clone();
        for a in 0..d {
            for b in 0..d {
                g[a * d + b] -= t * shift[a] * shift[b];
            }
        }
        (mean, g)
    }
}

/// The second derivatives of the natural cubic spline through `(x, y)` (0 at both ends),
/// by the tridiagonal (Thomas) solve.
pub fn natural_second_derivatives(x: &[f64], y: &[f64]) -> Vec<f64> {
    let n = x.len();
    let mut m = vec![0f64; n];
    if n < 3 {
        return m;
    }
    // Rows 1..n-1: h[j-1] m[j-1] + 2 (h[j-1] + h[j]) m[j] + h[j] m[j+1] = 6 (slope_j − slope_{j-1}).
    let h: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    let mut diag = vec![0f64; n];
    let mut rhs = vec![0f64; n];
    for j in 1..n - 1 {
        diag[j] = 2.0 * (h[j - 1] + h[j]);
        rhs[j] = 6.0 * ((y[j + 1] - y[j]) / h[j] - (y[j] - y[j - 1]) / h[j - 1]);
    }
    for j in 2..n - 1 {
        let w = h[j - 1] / diag[j - 1];
        diag[j] -= w * h[j - 1];
        rhs[j] -= w * rhs[j - 1];
    }
    for j in (1..n - 1).rev() {
        m[j] = (rhs[j] - h[j] * m[j + 1]) / diag[j];
    }
    m
}

/// The spline of [`natural_second_derivatives`] at `v` in `[x[j], x[j+1]]`.
pub fn spline_at(x: &[f64], y: &[f64], m: &[f64], j: usize, v: f64) -> f64 {
    let h = x[j + 1] - x[j];
    let (a, b) = ((x[j + 1] - v) / h, (v - x[j]) / h);
    a * y[j] + b * y[j + 1] + ((a * a * a - a) * m[j] + (b * b * b - b) * m[j + 1]) * h * h / 6.0
}

/// The weights `w ≥ 0`, `Σ w = 1` that minimise `wᵀ E w`, for `E` the Gram matrix of the
/// fillers' errors, with weight only on the fillers whose bits are set in `allowed`: the
/// exact minimum over every support within it (at most 2^M − 1), each solved with its
/// equality constraint by the KKT system `[E_S 1; 1ᵀ 0] [w; λ] = [0; 1]`. All zeros when
/// `allowed` holds none of the `M`.
pub fn simplex_least_squares<const M: usize>(e: &[[f64; M]; M], allowed: u32) -> [f64; M] {
    let mut best = ([0f64; M], f64::INFINITY);
    for support in (1u32..(1 << M)).filter(|s| s & !allowed == 0) {
        let idx: Vec<usize> = (0..M).filter(|&m| support & (1 << m) != 0).collect();
        let s = idx.len();
        // The KKT system, (s + 1) × (s + 1), augmented with its right-hand side.
        let mut a = vec![vec![0f64; s + 2]; s + 1];
        for (r, &m) in idx.iter().enumerate() {
            for (c, &l) in idx.iter().enumerate() {
                a[r][c] = e[m][l];
            }
            a[r][s] = 1.0;
        }
        for c in 0..s {
            a[s][c] = 1.0;
        }
        a[s][s + 1] = 1.0;
        let Some(x) = solve(a) else { continue };
        if x[..s].iter().any(|&w| w < -1e-12 || !w.is_finite()) {
            continue;
        }
        let mut w = [0f64; M];
        for (r, &m) in idx.iter().enumerate() {
            w[m] = x[r].max(0.0);
        }
        let total: f64 = w.iter().sum();
        w.iter_mut().for_each(|v| *v /= total);
        let objective = quadratic(&w, e);
        // Ties go to the support found first (lower indices before higher).
        if objective < best.1 * (1.0 - 1e-12) {
            best = (w, objective);
        }
    }
    best.0
}

/// `wᵀ E w`.
pub fn quadratic<const M: usize>(w: &[f64; M], e: &[[f64; M]; M]) -> f64 {
    (0..M)
        .flat_map(|m| (0..M).map(move |l| (m, l)))
        .map(|(m, l)| w[m] * e[m][l] * w[l])
        .sum()
}

/// Gaussian elimination with partial pivoting on an augmented `m × (m + 1)` system; `None`
/// if it is singular.
fn solve(mut a: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    let m = a.len();
    let scale = a
        .iter()
        .flat_map(|r| r[..m].iter())
        .fold(0f64, |s, v| s.max(v.abs()));
    for col in 0..m {
        let pivot = (col..m).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[pivot][col].abs() <= 1e-12 * scale {
            return None;
        }
        a.swap(col, pivot);
        for r in 0..m {
            if r != col {
                let f = a[r][col] / a[col][col];
                if f != 0.0 {
                    for c in col..=m {
                        a[r][c] -= f * a[col][c];
                    }
                }
            }
        }
    }
    Some((0..m).map(|r| a[r][m] / a[r][r]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every entry is the sum over the rows in their order, to the bit, whatever the
    /// column count (four rows of the result at a time, and the rest) and the row count
    /// (blocks of rows, and a last partial one).
    #[test]
    fn the_gram_matrix_sums_each_entry_over_the_rows_in_order() {
        for d in [1usize, 3, 4, 5, 8, 11] {
            for rows in [1usize, GRAM_BLOCK - 1, GRAM_BLOCK, 2 * GRAM_BLOCK + 5] {
                let x: Vec<f64> = (0..rows * d)
                    .map(|v| ((v * 7919 + 13) % 101) as f64 / 7.0 - 6.5)
                    .collect();
                let g = column_gram(x.chunks(d).map(<[f64]>::to_vec), d);
                for a in 0..d {
                    for b in 0..d {
                        let want = (0..rows).fold(0.0, |s, r| s + x[r * d + a] * x[r * d + b]);
                        assert_eq!(g[a * d + b].to_bits(), want.to_bits(), "{d} {rows} {a} {b}");
                    }
                }
            }
        }
    }

    /// After rounds of changes to a few entries of some rows (large offsets, as marker
    /// coordinates in millimetres carry), the moving Gram matrix and means are a fresh
    /// centred Gram matrix's to round-off.
    #[test]
    fn a_moving_gram_matrix_is_the_fresh_one_after_rows_change() {
        let (t, d) = (40, 7);
        let mut x: Vec<f64> = (0..t * d)
            .map(|v| 1000.0 * (v % d) as f64 + ((v * 7919 + 13) % 101) as f64 / 7.0)
            .collect();
        let mut moving = MovingGram::new(&x, d);
        for round in 0..5 {
            for k in (round..t).step_by(3) {
                let changed = [(k + round) % d, (k + round + 3) % d];
                let old = x[k * d..(k + 1) * d].to_vec();
                let mut new = old.clone();
                for &a in &changed {
                    new[a] += ((k * 31 + a * 17 + round) % 13) as f64 - 6.0;
                }
                moving.change_row(&old, &new, &changed);
                x[k * d..(k + 1) * d].copy_from_slice(&new);
            }
            // The changes are folded in between rounds, as the iterative PCA reads them.
            if round % 2 == 1 {
                moving.centred();
            }
        }
        let mean: Vec<f64> = (0..d)
            .map(|a| (0..t).map(|k| x[k * d + a]).sum::<f64>() / t as f64)
            .collect();
        let centred =
            |row: &[f64]| -> Vec<f64> { row.iter().zip(&mean).map(|(v, m)| v - m).collect() };
        let fresh = column_gram(x.chunks(d).map(centred), d);
        let (m, g) = moving.centred();
        // Folding the changes in twice changes nothing.
        assert_eq!(moving.centred().1, g);
        for a in 0..d {
            assert!(
                (m[a] - mean[a]).abs() < 1e-9,
                "{a}: {} vs {}",
                m[a],
                mean[a]
            );
        }
        let scale = fresh.iter().fold(0f64, |s, v| s.max(v.abs()));
        for (e, (p, q)) in g.iter().zip(&fresh).enumerate() {
            assert!((p - q).abs() < 1e-10 * scale, "{e}: {p} vs {q}");
        }
    }

    #[test]
    fn natural_spline_values_match_a_hand_solved_case() {
        // Knots (0,0), (1,1), (2,0): m1 = 6·(−1 − 1)/(2·2) = −3, so at 0.5:
        // 0.5·0 + 0.5·1 + (0.125 − 0.5)·(−3)/6 = 0.5 + 0.1875.
        let (x, y) = ([0.0, 1.0, 2.0], [0.0, 1.0, 0.0]);
        let m = natural_second_derivatives(&x, &y);
        assert_eq!(m, vec![0.0, -3.0, 0.0]);
        assert!((spline_at(&x, &y, &m, 0, 0.5) - 0.6875).abs() < 1e-12);
    }

    #[test]
    fn the_simplex_minimum_matches_hand_solved_cases() {
        const M: usize = 6;
        // Independent errors of variances 1, 4 and 100: the weights are the inverse
        // variances, normalised: (1, 1/4, 1/100, 1/100, 1/100, 1/100) / 1.29.
        let mut e = [[0f64; M]; M];
        e[0][0] = 1.0;
        e[1][1] = 4.0;
        for m in 2..M {
            e[m][m] = 100.0;
        }
        let w = simplex_least_squares(&e, u32::MAX);
        let want = [1.0, 0.25, 0.01, 0.01, 0.01, 0.01].map(|v| v / 1.29);
        for m in 0..M {
            assert!((w[m] - want[m]).abs() < 1e-12, "{w:?}");
        }
        // A filler that is exact takes the whole weight.
        let mut e = [[1f64; M]; M];
        for m in 0..M {
            e[m][m] = 2.0;
        }
        for l in 0..M {
            e[3][l] = 0.0;
            e[l][3] = 0.0;
        }
        let w = simplex_least_squares(&e, u32::MAX);
        assert_eq!(w, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        // Without filler 3, the other five share the weight equally: wᵀ E w = 1 + 1/5.
        let w = simplex_least_squares(&e, !(1 << 3));
        for m in [0, 1, 2, 4, 5] {
            assert!((w[m] - 0.2).abs() < 1e-12, "{w:?}");
        }
        assert_eq!(w[3], 0.0);
        assert_eq!(simplex_least_squares(&e, 0), [0.0; M]);
        // Perfectly anti-correlated errors cancel: (1, −1) → (0.5, 0.5) with zero error,
        // which a negative weight elsewhere cannot improve on.
        let mut e = [[0f64; M]; M];
        e[0][0] = 1.0;
        e[1][1] = 1.0;
        e[0][1] = -1.0;
        e[1][0] = -1.0;
        for m in 2..M {
            e[m][m] = 3.0;
        }
        let w = simplex_least_squares(&e, u32::MAX);
        assert!(
            (w[0] - 0.5).abs() < 1e-12 && (w[1] - 0.5).abs() < 1e-12,
            "{w:?}"
        );
        assert!(w[2..].iter().all(|&v| v == 0.0), "{w:?}");
    }
}
