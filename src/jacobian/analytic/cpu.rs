//! The row kernels of the CPU SIREN op ([`super::net`]): one row of a sine layer's
//! activation or of its backward, values and tangents in one pass.
//!
//! Built from tensor primitives ([`super::forward`]) a layer costs about ten passes over
//! `[4N, d]` (slices, `sin`, `cos`, products, a concat), each with its own allocation;
//! at the synthetic protocol's sizes that per-op overhead costs more than the matmuls
//! (see the README's speed section). Here each direction is one pass.
//! In f32 the sine and cosine come from [`sin_cos_f32`], a branch-free polynomial that the
//! compiler vectorises (error below 1e-7 absolute for |z| < 10⁴); in f64 from `std`.

use super::net::Pool;

/// The float types the fused loops serve.
pub(crate) trait Real:
    Copy
    + Send
    + Sync
    + std::fmt::Debug
    + 'static
    + bytemuck::Pod
    + burn::tensor::Element
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
{
    fn from_f64(v: f64) -> Self;
    fn zero() -> Self;
    fn one() -> Self;
    fn sin_cos(self) -> (Self, Self);
    /// The workspaces of this type.
    fn pool() -> &'static Pool<Self>;
}

static POOL_F32: Pool<f32> = Pool::new();
static POOL_F64: Pool<f64> = Pool::new();

impl Real for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn zero() -> Self {
        0.0
    }
    fn one() -> Self {
        1.0
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        sin_cos_f32(self)
    }
    fn pool() -> &'static Pool<Self> {
        &POOL_F32
    }
}

impl Real for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
    fn zero() -> Self {
        0.0
    }
    fn one() -> Self {
        1.0
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        f64::sin_cos(self)
    }
    fn pool() -> &'static Pool<Self> {
        &POOL_F64
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
