//! The GEMM front end of the CPU op: row-major matrices and transposed views of them,
//! multiplied by the `gemm` crate (AVX-512 when the CPU has it), in parallel only where
//! that pays, and split along the inner dimension for the weight gradients.

use rayon::prelude::*;

use super::real::Real;

/// GEMMs smaller than this many multiply-adds run on the calling thread. Measured on
/// the 2-core AVX-512 machine: a `[3000, 128] × [128, 12]` product (4.6M) takes 0.12 ms
/// on one thread and 0.08 ms on two.
const PARALLEL_GEMM: usize = 1 << 21;

/// The weight gradients `Sᵀ G` reduce over the `4N` rows: a small output (`d_in × d_out`)
/// and a long inner dimension, which the GEMM's own splitting (over the output) serves
/// badly: `[128, 3000]ᵀ × [3000, 12]` took 0.26 ms on two threads against 0.13 ms on one.
/// Such products are split along the inner dimension instead, one part per thread, and
/// the partial products summed (0.07 ms). Used from this inner length on.
const SPLIT_K_FROM: usize = 512;

thread_local! {
    /// Whether this thread runs the op's GEMMs and row passes without splitting them.
    static SERIAL: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` with every GEMM and row pass it calls on this thread alone: for work that is
/// already split across the threads (the fused training step runs its two network calls
/// side by side), where splitting each GEMM again only adds scheduling.
pub(crate) fn serial<R>(f: impl FnOnce() -> R) -> R {
    let before = SERIAL.with(|s| s.replace(true));
    let out = f();
    SERIAL.with(|s| s.set(before));
    out
}

/// Whether this thread is inside [`serial`].
pub(crate) fn is_serial() -> bool {
    SERIAL.with(|s| s.get())
}

/// A row-major matrix, or a transposed view of one, as the GEMM reads it.
#[derive(Clone, Copy)]
pub(crate) struct Mat<'a, E> {
    data: &'a [E],
    rows: usize,
    cols: usize,
    transposed: bool,
}

impl<'a, E> Mat<'a, E> {
    pub(crate) fn new(data: &'a [E], rows: usize, cols: usize) -> Self {
        Mat {
            data,
            rows,
            cols,
            transposed: false,
        }
    }

    /// The transpose, without a copy.
    pub(crate) fn t(self) -> Self {
        Mat {
            transposed: !self.transposed,
            ..self
        }
    }

    /// Logical shape and (row, column) strides.
    fn layout(&self) -> (usize, usize, isize, isize) {
        let (r, c) = (self.rows, self.cols);
        if self.transposed {
            (c, r, 1, c as isize)
        } else {
            (r, c, c as isize, 1)
        }
    }
}

/// `dst = [dst +] a b` for a row-major `dst` of `a.rows × b.cols` (logical shapes).
pub(crate) fn gemm<E: Real>(dst: &mut [E], a: Mat<E>, b: Mat<E>, accumulate: bool) {
    let (m, k, _, _) = a.layout();
    let (k2, n, _, _) = b.layout();
    assert_eq!(k, k2, "GEMM inner dimensions");
    assert!(a.data.len() >= a.rows * a.cols && b.data.len() >= b.rows * b.cols);
    assert!(dst.len() >= m * n, "GEMM output too small");
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst[..m * n].fill(E::zero());
        }
        return;
    }
    if is_serial() {
        return serial_or_rayon_gemm(dst, a, b, accumulate, gemm::Parallelism::None);
    }
    let work = m.saturating_mul(n).saturating_mul(k);
    let threads = rayon::current_num_threads();
    if a.transposed && !b.transposed && k >= SPLIT_K_FROM && work >= PARALLEL_GEMM && threads > 1 {
        return split_k_gemm(dst, a, b, accumulate, threads);
    }
    let parallelism = if work >= PARALLEL_GEMM {
        gemm::Parallelism::Rayon(0)
    } else {
        gemm::Parallelism::None
    };
    serial_or_rayon_gemm(dst, a, b, accumulate, parallelism);
}

/// Rows `from..to` of a row-major matrix (columns `from..to` of its transpose).
fn rows_of<'a, E>(m: Mat<'a, E>, from: usize, to: usize) -> Mat<'a, E> {
    Mat {
        data: &m.data[from * m.cols..to * m.cols],
        rows: to - from,
        ..m
    }
}

/// `dst = [dst +] a b` with the inner dimension split into `parts` (see [`SPLIT_K_FROM`]);
/// `a` is a transposed view, so its inner dimension is its storage's rows.
fn split_k_gemm<E: Real>(dst: &mut [E], a: Mat<E>, b: Mat<E>, accumulate: bool, parts: usize) {
    let (m, k, _, _) = a.layout();
    let n = b.layout().1;
    let bounds: Vec<(usize, usize)> = (0..parts)
        .map(|p| (p * k / parts, (p + 1) * k / parts))
        .collect();
    let partials: Vec<Vec<E>> = bounds
        .par_iter()
        .map(|&(from, to)| {
            let mut part = E::pool().take(m * n);
            let (ap, bp) = (rows_of(a, from, to), rows_of(b, from, to));
            serial_or_rayon_gemm(&mut part, ap, bp, false, gemm::Parallelism::None);
            part
        })
        .collect();
    let dst = &mut dst[..m * n];
    for (p, part) in partials.into_iter().enumerate() {
        if p == 0 && !accumulate {
            dst.copy_from_slice(&part);
        } else {
            dst.iter_mut().zip(&part).for_each(|(d, v)| *d = *d + *v);
        }
        E::pool().give(part);
    }
}

/// One call of the `gemm` crate: `dst = [dst +] a b`.
fn serial_or_rayon_gemm<E: Real>(
    dst: &mut [E],
    a: Mat<E>,
    b: Mat<E>,
    accumulate: bool,
    parallelism: gemm::Parallelism,
) {
    let (m, k, a_rs, a_cs) = a.layout();
    let (_, n, b_rs, b_cs) = b.layout();
    assert!(a.data.len() >= a.rows * a.cols && b.data.len() >= b.rows * b.cols);
    assert!(dst.len() >= m * n, "GEMM output too small");
    // SAFETY: the asserts above bound every index the strides reach: `a` covers
    // `rows × cols` row-major elements (read through its own or transposed strides), so
    // does `b`, and `dst` holds `m × n` row-major elements. `dst` is a unique borrow.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            a.data.as_ptr(),
            a_cs,
            a_rs,
            b.data.as_ptr(),
            b_cs,
            b_rs,
            E::one(),
            E::one(),
            false,
            false,
            false,
            parallelism,
        );
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A small deterministic pseudo-random stream in [-1, 1).
    pub(crate) fn noise(len: usize, seed: u64) -> Vec<f64> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..len)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
            })
            .collect()
    }

    fn naive(a: &[f64], b: &[f64], m: usize, n: usize, k: usize, ta: bool, tb: bool) -> Vec<f64> {
        let at = |i: usize, p: usize| if ta { a[p * m + i] } else { a[i * k + p] };
        let bt = |p: usize, j: usize| if tb { b[j * k + p] } else { b[p * n + j] };
        let mut c = vec![0.0; m * n];
        for i in 0..m {
            for j in 0..n {
                c[i * n + j] = (0..k).map(|p| at(i, p) * bt(p, j)).sum();
            }
        }
        c
    }

    #[test]
    fn gemm_matches_the_naive_product_in_every_layout_and_split() {
        // 128 × 12 × 1500 with a transposed `a` takes the split-K path; 37 × 19 × 70 not.
        for (m, n, k) in [(128, 12, 1500), (37, 19, 70)] {
            for (ta, tb) in [(false, false), (true, false), (false, true), (true, true)] {
                let (a, b) = (noise(m * k, 1), noise(k * n, 2));
                let am = if ta {
                    Mat::new(&a[..], k, m).t()
                } else {
                    Mat::new(&a[..], m, k)
                };
                let bm = if tb {
                    Mat::new(&b[..], n, k).t()
                } else {
                    Mat::new(&b[..], k, n)
                };
                let want = naive(&a, &b, m, n, k, ta, tb);
                for accumulate in [false, true] {
                    let start = noise(m * n, 3);
                    let mut c = start.clone();
                    gemm(&mut c, am, bm, accumulate);
                    for i in 0..m * n {
                        let expect = want[i] + if accumulate { start[i] } else { 0.0 };
                        assert!(
                            (c[i] - expect).abs() < 1e-9 * (1.0 + expect.abs()),
                            "{m}x{n}x{k} ta={ta} tb={tb} acc={accumulate}: {} vs {expect}",
                            c[i]
                        );
                    }
                }
            }
        }
    }
}
