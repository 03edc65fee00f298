//! DOMA-Scaled SE(3) (Eq. 12): `y = s(x, t) Q(x, t) x + u(x, t)`; 10 raw outputs.
//!
//! `s = softplus(o[0])` (β = 1), `Q` is the Gram–Schmidt of `o[1..7]` and `u = o[7..10]`.

use super::{LocalAffine, rotation};
use crate::dual::Dual;
use std::ops::Mul;

/// Raw outputs per point.
pub const OUTPUTS: usize = 10;

/// The local transformation `(s Q, u)`.
pub fn local_affine(raw: Dual) -> LocalAffine {
    let scale = raw.clone().narrow(0, 1).softplus();
    let columns = rotation::gram_schmidt(raw.clone().narrow(1, 6)).map(|c| c.mul(scale.clone()));
    LocalAffine {
        columns: Some(columns),
        translation: raw.narrow(7, 3),
    }
}
