//! `doma image2d`: supplement Tab. A7 (a deforming 2-D pixel grid).

use std::path::PathBuf;

use crate::Result;
use crate::cli::{ExperimentArgs, check_widths};
use crate::experiments::image2d::{self, Image2dJob, Motion2d};
use crate::field::Variant;

/// The flags of `doma image2d`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Trans vs Affinity on a deforming 2-D pixel grid at widths 32/64/128 (Tab. A7)")]
pub struct Image2dArgs {
    /// Grid resolution (pixels per side).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u64).range(2..))]
    pub resolution: u64,
    /// Frames.
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u64).range(2..))]
    pub frames: u64,
    /// The motions (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "rotation,scaling,shearing,translation"
    )]
    pub motion: Vec<Motion2d>,
    /// The variants (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "trans,affinity"
    )]
    pub variant: Vec<Variant>,
    /// Hidden widths (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "32,64,128")]
    pub widths: Vec<usize>,
    /// Iterations per fit.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    pub iters: u64,
    /// The folder for the PNG pictures of the last frame.
    #[arg(long, default_value = "results/image2d")]
    pub png_dir: PathBuf,
    /// Backend, seed, progress and JSON records.
    #[command(flatten)]
    pub common: ExperimentArgs,
}

impl Image2dArgs {
    /// The library job these flags describe.
    pub fn job(&self) -> Image2dJob {
        Image2dJob {
            resolution: self.resolution as usize,
            frames: self.frames as usize,
            motions: self.motion.clone(),
            variants: self.variant.clone(),
            widths: self.widths.clone(),
            iterations: self.iters as usize,
            backend: self.common.backend,
            seed: self.common.seed,
            quiet: self.common.quiet,
            png_dir: Some(self.png_dir.clone()),
        }
    }
}

/// Runs every fit, then prints the table.
pub fn run(args: &Image2dArgs) -> Result<()> {
    args.common.check_json()?;
    check_widths(&args.widths)?;
    let records = image2d::run(&args.job(), |r| {
        eprintln!(
            "{} {} {}D: EPE {:.2}e-4 in {:.1} s",
            r.motion, r.variant, r.hidden, r.epe_x1e4, r.seconds
        )
    })?;
    print!("{}", image2d::table(&records));
    args.common.write_json(&records)
}
