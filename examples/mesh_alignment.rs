//! Guided mesh alignment (paper Tab. 3, Eq. 14): align the frame-0 template to every frame's surface with sparse guidance keypoints; CD, CDN, STD(E), STD(V).
//!
//! The same flags as `doma mesh-alignment` (`--help` lists them):
//!
//! ```text
//! cargo run --release --example mesh_alignment -- --help
//! cargo run --release --example mesh_alignment -- --frames 0..10 --model trans,affinity --reg none,h --iters 200
//! ```
//!
//! How it works: [`doma::experiments::meshes::mesh_alignment`] builds a [`doma::register::RegistrationTask`] and fits each model by [`doma::register::register`], whose objective runs in the same [`doma::train::Trainer`] as every trajectory fit.

use clap::Parser;
use doma::cli::mesh_alignment::{MeshAlignmentArgs, run};

fn main() -> anyhow::Result<()> {
    // SAFETY: first thing in main; no other thread exists yet.
    unsafe { doma::cli::init_process() };
    run(&MeshAlignmentArgs::parse())?;
    Ok(())
}
