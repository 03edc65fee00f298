//! Novel points (paper Tab. 1): fit 25 % of an animated mesh's vertices and predict the other 75 %; EPE, and CD/CDN of the warped mesh.
//!
//! The same flags as `doma novel-points` (`--help` lists them):
//!
//! ```text
//! cargo run --release --example novel_points -- --help
//! cargo run --release --example novel_points -- --frames 0..20 --variant trans,affinity --baselines mlp --iters 100
//! ```
//!
//! How it works: [`doma::experiments::meshes::novel_points`] splits the vertices ([`doma::data::sequence::split_indices`]), fits each [`doma::field::model::ModelConfig`] (variants and baselines) through [`doma::train::Trainer`], and measures the warped mesh ([`doma::warp::warp_mesh_sequence`], [`doma::metrics`]).

use clap::Parser;
use doma::cli::novel_points::{NovelPointsArgs, run};

fn main() -> anyhow::Result<()> {
    // SAFETY: first thing in main; no other thread exists yet.
    unsafe { doma::cli::init_process() };
    run(&NovelPointsArgs::parse())?;
    Ok(())
}
