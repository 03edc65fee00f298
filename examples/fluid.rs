//! The fluid experiment (supplement Tab. A8): frame-wise DPF against DOMA-Trans and DOMA-Affinity on 10-frame clips of an MPM fluid, half of the particles held out.
//!
//! The same flags as `doma fluid` (`--help` lists them):
//!
//! ```text
//! cargo run --release --example fluid -- --help
//! cargo run --release --example fluid -- --clips 40 --widths 64 --iters 300 --eval-every 100
//! ```
//!
//! How it works: [`doma::experiments::fluid::run`] cuts the clips, skips the static ones, and fits each model through [`doma::train::Trainer::run_observed`] (learning curves with `--eval-every`).

use clap::Parser;
use doma::cli::fluid::{FluidArgs, run};

fn main() -> anyhow::Result<()> {
    // SAFETY: first thing in main; no other thread exists yet.
    unsafe { doma::cli::init_process() };
    run(&FluidArgs::parse())?;
    Ok(())
}
