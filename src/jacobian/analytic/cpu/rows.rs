//! The sine passes of the CPU op: a layer's activation and its backward over all rows, in
//! parallel chunks of rows, each row values and tangents in one pass, by row kernels
//! compiled for three instruction sets and picked at run time.
//!
//! Built from tensor primitives ([`crate::jacobian::analytic::reference`]) a layer costs
//! about ten passes over `[4N, d]` (slices, `sin`, `cos`, products, a concat), each with its
//! own allocation; at the synthetic protocol's sizes that per-op overhead costs more than
//! the matmuls (docs/speed.md). Here each direction is one pass. In f32 the sine and cosine
//! come from [`super::real::sin_cos_f32`], a branch-free polynomial that the compiler
//! vectorises (error below 1e-7 absolute for |z| < 10⁴); in f64 from `std`.

use rayon::prelude::*;

use super::gemm::is_serial;
use super::real::Real;

/// Rows per parallel task: large enough that splitting costs nothing measurable.
const ROWS_PER_TASK: usize = 64;

/// Defines a row kernel `$name::run` compiled three times (baseline, AVX2+FMA and
/// AVX-512) and picked at run time: the crate is built for baseline x86-64 (4-wide SSE), and
/// the sine/cosine loops run 2–4× faster on the wider units.
macro_rules! simd_kernel {
    ($name:ident, ($($arg:ident : $ty:ty),* $(,)?), $body:block) => {
        #[allow(clippy::too_many_arguments)] // one slice per block of the stacked matrix
        pub(crate) mod $name {
            #[allow(unused_imports)]
            use super::*;

            #[inline(always)]
            fn portable<E: Real>($($arg: $ty),*) $body

            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
            fn v4<E: Real>($($arg: $ty),*) {
                portable::<E>($($arg),*)
            }

            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            fn v3<E: Real>($($arg: $ty),*) {
                portable::<E>($($arg),*)
            }

            pub(crate) fn run<E: Real>($($arg: $ty),*) {
                #[cfg(target_arch = "x86_64")]
                {
                    if std::arch::is_x86_feature_detected!("avx512f")
                        && std::arch::is_x86_feature_detected!("avx512vl")
                        && std::arch::is_x86_feature_detected!("avx512dq")
                        && std::arch::is_x86_feature_detected!("avx512bw")
                    {
                        // SAFETY: the CPU has every feature `v4` is compiled for.
                        return unsafe { v4::<E>($($arg),*) };
                    }
                    if std::arch::is_x86_feature_detected!("avx2")
                        && std::arch::is_x86_feature_detected!("fma")
                    {
                        // SAFETY: as above, for `v3`.
                        return unsafe { v3::<E>($($arg),*) };
                    }
                }
                portable::<E>($($arg),*)
            }
        }
    };
}

// One row of the dual forward: h = sin z, ḣ_k = ω cos z · zs_k, z = ω(zs + b).
simd_kernel!(dual_forward_row, (
    w: E, z: &[E], b: &[E], z0: &[E], z1: &[E], z2: &[E],
    h: &mut [E], h0: &mut [E], h1: &mut [E], h2: &mut [E],
), {
    let d = z.len();
    // Equal-length slices, so that the loop has no bounds checks and vectorises.
    let (b, z0, z1, z2) = (&b[..d], &z0[..d], &z1[..d], &z2[..d]);
    let (h, h0, h1, h2) = (&mut h[..d], &mut h0[..d], &mut h1[..d], &mut h2[..d]);
    for j in 0..d {
        let (s, co) = (w * (z[j] + b[j])).sin_cos();
        h[j] = s;
        let wc = w * co;
        h0[j] = wc * z0[j];
        h1[j] = wc * z1[j];
        h2[j] = wc * z2[j];
    }
});

// One row of the dual backward (see `activation_backward`).
simd_kernel!(dual_backward_row, (
    w: E, z: &[E], b: &[E], gh: &[E], zk: [&[E]; 3], gk: [&[E]; 3],
    gz: &mut [E], g0: &mut [E], g1: &mut [E], g2: &mut [E],
), {
    let d = z.len();
    let (b, gh) = (&b[..d], &gh[..d]);
    let (z0, z1, z2) = (&zk[0][..d], &zk[1][..d], &zk[2][..d]);
    let (k0, k1, k2) = (&gk[0][..d], &gk[1][..d], &gk[2][..d]);
    let (gz, g0, g1, g2) = (&mut gz[..d], &mut g0[..d], &mut g1[..d], &mut g2[..d]);
    for j in 0..d {
        let (s, co) = (w * (z[j] + b[j])).sin_cos();
        // ż_k = ω zs_k, so Σ_k g_ḣ,k ż_k = ω Σ_k g_ḣ,k zs_k.
        let mixed = k0[j] * z0[j] + k1[j] * z1[j] + k2[j] * z2[j];
        gz[j] = w * (gh[j] * co - s * w * mixed);
        let wc = w * co;
        g0[j] = wc * k0[j];
        g1[j] = wc * k1[j];
        g2[j] = wc * k2[j];
    }
});

// One row of the value-only layer: sin(ω(zs + b)).
simd_kernel!(plain_forward_row, (w: E, z: &[E], b: &[E], o: &mut [E]), {
    let d = z.len();
    let (b, o) = (&b[..d], &mut o[..d]);
    for j in 0..d {
        o[j] = (w * (z[j] + b[j])).sin_cos().0;
    }
});

// One row of its backward: ω g cos(ω(zs + b)).
simd_kernel!(plain_backward_row, (w: E, z: &[E], b: &[E], g: &[E], o: &mut [E]), {
    let d = z.len();
    let (b, g, o) = (&b[..d], &g[..d], &mut o[..d]);
    for j in 0..d {
        o[j] = w * g[j] * (w * (z[j] + b[j])).sin_cos().1;
    }
});

/// Where a sine layer's tangent pre-activations `ż_k / ω` come from.
#[derive(Clone, Copy)]
pub(crate) enum Tangents<'a, E> {
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
    // Inside `serial`, one task: no split, so the chunks run on the calling thread.
    let min_len = if is_serial() { usize::MAX } else { 1 };
    items.into_par_iter().enumerate().with_min_len(min_len)
}

/// The sine activation of one layer: `S = [sin z; ω cos z ⊙ Z_k]` with `z = ω(Z_0 + b)`
/// (dual), or `sin z` (values only). `z` holds the value rows first.
pub(crate) fn activate<E: Real>(
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
pub(crate) fn activate_backward<E: Real>(
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
pub(crate) fn column_sums<E: Real>(m: &[E], d: usize, acc: &mut [E]) {
    let acc = &mut acc[..d];
    for row in m.chunks_exact(d) {
        acc.iter_mut().zip(row).for_each(|(a, v)| *a = *a + *v);
    }
}
