//! DOMA-Affinity (Eq. 4): `y = A(x, t) x + u(x, t)` with a free 3×3 `A`; 12 raw outputs.
//!
//! `A` is `o[0..9]` read row-major and `u = o[9..12]`. As in the authors' code, no
//! identity is added to `A`: the network has to learn `A ≈ I` (docs/reference.md §2).

use super::LocalAffine;
use crate::dual::Dual;

/// Raw outputs per point.
pub const OUTPUTS: usize = 12;

/// The local transformation: column `j` of `A` is `(o[j], o[3 + j], o[6 + j])`.
pub fn local_affine(raw: Dual) -> LocalAffine {
    let columns = [0, 1, 2].map(|j| raw.clone().select(&[j, 3 + j, 6 + j]));
    LocalAffine {
        columns: Some(columns),
        translation: raw.narrow(9, 3),
    }
}
