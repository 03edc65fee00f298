//! The spatial Jacobian of a SIREN, behind one trait (DESIGN §2).
//!
//! The smoothness loss `L_H` (Eq. 13) and the elasticity loss need `∂o/∂x` inside the
//! loss, and the loss is then differentiated with respect to the weights θ. Burn 0.22
//! has first-order reverse mode only, so a [`JacobianMethod`] computes the Jacobian in
//! forward mode and returns it as the tangents of a [`Dual`]; Burn's reverse mode then
//! gives exact θ-gradients through it. The fit loop only sees the trait, so methods
//! plug in without touching it.

pub mod analytic;
mod dual;

pub use analytic::Analytic;
pub use dual::Dual;

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

    /// One value-only sine layer `sin(ω (h W + b))` (Eq. 1), `h: [N, fan_in]`,
    /// `w: [fan_in, fan_out]`. The default is Burn's ops; a method may fuse it. Models
    /// built from bare weights rather than a [`Siren`] (DPF's frame nets) call it, so
    /// that they get the same kernels as the DOMA fields they are compared with.
    fn sine_layer(&self, h: Tensor<2>, w: Tensor<2>, b: Tensor<1>, omega: f64) -> Tensor<2> {
        (h.matmul(w) + b.unsqueeze_dim::<2>(0))
            .mul_scalar(omega)
            .sin()
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

    /// The lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            JacobianKind::Autodiff => "autodiff",
            JacobianKind::Analytic => "analytic",
        }
    }
}

impl std::fmt::Display for JacobianKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
