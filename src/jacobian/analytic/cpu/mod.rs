//! The analytic op on the CPU backends (flex, ndarray): the whole SIREN as one operation
//! on raw buffers (docs/design.md §2.2). The files go from the leaf up:
//!
//! | file | what it holds |
//! |---|---|
//! | `real.rs` | the float trait (f32, f64), the workspace pool, a vectorisable f32 sine |
//! | `gemm.rs` | the GEMM front end over the `gemm` crate, split-K for weight gradients |
//! | `rows.rs` | the fused sine passes over one row, compiled for three instruction sets |
//! | `net.rs` | the network: forward and hand-written backward on slices |
//! | `host.rs` | flex's and ndarray's buffers lent to `net.rs`; the backends' impls |

mod gemm;
mod host;
mod net;
mod real;
mod rows;

pub(crate) use gemm::{Mat, gemm, serial};
pub(crate) use net::Net;
pub(crate) use real::Real;
