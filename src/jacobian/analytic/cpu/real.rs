//! The float types of the CPU op and their workspaces: [`Real`] (f32 and f64), the
//! [`Pool`] of reused buffers, and a vectorisable f32 sine and cosine. A leaf: the GEMM,
//! the row kernels and the network build on it.

use std::sync::Mutex;

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
    pub(crate) fn take(&self, len: usize) -> Vec<E> {
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

    pub(crate) fn give(&self, v: Vec<E>) {
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        if free.len() < POOL_CAPACITY {
            free.push(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{Pool, sin_cos_f32};

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
