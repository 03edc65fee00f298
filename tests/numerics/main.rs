//! The numerics against independent references: the SIREN and its initialiser, the motion fields'
//! heads, both Jacobian methods (against reverse mode, finite differences and each other, on
//! every backend), the CubeCL kernels, the baselines, and every loss and metric on
//! hand-computed values. In f32; the f64 oracles are in `numerics_f64`.

#[path = "../common/mod.rs"]
mod common;

mod analytic;
// The CubeCL kernels exist with the `wgpu` feature alone.
#[cfg(feature = "wgpu")]
mod analytic_kernels;
mod baselines;
mod fields;
mod jacobian_f32;
mod losses_metrics;
mod siren_init;
