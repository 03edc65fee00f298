//! The whole SIREN as one operation on raw CPU buffers: the input layer, the hidden sine
//! layers and the output layer, values and (for the dual path) the three spatial tangents,
//! with one hand-written backward for every weight and bias (DESIGN §2, paper Eq. 6).
//!
//! Written once on slices; flex and ndarray hand their contiguous buffers to it
//! ([`super::host`]). Per layer, the forward is one GEMM and one fused parallel pass, the
//! backward two GEMMs and one fused pass that also sums the bias gradient. The layout is
//! the stacked one of [`super::SirenBackend`]: `S = [h; ḣ_x; ḣ_y; ḣ_z]`, `[4N, d]`, so that
//! one GEMM serves the values and the tangents. Three things the per-layer composition
//! paid for are gone:
//! - the input seeds `e_x, e_y, e_z` are never built: the first layer's tangent
//!   pre-activations are the first three rows of its weight matrix, read in place, and
//!   their gradient is a column sum;
//! - no buffer is zero-filled and then overwritten, and no `cat`/`slice` copies are made:
//!   the saved activations and the backward's temporaries come from a [`Pool`] of
//!   workspaces that is filled on the first step and reused afterwards;
//! - no autodiff node per layer: the whole network is one node.

use std::sync::Mutex;

use rayon::prelude::*;

use super::cpu::{
    Real, dual_backward_row, dual_forward_row, plain_backward_row, plain_forward_row,
};

/// Rows per parallel task: large enough that splitting costs nothing measurable.
const ROWS_PER_TASK: usize = 64;

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

/// Free workspaces of one float type, reused between steps so that steady-state steps
/// neither allocate nor zero-fill the per-layer buffers.
pub(crate) struct Pool<E> {
    free: Mutex<Vec<Vec<E>>>,
}

/// At most this many idle workspaces are kept (a step of the default SIREN uses about 12).
const POOL_CAPACITY: usize = 64;

impl<E: Real> Pool<E> {
    pub(crate) const fn new() -> Self {
        Pool {
            free: Mutex::new(Vec::new()),
        }
    }

    /// A buffer of `len` elements whose contents are unspecified (but initialised).
    fn take(&self, len: usize) -> Vec<E> {
        let found = {
            let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
            // The smallest free buffer that holds `len` without wasting more than half.
            let best = free
                .iter()
                .enumerate()
                .filter(|(_, v)| v.capacity() >= len && v.capacity() <= 2 * len.max(1))
                .min_by_key(|(_, v)| v.capacity())
                .map(|(i, _)| i);
            best.map(|i| free.swap_remove(i))
        };
        match found {
            Some(mut v) => {
                if v.len() >= len {
                    v.truncate(len);
                } else {
                    v.resize(len, E::zero());
                }
                v
            }
            None => vec![E::zero(); len],
        }
    }

    fn give(&self, v: Vec<E>) {
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        if free.len() < POOL_CAPACITY {
            free.push(v);
        }
    }
}

/// One layer's parameters, row-major: `w` is `[d_in, d_out]` (Burn's `Linear` layout).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layer<'a, E> {
    pub w: &'a [E],
    pub b: &'a [E],
    pub d_in: usize,
    pub d_out: usize,
}

/// What the backward needs from the forward: for each sine layer `l`, its pre-activation
/// `Z_l = S_{l-1} W_l` (the first layer's without tangent rows, which are `W_0`'s first
/// rows) and its output `S_l`.
#[derive(Debug)]
pub(crate) struct Activations<E: Real> {
    z: Vec<Vec<E>>,
    s: Vec<Vec<E>>,
}

impl<E: Real> Drop for Activations<E> {
    fn drop(&mut self) {
        for v in self.z.drain(..).chain(self.s.drain(..)) {
            E::pool().give(v);
        }
    }
}

/// A row-major matrix, or a transposed view of one, as the GEMM reads it.
#[derive(Clone, Copy)]
struct Mat<'a, E> {
    data: &'a [E],
    rows: usize,
    cols: usize,
    transposed: bool,
}

impl<'a, E> Mat<'a, E> {
    fn new(data: &'a [E], rows: usize, cols: usize) -> Self {
        Mat {
            data,
            rows,
            cols,
            transposed: false,
        }
    }

