//! # doma
//!
//! A Burn implementation of *Degrees of Freedom Matter: Inferring Dynamics from
//! Point Trajectories* (Zhang et al., CVPR 2024, "DOMA").
//!
//! From observed 3-D point trajectories, doma fits one small SIREN `f(x, t)`
//! ([`siren`]) whose outputs a head ([`field`]) turns into a local transformation
//! `(A, u)`; any canonical point `x` then moves to `y = A x + u` (Eq. 4 of the paper).
//! The variants (Trans, SE(3), Scaled SE(3), Affinity) differ only in the degrees of
//! freedom of `A`. The smoothness loss `L_H` (Eq. 13) needs the spatial Jacobian of the
//! network inside the loss; [`jacobian`] computes it in forward mode, so that Burn's
//! first-order reverse mode gives exact parameter gradients through it.
//!
//! The backend is a runtime value ([`backend::BackendKind`] maps a name to a Burn
//! `Device`); no code is generic over a backend type.
//!
//! A fit, from a config to the error on held-out points:
//!
//! ```
//! use burn::tensor::Device;
//! use doma::data::synthetic::{Motion, benchmark_sequence};
//! use doma::field::{DomaFieldConfig, Variant};
//! use doma::prelude::*;
//! use doma::train::{FitConfig, Trainer};
//!
//! let seq = benchmark_sequence(Motion::Shearing, 0)?;
//! let field = DomaFieldConfig::new(Variant::Affinity).with_hidden(16);
//! let config = FitConfig::doma(field).with_iterations(2);
//! let fitted = Trainer::from_config(&config, &seq.train, &Device::flex())?.run()?;
//! let epe = doma::metrics::evaluate_epe(&fitted.field, &seq.test, &Device::flex())?;
//! assert!(epe.is_finite());
//! # Ok::<(), doma::DomaError>(())
//! ```
//!
//! **Layers**: each module imports only those of the layers before it, from the leaves
//! ([`dual`], [`io`], [`numeric`]: k-NN, eigensolvers and small solvers, [`names`], …) and gap filling on bare numbers ([`gaps`]:
//! the fillers, the field's fill, the blend, the spans) through the network ([`siren`],
//! [`jacobian`], [`field`]), data and losses ([`data`], [`loss`]), [`warp`] and
//! [`metrics`], fitting ([`train`], [`register`]) and the jobs ([`run`], [`experiments`],
//! [`export`], [`view`], [`batch`]) to the command line ([`cli`]). The list, with what
//! each layer holds, is in docs/design.md §4.
//!
//! Equation numbers refer to the CVPR 2024 paper (main text): Eq. 1 SIREN, Eq. 2 DPF,
//! Eq. 4 the affinity field, Eq. 6 the SIREN Jacobian, Eq. 10–12 the Trans, SE(3) and
//! Scaled SE(3) variants, Eq. 13 the smoothness loss.

#![warn(missing_docs)]

pub mod backend;
pub mod batch;
pub mod checkpoint;
pub mod cli;
pub mod data;
pub mod dual;
pub mod error;
pub mod experiments;
pub mod export;
pub mod field;
pub mod gaps;
pub mod io;
pub mod jacobian;
pub mod loss;
pub mod metrics;
pub mod names;
pub mod numeric;
pub mod plot;
pub mod prelude;
pub mod readback;
pub mod register;
pub mod run;
pub mod siren;
pub mod train;
pub mod view;
pub mod warp;

pub use error::{DomaError, Result};
