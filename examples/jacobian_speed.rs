//! Autodiff against the hand-derived Analytic Jacobian (paper Eq. 6): the Jacobian step and the Affinity-H training step per backend, the table of `doma bench`.
//!
//! The same flags as `doma bench` (`--help` lists them):
//!
//! ```text
//! cargo run --release --example jacobian_speed -- --help
//! cargo run --release --example jacobian_speed -- --backend all --steps 20
//! ```
//!
//! How it works: [`doma::experiments::speed::run`] times [`doma::jacobian::JacobianMethod::forward_dual`] with its backward, and one [`doma::train::Trainer::step`], per backend and method (median after warm-up, a device sync in every timed step).

use clap::Parser;
use doma::cli::bench::{BenchArgs, run};

fn main() -> anyhow::Result<()> {
    // SAFETY: first thing in main; no other thread exists yet.
    unsafe { doma::cli::init_process() };
    run(&BenchArgs::parse())?;
    Ok(())
}
