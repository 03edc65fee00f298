//! `doma view`: a self-contained HTML viewer of a fitted run.

use std::path::PathBuf;

use crate::Result;
use crate::cli::DeviceArgs;
use crate::run::RunDir;

/// The flags of `doma view`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Write a self-contained HTML page that plays a fitted run in WebGL")]
pub struct ViewArgs {
    /// The run folder.
    pub run: PathBuf,
    /// The page to write.
    #[arg(long, default_value = "view.html")]
    pub out: PathBuf,
    /// Show this mesh (any OBJ in the data's units) warped, instead of the run's points.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Which frames, `A..B` or `A..=B` (default: all of the run's frames).
    #[arg(long, value_parser = crate::data::parse_frame_range)]
    pub frames: Option<std::ops::Range<usize>>,
    /// The vertical axis (default: the box's clearly longest side, else y).
    #[arg(long, value_enum)]
    pub up: Option<crate::view::Axis>,
    /// The device.
    #[command(flatten)]
    pub device: DeviceArgs,
}

/// Writes the page.
pub fn run(args: &ViewArgs) -> Result<()> {
    let device = args.device.backend.device()?;
    let bytes = crate::view::write_view(
        &RunDir::new(&args.run),
        args.mesh.as_deref(),
        args.frames.clone(),
        args.up,
        &args.out,
        &device,
    )?;
    eprintln!(
        "wrote {} ({:.1} MB); open it in a browser",
        args.out.display(),
        bytes as f64 / 1e6
    );
    Ok(())
}
