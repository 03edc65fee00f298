//! The flex implementation of the elementwise parts of [`super::SirenBackend`]: one fused
//! pass over raw buffers per layer and direction, split across threads by rows.
//!
//! Built from tensor primitives ([`super::forward`]) a layer costs about ten passes over
//! `[4N, d]` (slices, `sin`, `cos`, products, a concat), each with its own allocation;
//! at the synthetic protocol's sizes that per-op overhead costs more than the matmuls
//! (see the README's speed section). Here each direction is one allocation and one pass.
//! In f32 the sine and cosine come from [`sin_cos_f32`], a branch-free polynomial that the
//! compiler vectorises (error below 1e-7 absolute for |z| < 10⁴); in f64 from `std`.

use burn::backend::Flex;
use burn::backend::TensorMetadata;
use burn::backend::flex::FlexTensor;
use burn::tensor::DType;
use burn::tensor::TensorData;
use rayon::prelude::*;

use super::forward;

/// Rows per parallel task: large enough that splitting costs nothing measurable.
const ROWS_PER_TASK: usize = 64;

/// The float types the fused loops serve.
pub(crate) trait Real:
    Copy
    + Send
    + Sync
    + bytemuck::Pod
    + burn::tensor::Element
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
{
    fn from_f64(v: f64) -> Self;
    fn zero() -> Self;
    fn sin_cos(self) -> (Self, Self);
}

impl Real for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn zero() -> Self {
        0.0
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        sin_cos_f32(self)
    }
}

impl Real for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
    fn zero() -> Self {
        0.0
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        f64::sin_cos(self)
    }
}

/// `(sin x, cos x)` in f32 without branches: Cody–Waite reduction by π/2 in three parts,
/// then the minimax polynomials of Cephes' `sinf`/`cosf` on [−π/4, π/4], and the quadrant
/// picked by selects.
#[inline(always)]
#[allow(clippy::excessive_precision)] // Cephes' coefficients, as published.
pub fn sin_cos_f32(x: f32) -> (f32, f32) {
    const FRAC_2_PI: f32 = std::f32::consts::FRAC_2_PI;
    // π/2 = P1 + P2 + P3, each short enough that k·P1 is exact for |k| < 2¹².
    const P1: f32 = 1.570_312_5;
    const P2: f32 = 4.837_512_969_970_703e-4;
    const P3: f32 = 7.549_789_948_768_648e-8;
    // Round to nearest by the 1.5·2²³ trick: `f32::round` is a libm call on baseline x86-64.
    const SHIFT: f32 = 12_582_912.0;
    let shifted = x * FRAC_2_PI + SHIFT;
    let k = shifted - SHIFT;
    let r = ((x - k * P1) - k * P2) - k * P3;
    let r2 = r * r;
    let s = r + r * r2 * (-1.666_665_46e-1 + r2 * (8.332_160_87e-3 + r2 * -1.951_529_59e-4));
    let c =
        1.0 - 0.5 * r2 + r2 * r2 * (4.166_664_57e-2 + r2 * (-1.388_731_6e-3 + r2 * 2.443_315_7e-5));
    // sin x = [s, c, −s, −c][q], cos x = [c, −s, −c, s][q] for the quadrant q = k mod 4;
    // selects and sign-bit flips, so that the loop around this vectorises.
    // After the shift, k's low bits are the mantissa's low bits (no float→int conversion,
    // which is a saturating, slow-to-vectorise cast in Rust).
    let q = shifted.to_bits();
    let odd = q & 1 != 0;
    let (sin, cos) = (if odd { c } else { s }, if odd { s } else { c });
    let sin_sign = (q & 2) << 30;
    let cos_sign = (q.wrapping_add(1) & 2) << 30;
    (
        f32::from_bits(sin.to_bits() ^ sin_sign),
        f32::from_bits(cos.to_bits() ^ cos_sign),
    )
}