    /// The transpose, without a copy.
    fn t(self) -> Self {
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
fn gemm<E: Real>(dst: &mut [E], a: Mat<E>, b: Mat<E>, accumulate: bool) {
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

/// Where a sine layer's tangent pre-activations `ż_k / ω` come from.
#[derive(Clone, Copy)]
enum Tangents<'a, E> {
    /// The first layer: row `k` of `W_0`, the same for every point (`e_k W_0`).
    Seed(&'a [E]),
    /// A later layer: blocks `1..4` of its stacked pre-activation `Z` (`[4N, d]`).
    Stacked(&'a [E]),
}

impl<'a, E: Real> Tangents<'a, E> {
    /// Row `r` of tangent `k` (`d` wide), for `n` points.
    #[inline(always)]
    fn row(&self, k: usize, r: usize, n: usize, d: usize) -> &'a [E] {
        match *self {
            Tangents::Seed(w) => &w[k * d..(k + 1) * d],
            Tangents::Stacked(z) => {
                let at = (k + 1) * n * d + r * d;
                &z[at..at + d]
            }
        }
    }
}

/// Splits `buf` (`blocks × n × d`) into its blocks and each block into chunks of
/// `ROWS_PER_TASK` rows; item `c` holds chunk `c` of every block.
fn block_chunks<E: Send>(
    buf: &mut [E],
    blocks: usize,
    n: usize,
    d: usize,
) -> impl IndexedParallelIterator<Item = (usize, Vec<&mut [E]>)> {
    let chunk = ROWS_PER_TASK * d;
    let mut per_block: Vec<Vec<&mut [E]>> = buf[..blocks * n * d]
        .chunks_mut((n * d).max(1))
        .map(|b| b.chunks_mut(chunk.max(1)).collect())
        .collect();
    let n_chunks = n.div_ceil(ROWS_PER_TASK);
    let mut items: Vec<Vec<&mut [E]>> = (0..n_chunks).map(|_| Vec::with_capacity(blocks)).collect();
    for block in per_block.iter_mut() {
        for (c, part) in block.drain(..).enumerate() {
            items[c].push(part);
        }
    }
    items.into_par_iter().enumerate()
}

/// The sine activation of one layer: `S = [sin z; ω cos z ⊙ Z_k]` with `z = ω(Z_0 + b)`
/// (dual), or `sin z` (values only). `z` holds the value rows first.
fn activate<E: Real>(
    z: &[E],
    tangents: Option<Tangents<E>>,
    b: &[E],
    omega: E,
    n: usize,
    d: usize,
) -> Vec<E> {
    let blocks = if tangents.is_some() { 4 } else { 1 };
    let mut out = E::pool().take(blocks * n * d);
    block_chunks(&mut out, blocks, n, d).for_each(|(c, mut parts)| {
        let rows = parts[0].len() / d;
        for i in 0..rows {
            let r = c * ROWS_PER_TASK + i;
            let o = i * d..(i + 1) * d;
            let zr = &z[r * d..(r + 1) * d];
            match tangents {
                Some(t) => {
                    let [h, h0, h1, h2] = &mut parts[..] else {
                        unreachable!("four blocks")
                    };
                    dual_forward_row::run::<E>(
                        omega,
                        zr,
                        b,
                        t.row(0, r, n, d),
                        t.row(1, r, n, d),
                        t.row(2, r, n, d),
                        &mut h[o.clone()],
                        &mut h0[o.clone()],
                        &mut h1[o.clone()],
                        &mut h2[o],
                    );
                }
                None => plain_forward_row::run::<E>(omega, zr, b, &mut parts[0][o]),
            }
        }
    });
    out
}

/// The backward of [`activate`]: from the upstream gradient `g` (same layout as `S`), the
/// gradient with respect to `Z` (same layout), and the column sums of each of its blocks
/// (`blocks × d`), summed in the same pass.
fn activate_backward<E: Real>(
    z: &[E],
    tangents: Option<Tangents<E>>,
    b: &[E],
    g: &[E],
    omega: E,
    n: usize,
    d: usize,
) -> (Vec<E>, Vec<E>) {
    let blocks = if tangents.is_some() { 4 } else { 1 };
    let mut out = E::pool().take(blocks * n * d);
    // Each chunk's column sums, collected in chunk order and added up in that order, so
    // that the result does not depend on how rayon split the work (a `reduce` would).
    let partials: Vec<Vec<E>> = block_chunks(&mut out, blocks, n, d)
        .map(|(c, mut parts)| {
            let rows = parts[0].len() / d;
            for i in 0..rows {
                let r = c * ROWS_PER_TASK + i;
                let o = i * d..(i + 1) * d;
                let zr = &z[r * d..(r + 1) * d];
                let gr = |k: usize| &g[k * n * d + r * d..k * n * d + (r + 1) * d];
                match tangents {
                    Some(t) => {
                        let [gz, g0, g1, g2] = &mut parts[..] else {
                            unreachable!("four blocks")
                        };
                        let zk = [t.row(0, r, n, d), t.row(1, r, n, d), t.row(2, r, n, d)];
                        dual_backward_row::run::<E>(
                            omega,
                            zr,
                            b,
                            gr(0),
                            zk,
                            [gr(1), gr(2), gr(3)],
                            &mut gz[o.clone()],
                            &mut g0[o.clone()],
                            &mut g1[o.clone()],
                            &mut g2[o],
                        );
                    }
                    None => plain_backward_row::run::<E>(omega, zr, b, gr(0), &mut parts[0][o]),
                }
            }
            let mut sums = vec![E::zero(); blocks * d];
            for (k, part) in parts.iter().enumerate() {
                column_sums(part, d, &mut sums[k * d..(k + 1) * d]);
            }
            sums
        })
        .collect();
    let mut sums = vec![E::zero(); blocks * d];
    for part in &partials {
        sums.iter_mut().zip(part).for_each(|(a, b)| *a = *a + *b);
    }
    (out, sums)
}

/// `acc += Σ_rows m` for a row-major `m` of width `d`.
fn column_sums<E: Real>(m: &[E], d: usize, acc: &mut [E]) {
    let acc = &mut acc[..d];
    for row in m.chunks_exact(d) {
        acc.iter_mut().zip(row).for_each(|(a, v)| *a = *a + *v);
    }
}

/// The SIREN at `x` (`[n, c]`, row-major; tangents seeded on its first three columns when
/// `dual`): the output `[n, O]`, or `[4n, O]` stacked values and tangents, and the
/// activations the backward needs. `layers` are the sine layers, then the output layer.
pub(crate) fn forward<E: Real>(
    x: &[E],
    n: usize,
    layers: &[Layer<E>],
    omega: f64,
    dual: bool,
) -> (Vec<E>, Activations<E>) {
    let (out_layer, sine) = layers.split_last().expect("a SIREN has an output layer");
    assert!(!sine.is_empty(), "a SIREN has a sine layer");
    let blocks = if dual { 4 } else { 1 };
    let w = E::from_f64(omega);
    let mut acts = Activations {
        z: Vec::with_capacity(sine.len()),
        s: Vec::with_capacity(sine.len()),
    };
    for (l, layer) in sine.iter().enumerate() {
        let d = layer.d_out;
        let (input, rows) = match l {
            0 => (x, n),
            _ => (&acts.s[l - 1][..], blocks * n),
        };
        let mut z = E::pool().take(rows * d);
        gemm(
            &mut z,
            Mat::new(input, rows, layer.d_in),
            Mat::new(layer.w, layer.d_in, d),
            false,
        );
        let tangents = dual.then_some(match l {
            0 => Tangents::Seed(layer.w),
            _ => Tangents::Stacked(&z),
        });
        let s = activate(&z, tangents, layer.b, w, n, d);
        acts.z.push(z);
        acts.s.push(s);
    }
    let (d, o) = (out_layer.d_in, out_layer.d_out);
    let mut out = vec![E::zero(); blocks * n * o];
    let last = acts.s.last().expect("a sine layer's output");
    gemm(
        &mut out,
        Mat::new(last, blocks * n, d),
        Mat::new(out_layer.w, d, o),
        false,
    );
    // The bias moves the values only.
    for row in out[..n * o].chunks_exact_mut(o) {
        row.iter_mut()
            .zip(out_layer.b)
            .for_each(|(v, b)| *v = *v + *b);
    }
    (out, acts)
}

/// Splits a buffer laid out like the parameters, `[W_0, b_0, …, W_o, b_o]` flattened, into
/// each layer's `(W, b)`.
pub(crate) fn split_layers<'a, E>(
    mut flat: &'a mut [E],
    shapes: &[[usize; 2]],
) -> Vec<(&'a mut [E], &'a mut [E])> {
    shapes
        .iter()
        .map(|&[d_in, d_out]| {
            let (w, rest) = std::mem::take(&mut flat).split_at_mut(d_in * d_out);
            let (b, rest) = rest.split_at_mut(d_out);
            flat = rest;
            (w, b)
        })
        .collect()
}

/// The gradients of a loss whose gradient with respect to [`forward`]'s output is `g_out`:
/// every layer's `(g_W, g_b)` written into `g_params` (laid out like the parameters, see
/// [`split_layers`]), and `g_x` when `input_grad`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward<E: Real>(
    acts: &Activations<E>,
    x: &[E],
    n: usize,
    layers: &[Layer<E>],
    omega: f64,
    dual: bool,
    g_out: &[E],
    input_grad: bool,
    g_params: &mut [E],
) -> Option<Vec<E>> {
    let (out_layer, sine) = layers.split_last().expect("a SIREN has an output layer");
    assert!(!sine.is_empty(), "a SIREN has a sine layer");
    let blocks = if dual { 4 } else { 1 };
    let w = E::from_f64(omega);
    let shapes: Vec<[usize; 2]> = layers.iter().map(|l| [l.d_in, l.d_out]).collect();
    let mut slots = split_layers(g_params, &shapes);

    // Output layer: g_b = Σ value rows, g_W = S_Lᵀ G, g_S = G W_oᵀ.
    let (d, o) = (out_layer.d_in, out_layer.d_out);
    let (g_w, g_b) = slots.pop().expect("the output layer's slot");
    g_b.fill(E::zero());
    column_sums(&g_out[..n * o], o, g_b);
    let last = acts.s.last().expect("a sine layer's output");
    gemm(
        g_w,
        Mat::new(last, blocks * n, d).t(),
        Mat::new(g_out, blocks * n, o),
        false,
    );
    let mut g_s = E::pool().take(blocks * n * d);
    gemm(
        &mut g_s,
        Mat::new(g_out, blocks * n, o),
        Mat::new(out_layer.w, d, o).t(),
        false,
    );

    let mut g_x = None;
    for (l, layer) in sine.iter().enumerate().rev() {
        let (d_in, d) = (layer.d_in, layer.d_out);
        let (g_w, g_b) = slots.pop().expect("a sine layer's slot");
        let tangents = dual.then_some(match l {
            0 => Tangents::Seed(layer.w),
            _ => Tangents::Stacked(&acts.z[l]),
        });
        let (g_z, sums) = activate_backward(&acts.z[l], tangents, layer.b, &g_s, w, n, d);
        E::pool().give(std::mem::take(&mut g_s));
        g_b.copy_from_slice(&sums[..d]);
        if l > 0 {
            gemm(
                g_w,
                Mat::new(&acts.s[l - 1], blocks * n, d_in).t(),
                Mat::new(&g_z, blocks * n, d),
                false,
            );
            g_s = E::pool().take(blocks * n * d_in);
            gemm(
                &mut g_s,
                Mat::new(&g_z, blocks * n, d),
                Mat::new(layer.w, d_in, d).t(),
                false,
            );
        } else {
            // The input's tangent rows are the seeds e_k: their part of g_W is the column
            // sum of each tangent block, added to row k.
            gemm(
                g_w,
                Mat::new(x, n, d_in).t(),
                Mat::new(&g_z[..n * d], n, d),
                false,
            );
            if dual {
                for k in 0..3 {
                    let row = &mut g_w[k * d..(k + 1) * d];
                    let s = &sums[(k + 1) * d..(k + 2) * d];
                    row.iter_mut().zip(s).for_each(|(a, b)| *a = *a + *b);
                }
            }
            if input_grad {
                let mut gx = vec![E::zero(); n * d_in];
                gemm(
                    &mut gx,
                    Mat::new(&g_z[..n * d], n, d),
                    Mat::new(layer.w, d_in, d).t(),
                    false,
                );
                g_x = Some(gx);
            }
        }
        E::pool().give(g_z);
    }
    g_x
}

/// The layers over a flat parameter buffer `[W_0, b_0, …, W_o, b_o]` of the given
/// `[d_in, d_out]` shapes.
pub(crate) fn layers_of<'a, E>(mut flat: &'a [E], shapes: &[[usize; 2]]) -> Vec<Layer<'a, E>> {
    shapes
        .iter()
        .map(|&[d_in, d_out]| {
            let (w, rest) = flat.split_at(d_in * d_out);
            let (b, rest) = rest.split_at(d_out);
            flat = rest;
            Layer { w, b, d_in, d_out }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic pseudo-random stream in [-1, 1).
    fn noise(len: usize, seed: u64) -> Vec<f64> {
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

    /// `g_x` of the dual op (values and tangents) against central finite differences of
    /// `Σ R ⊙ out` in f64; the parameters' gradients are checked the same way, through
    /// the public API, in `tests/analytic_f64.rs`.
    #[test]
    fn input_gradient_matches_finite_differences() {
        let (n, omega) = (5, 3.0);
        let shapes = [[4, 8], [8, 8], [8, 3]];
        let flat = noise(shapes.iter().map(|[i, o]| i * o + o).sum(), 4);
        let layers = layers_of(&flat, &shapes);
        let x = noise(n * 4, 5);
        for dual in [false, true] {
            let rows = if dual { 4 * n } else { n };
            let r = noise(rows * 3, 6);
            let loss = |x: &[f64]| -> f64 {
                let (out, _) = forward(x, n, &layers, omega, dual);
                out.iter().zip(&r).map(|(a, b)| a * b).sum()
            };
            let (_, acts) = forward(&x, n, &layers, omega, dual);
            let mut g_params = vec![0.0; flat.len()];
            let g_x = backward(&acts, &x, n, &layers, omega, dual, &r, true, &mut g_params)
                .expect("asked for g_x");
            let h = 1e-6;
            for i in 0..x.len() {
                let (mut up, mut down) = (x.clone(), x.clone());
                up[i] += h;
                down[i] -= h;
                let fd = (loss(&up) - loss(&down)) / (2.0 * h);
                assert!(
                    (g_x[i] - fd).abs() < 1e-6 * (1.0 + fd.abs()),
                    "dual={dual} x[{i}]: {} vs {fd}",
                    g_x[i]
                );
            }
        }
    }

    /// The bias and first-layer gradients are sums over chunks of rows computed in
    /// parallel: they must not depend on how rayon splits the work, or fits stop being
    /// reproducible (a `reduce` made the same fit end 1e-4 apart from run to run).
    #[test]
    fn the_backward_is_bitwise_reproducible_across_runs() {
        let (n, omega) = (1000, 30.0);
        let shapes = [[4, 32], [32, 32], [32, 12]];
        let flat: Vec<f32> = noise(shapes.iter().map(|[i, o]| i * o + o).sum(), 7)
            .iter()
            .map(|&v| 0.1 * v as f32)
            .collect();
        let layers = layers_of(&flat, &shapes);
        let x: Vec<f32> = noise(n * 4, 8).iter().map(|&v| v as f32).collect();
        let g: Vec<f32> = noise(4 * n * 12, 9).iter().map(|&v| v as f32).collect();
        let run = || {
            let (_, acts) = forward(&x, n, &layers, omega, true);
            let mut g_params = vec![0.0f32; flat.len()];
            backward(&acts, &x, n, &layers, omega, true, &g, false, &mut g_params);
            g_params
        };
        let first = run();
        for _ in 0..20 {
            let again = run();
            assert!(
                first
                    .iter()
                    .zip(&again)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "the gradients changed between two runs"
            );
        }
    }

    #[test]
    fn no_points_give_empty_outputs_and_zero_gradients() {
        let shapes = [[4, 8], [8, 8], [8, 3]];
        let flat = noise(shapes.iter().map(|[i, o]| i * o + o).sum(), 4);
        let layers = layers_of(&flat, &shapes);
        for dual in [false, true] {
            let (out, acts) = forward(&[], 0, &layers, 30.0, dual);
            assert!(out.is_empty());
            let mut g = vec![1.0; flat.len()];
            let g_x = backward(&acts, &[], 0, &layers, 30.0, dual, &[], true, &mut g);
            assert_eq!(g_x.map(|v| v.len()), Some(0));
            assert!(g.iter().all(|&v| v == 0.0), "no points, no gradient");
        }
    }

    #[test]
    fn the_pool_reuses_a_returned_buffer() {
        let pool = Pool::<f64>::new();
        let v = pool.take(1000);
        let ptr = v.as_ptr();
        pool.give(v);
        let again = pool.take(900);
        assert_eq!(again.as_ptr(), ptr, "a fitting free buffer is reused");
        assert_eq!(again.len(), 900);
        let other = pool.take(5000);
        assert_ne!(other.as_ptr(), ptr);
        assert_eq!(other.len(), 5000);
    }
}
