//! DOMA-Trans (Eq. 10): `y = x + u(x, t)`; `A = I`, 3 raw outputs.

use super::LocalAffine;
use crate::dual::Dual;

/// Raw outputs per point.
pub const OUTPUTS: usize = 3;

/// The local transformation: `A = I`, `u = o`.
pub fn local_affine(raw: Dual) -> LocalAffine {
    LocalAffine {
        columns: None,
        translation: raw,
    }
}
