//! `doma export`: a fitted run's motion as one animated binary glTF (`.glb`).

use std::path::PathBuf;

use crate::Result;
use crate::cli::DeviceArgs;
use crate::export::{ExportOptions, export_gltf};
use crate::run::RunDir;

/// The flags of `doma export`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Export a fitted run's motion as an animated binary glTF (.glb, morph targets)")]
pub struct ExportArgs {
    /// The run folder.
    pub run: PathBuf,
    /// The .glb to write.
    #[arg(long)]
    pub gltf: PathBuf,
    /// The canonical mesh, any OBJ in the data's units, with its UVs and materials
    /// (default: the run data's first frame with its faces, or its points).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Which frames, `A..B` or `A..=B` (default: all of the run's frames).
    #[arg(long, value_parser = crate::data::parse_frame_range)]
    pub frames: Option<std::ops::Range<usize>>,
    /// Colour the vertices by their mean end-point error over the frames (the vertices
    /// must be the run's points: no --mesh, or one with a vertex per point, in order).
    #[arg(long)]
    pub color_by_error: bool,
    /// Keyframes per second.
    #[arg(long, default_value_t = 24.0)]
    pub fps: f32,
    /// The data's up axis, turned onto glTF's +y (default: the data's y).
    #[arg(long, value_enum)]
    pub up: Option<crate::view::Axis>,
    /// The device.
    #[command(flatten)]
    pub device: DeviceArgs,
}

/// Writes the `.glb`.
pub fn run(args: &ExportArgs) -> Result<()> {
    let device = args.device.backend.device()?;
    let summary = export_gltf(
        &RunDir::new(&args.run),
        args.mesh.as_deref(),
        &args.gltf,
        &ExportOptions {
            frames: args.frames.clone(),
            color_by_error: args.color_by_error,
            fps: Some(args.fps),
            up: args.up,
        },
        &device,
    )?;
    eprintln!(
        "wrote {}: {} vertices, {} triangles, {} frames as morph targets, {} bytes",
        args.gltf.display(),
        summary.vertices,
        summary.triangles,
        summary.frames,
        summary.bytes
    );
    Ok(())
}
