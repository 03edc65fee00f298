//! DOMA-SE(3) (Eq. 11): `y = Q(x, t) x + u(x, t)` with `Q ∈ SO(3)`; 9 raw outputs.
//!
//! `Q` is the Gram–Schmidt of `o[0..6]` ([`super::rotation::gram_schmidt`]) and
//! `u = o[6..9]`.

use super::{LocalAffine, rotation};
use crate::dual::Dual;

/// Raw outputs per point.
pub const OUTPUTS: usize = 9;

/// The local transformation `(Q, u)`.
pub fn local_affine(raw: Dual) -> LocalAffine {
    LocalAffine {
        columns: Some(rotation::gram_schmidt(raw.clone().narrow(0, 6))),
        translation: raw.narrow(6, 3),
    }
}
