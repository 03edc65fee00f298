//! The spatial Jacobian of a SIREN, behind one trait (docs/design.md §2).
//!
//! The smoothness loss `L_H` (Eq. 13) and the elasticity loss need `∂o/∂x` inside the
//! loss, and the loss is then differentiated with respect to the weights θ. Burn 0.22
//! has first-order reverse mode only, so a [`JacobianMethod`] computes the Jacobian in
//! forward mode and returns it as the tangents of a [`Dual`]; Burn's reverse mode then
//! gives exact θ-gradients through it. The fit loop only sees the trait, so methods
//! plug in without touching it.

pub mod analytic;

pub use crate::dual::Dual;
pub use analytic::Analytic;

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use crate::siren::Siren;

/// How the spatial Jacobian of a SIREN's outputs is computed.
pub trait JacobianMethod: std::fmt::Debug + Send + Sync {
    /// A short name for tables and JSON records.
    fn name(&self) -> &'static str;

    /// The SIREN's outputs `[N, O]` for inputs `xt: [N, 4]`, without tangents (Eq. 1).
    /// The default is the plain [`Siren::forward`]; a method may fuse it.
    fn forward(&self, siren: &Siren, xt: Tensor<2>) -> Tensor<2> {
        siren.forward(xt)
    }

    /// The SIREN's outputs `[N, O]` for inputs `xt: [N, 4]` (`[x, y, z, t]`), with their
    /// tangents `[3, N, O]` with respect to the three spatial inputs.
    fn forward_dual(&self, siren: &Siren, xt: Tensor<2>) -> Dual;

    /// Whether the method works for any model written on [`Dual`]s (automatic forward
    /// mode), or only for SIREN layers (the hand-derived kernels). A model without SIREN
    /// layers accepts general methods alone ([`crate::field::MotionField::accepts`]).
    fn is_general(&self) -> bool {
        false
    }
}

/// Automatic forward mode: the network runs on [`Dual`]s, with the three tangents
/// stacked into one `[3N, d]` matrix per layer. It works for any model written on
/// duals, not only SIRENs.
#[derive(Clone, Copy, Debug, Default)]
pub struct Autodiff;

impl JacobianMethod for Autodiff {
    fn name(&self) -> &'static str {
        "autodiff"
    }

    fn forward_dual(&self, siren: &Siren, xt: Tensor<2>) -> Dual {
        siren.forward_dual(Dual::seed_spatial(xt))
    }

    fn is_general(&self) -> bool {
        true
    }
}

/// The Jacobian methods that can be named in a config or on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum JacobianKind {
    /// [`Autodiff`]: automatic forward mode on dual tensors.
    Autodiff,
    /// [`Analytic`]: hand-derived fused sine layers with a hand-written backward.
    Analytic,
}

impl JacobianKind {
    /// The method itself.
    pub fn method(self) -> Box<dyn JacobianMethod> {
        match self {
            JacobianKind::Autodiff => Box::new(Autodiff),
            JacobianKind::Analytic => Box::new(Analytic),
        }
    }
}

crate::names::value_names!(JacobianKind);
