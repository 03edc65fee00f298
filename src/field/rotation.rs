//! The 6-D rotation representation (Zhou et al. 2019) and its Gram–Schmidt map to SO(3),
//! with the exact layout of the authors' code (docs/reference.md §2.1), written on duals so
//! that its Jacobian comes out in forward mode.

use crate::dual::Dual;
use std::ops::{Mul, Sub};

/// The smallest norm that [`normalize`] divides by (PyTorch's `F.normalize` default).
pub const NORM_EPS: f64 = 1e-12;

/// The dot product of two `[N, 3]` duals, `[N, 1]`.
pub fn dot(a: Dual, b: Dual) -> Dual {
    a.mul(b).sum_channels()
}

/// `v / max(‖v‖, 1e-12)` for `v: [N, 3]`.
pub fn normalize(v: Dual) -> Dual {
    let inv_norm = dot(v.clone(), v.clone()).sqrt().clamp_min(NORM_EPS).recip();
    v.mul(inv_norm)
}

/// The cross product of two `[N, 3]` duals.
pub fn cross(a: Dual, b: Dual) -> Dual {
    let a_yzx = a.clone().select(&[1, 2, 0]);
    let a_zxy = a.select(&[2, 0, 1]);
    let b_yzx = b.clone().select(&[1, 2, 0]);
    let b_zxy = b.select(&[2, 0, 1]);
    a_yzx.mul(b_zxy).sub(a_zxy.mul(b_yzx))
}

/// Gram–Schmidt of the 6-D representation `o = (o0..o5)` (`[N, 6]`), read as a 3×2
/// matrix in row-major order, so that the two columns are `a1 = (o0, o2, o4)` and
/// `a2 = (o1, o3, o5)`. Returns the columns `[b1, b2, b3]` of `R`, each `[N, 3]`:
/// `b1 = a1/‖a1‖`, `b2 = normalize(a2 − (b1·a2) b1)`, `b3 = b1 × b2`.
/// The identity is `o = (1, 0, 0, 1, 0, 0)`.
pub fn gram_schmidt(six: Dual) -> [Dual; 3] {
    let a1 = six.clone().select(&[0, 2, 4]);
    let a2 = six.select(&[1, 3, 5]);
    let b1 = normalize(a1);
    let proj = dot(b1.clone(), a2.clone());
    let b2 = normalize(a2.sub(b1.clone().mul(proj)));
    let b3 = cross(b1.clone(), b2.clone());
    [b1, b2, b3]
}
