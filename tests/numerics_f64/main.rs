//! The f64 oracles: both Jacobian methods, every parameter's gradient and the baselines
//! against central finite differences in f64. Its own binary: a flex device's float type is
//! set once per process.

#[path = "../common/mod.rs"]
mod common;

mod analytic_f64;
mod baselines_f64;
mod jacobian_f64;
