//! `doma warp`: a canonical mesh warped through a fitted run, as an OBJ sequence.

use std::path::PathBuf;

use crate::Result;
use crate::cli::DeviceArgs;
use crate::run::{RunDir, warp_run};

/// The flags of `doma warp`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Warp a canonical mesh through a fitted run and write an OBJ sequence")]
pub struct WarpArgs {
    /// The run folder.
    pub run: PathBuf,
    /// The canonical mesh, in the data's units (default: the run data's first frame, with
    /// the faces of its mesh).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// The folder to write frame_0000.obj, … into.
    #[arg(long)]
    pub out: PathBuf,
    /// Which frames, `A..B` or `A..=B` (default: all of the run's frames).
    #[arg(long, value_parser = crate::data::parse_frame_range)]
    pub frames: Option<std::ops::Range<usize>>,
    /// The device.
    #[command(flatten)]
    pub device: DeviceArgs,
}

/// Writes the frames.
pub fn run(args: &WarpArgs) -> Result<()> {
    let device = args.device.backend.device()?;
    let paths = warp_run(
        &RunDir::new(&args.run),
        args.mesh.as_deref(),
        &args.out,
        args.frames.clone(),
        &device,
    )?;
    eprintln!("wrote {} frames to {}", paths.len(), args.out.display());
    Ok(())
}
