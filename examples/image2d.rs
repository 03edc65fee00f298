//! The 2-D image experiment (supplement Tab. A7): Trans against Affinity on a deforming pixel grid at several widths, with pictures of the last frame.
//!
//! The same flags as `doma image2d` (`--help` lists them):
//!
//! ```text
//! cargo run --release --example image2d -- --help
//! cargo run --release --example image2d -- --resolution 64 --motion shearing --widths 32 --iters 100 --png-dir /tmp/image2d
//! ```
//!
//! How it works: [`doma::experiments::image2d::run`] deforms the grid, fits each variant and width through [`doma::train::Trainer`] and renders the held-out pixels.

use clap::Parser;
use doma::cli::image2d::{Image2dArgs, run};

fn main() -> anyhow::Result<()> {
    // SAFETY: first thing in main; no other thread exists yet.
    unsafe { doma::cli::init_process() };
    run(&Image2dArgs::parse())?;
    Ok(())
}
