//! The synthetic benchmark (paper Tab. 2): the four DOMA variants on four closed-form motions of a cube's points, EPE on held-out points.
//!
//! The same flags as `doma synthetic` (`--help` lists them):
//!
//! ```text
//! cargo run --release --example synthetic -- --help
//! cargo run --release --example synthetic -- --motion shearing --variant affinity --reg h --iters 200
//! ```
//!
//! How it works: [`doma::experiments::synthetic::run`] draws each motion's points ([`doma::data::synthetic::benchmark_sequence`]), fits one [`doma::train::FitConfig`] per variant through the common [`doma::train::Trainer`], and scores it with [`doma::metrics::evaluate_epe`].

use clap::Parser;
use doma::cli::synthetic::{SyntheticArgs, run};

fn main() -> anyhow::Result<()> {
    // SAFETY: first thing in main; no other thread exists yet.
    unsafe { doma::cli::init_process() };
    run(&SyntheticArgs::parse())?;
    Ok(())
}