/// Defines a row kernel `$name::run` compiled three times (baseline, AVX2+FMA and
/// AVX-512) and picked at run time: the crate is built for baseline x86-64 (4-wide SSE), and
/// the sine/cosine loops run 2–4× faster on the wider units.
macro_rules! simd_kernel {
    ($name:ident, ($($arg:ident : $ty:ty),* $(,)?), $body:block) => {
        #[allow(clippy::too_many_arguments)] // one slice per block of the stacked matrix
        mod $name {
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

            pub(super) fn run<E: Real>($($arg: $ty),*) {
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

/// A contiguous view of `t`'s elements (copying only when `t` is strided).
fn contiguous(t: FlexTensor) -> FlexTensor {
    if t.layout().contiguous_offsets().is_some() {
        t
    } else {
        FlexTensor::from_data(t.into_data())
    }
}

fn slice<E: Real>(t: &FlexTensor) -> &[E] {
    t.as_slice::<E>()
        .expect("a contiguous tensor of the matching dtype")
}

/// `[sin z; cos z ⊙ ż]` with `z = ω(zs[0..N] + b)`, `ż = ω zs[N..4N]`. Other dtypes than
/// f32 and f64 take the primitive path.
pub fn activation(zs: FlexTensor, bias: FlexTensor, omega: f64) -> FlexTensor {
    match zs.dtype() {
        DType::F32 => activation_typed::<f32>(&zs, &bias, omega),
        DType::F64 => activation_typed::<f64>(&zs, &bias, omega),
        _ => forward::activation::<Flex>(zs, bias, omega),
    }
}

/// A fresh `[4N, d]` stacked output, filled in parallel: `row(at, [h, ḣ_x, ḣ_y, ḣ_z])` gets
/// the offset `at` of one row inside a block and that row of each of the four blocks.
fn stacked_rows<E: Real>(
    n: usize,
    d: usize,
    row: impl Fn(usize, [&mut [E]; 4]) + Sync,
) -> FlexTensor {
    let nd = n * d;
    let mut out = vec![E::zero(); 4 * nd];
    let (top, tangents) = out.split_at_mut(nd);
    let (t0, rest) = tangents.split_at_mut(nd);
    let (t1, t2) = rest.split_at_mut(nd);
    let chunk = ROWS_PER_TASK * d;
    top.par_chunks_mut(chunk)
        .zip(t0.par_chunks_mut(chunk))
        .zip(t1.par_chunks_mut(chunk))
        .zip(t2.par_chunks_mut(chunk))
        .enumerate()
        .for_each(|(c, (((h, h0), h1), h2))| {
            for r in 0..h.len() / d {
                let o = r * d..(r + 1) * d;
                row(
                    c * chunk + r * d,
                    [
                        &mut h[o.clone()],
                        &mut h0[o.clone()],
                        &mut h1[o.clone()],
                        &mut h2[o],
                    ],
                );
            }
        });
    FlexTensor::from_data(TensorData::new(out, [4 * n, d]))
}

fn activation_typed<E: Real>(zs: &FlexTensor, bias: &FlexTensor, omega: f64) -> FlexTensor {
    let [r, d] = zs.shape().dims::<2>();
    let (n, nd) = (r / 4, r / 4 * d);
    let (zs, bias) = (contiguous(zs.clone()), contiguous(bias.clone()));
    let (zv, b) = (slice::<E>(&zs), slice::<E>(&bias));
    let w = E::from_f64(omega);
    stacked_rows::<E>(n, d, |at, [h, h0, h1, h2]| {
        let zp = |k: usize| &zv[k * nd + at..k * nd + at + d];
        dual_forward_row::run::<E>(w, zp(0), b, zp(1), zp(2), zp(3), h, h0, h1, h2);
    })
}

/// The gradient with respect to `zs`:
/// `ω [g_h ⊙ cos z − sin z ⊙ Σ_k g_ḣ,k ⊙ ż_k ; g_ḣ ⊙ cos z]`.
pub fn activation_backward(
    zs: FlexTensor,
    bias: FlexTensor,
    grad: FlexTensor,
    omega: f64,
) -> FlexTensor {
    match zs.dtype() {
        DType::F32 => backward_typed::<f32>(&zs, &bias, &grad, omega),
        DType::F64 => backward_typed::<f64>(&zs, &bias, &grad, omega),
        _ => forward::activation_backward::<Flex>(zs, bias, grad, omega),
    }
}

fn backward_typed<E: Real>(
    zs: &FlexTensor,
    bias: &FlexTensor,
    grad: &FlexTensor,
    omega: f64,
) -> FlexTensor {
    let [r, d] = zs.shape().dims::<2>();
    let (n, nd) = (r / 4, r / 4 * d);
    let (zs, bias, grad) = (
        contiguous(zs.clone()),
        contiguous(bias.clone()),
        contiguous(grad.clone()),
    );
    let (zv, b, g) = (slice::<E>(&zs), slice::<E>(&bias), slice::<E>(&grad));
    let w = E::from_f64(omega);
    stacked_rows::<E>(n, d, |at, [gz, g0, g1, g2]| {
        let zp = |k: usize| &zv[k * nd + at..k * nd + at + d];
        let gp = |k: usize| &g[k * nd + at..k * nd + at + d];
        let (zk, gk) = ([zp(1), zp(2), zp(3)], [gp(1), gp(2), gp(3)]);
        dual_backward_row::run::<E>(w, zp(0), b, gp(0), zk, gk, gz, g0, g1, g2);
    })
}

/// The value-only layer: `sin(ω(zs + b))`.
pub fn plain_activation(zs: FlexTensor, bias: FlexTensor, omega: f64) -> FlexTensor {
    match zs.dtype() {
        DType::F32 => plain_typed::<f32>(&zs, &bias, None, omega),
        DType::F64 => plain_typed::<f64>(&zs, &bias, None, omega),
        _ => forward::plain_activation::<Flex>(zs, bias, omega),
    }
}

/// Its backward: `ω g ⊙ cos(ω(zs + b))`.
pub fn plain_activation_backward(
    zs: FlexTensor,
    bias: FlexTensor,
    grad: FlexTensor,
    omega: f64,
) -> FlexTensor {
    match zs.dtype() {
        DType::F32 => plain_typed::<f32>(&zs, &bias, Some(&grad), omega),
        DType::F64 => plain_typed::<f64>(&zs, &bias, Some(&grad), omega),
        _ => forward::plain_activation_backward::<Flex>(zs, bias, grad, omega),
    }
}

/// `sin(ω(zs + b))`, or with `grad`, `ω g ⊙ cos(ω(zs + b))`.
fn plain_typed<E: Real>(
    zs: &FlexTensor,
    bias: &FlexTensor,
    grad: Option<&FlexTensor>,
    omega: f64,
) -> FlexTensor {
    let [r, d] = zs.shape().dims::<2>();
    let (zs, bias) = (contiguous(zs.clone()), contiguous(bias.clone()));
    let grad = grad.map(|g| contiguous(g.clone()));
    let (zv, b) = (slice::<E>(&zs), slice::<E>(&bias));
    let g = grad.as_ref().map(slice::<E>);
    let w = E::from_f64(omega);
    let mut out = vec![E::zero(); r * d];
    let chunk = ROWS_PER_TASK * d;
    out.par_chunks_mut(chunk).enumerate().for_each(|(c, o)| {
        for (row, o) in o.chunks_mut(d).enumerate() {
            let at = c * chunk + row * d;
            let z = &zv[at..at + d];
            match g {
                None => plain_forward_row::run::<E>(w, z, b, o),
                Some(g) => plain_backward_row::run::<E>(w, z, b, &g[at..at + d], o),
            }
        }
    });
    FlexTensor::from_data(TensorData::new(out, [r, d]))
}

#[cfg(test)]
mod tests {
    use super::sin_cos_f32;

    #[test]
    fn fast_sin_cos_matches_std() {
        let mut worst: f64 = 0.0;
        let mut x = -2000.0f32;
        while x < 2000.0 {
            let (s, c) = sin_cos_f32(x);
            let (es, ec) = (x as f64).sin_cos();
            worst = worst.max((s as f64 - es).abs()).max((c as f64 - ec).abs());
            x += 0.0137;
        }
        assert!(worst < 3e-7, "worst absolute error {worst:e}");
    }
}
