//! How a fit's training step is computed: a setting of [`super::FitConfig`], the fused
//! step's own code in `fused/`.

use serde::{Deserialize, Serialize};

/// How a training step is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum StepKind {
    /// Burn's operations around the Jacobian method, differentiated by Burn's autodiff:
    /// every model, backend and loss.
    Composed,
    /// The whole step as one operation on the CPU (docs/design.md §2.4): a DOMA field, the
    /// analytic Jacobian, flex or ndarray, the trajectory loss and `L_H`; refused, with
    /// the reason, for any other fit.
    Fused,
    /// The fused step where it applies, the composed step elsewhere.
    Auto,
}

crate::names::value_names!(StepKind);
