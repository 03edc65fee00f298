//! The traits that most code using doma needs in scope: `use doma::prelude::*;`.

pub use crate::field::MotionField;
pub use crate::jacobian::JacobianMethod;
pub use crate::siren::WithSirenShape;
pub use crate::train::WithSchedule;
