//! `doma plot`: plots of a run, as PNG and SVG.

use std::path::PathBuf;

use crate::Result;
use crate::cli::DeviceArgs;
use crate::run::{RunDir, plot_run};

/// The flags of `doma plot`.
#[derive(clap::Parser, Debug, Clone)]
#[command(
    about = "Write plots of a run, PNG and SVG (loss, per-frame EPE, the longest filled gaps of tracks with gaps, 3-view error scatters)"
)]
pub struct PlotArgs {
    /// The run folder.
    pub run: PathBuf,
    /// The frames of the scatter plots (comma-separated; default: the middle and the last).
    #[arg(long, value_delimiter = ',')]
    pub frames: Option<Vec<usize>>,
    /// The device.
    #[command(flatten)]
    pub device: DeviceArgs,
}

/// Writes the plots into RUN/plots/.
pub fn run(args: &PlotArgs) -> Result<()> {
    let device = args.device.backend.device()?;
    for path in plot_run(&RunDir::new(&args.run), args.frames.as_deref(), &device)? {
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
