//! `doma complete`: a fitted run's tracks at every frame, gaps filled.

use std::path::PathBuf;

use crate::Result;
use crate::cli::DeviceArgs;
use crate::data::layout::Layout;
use crate::run::{RunDir, complete_run};

/// The flags of `doma complete`.
#[derive(clap::Parser, Debug, Clone)]
#[command(
    about = "Write every track of a fitted run at every frame (.npz, or .c3d from a C3D input), gaps filled by the field"
)]
pub struct CompleteArgs {
    /// The run folder.
    pub run: PathBuf,
    /// The file to write: a .npz (`tracks` f32 [T, N, 3] and `observed` bool [T, N]), or,
    /// when the run fitted a .c3d, a .c3d with its labels, rate and units, where a filled
    /// marker has residual 0 (computed, not measured).
    #[arg(long)]
    pub out: PathBuf,
    /// Write a tracker's keys instead (pointodyssey: trajs_3d, visibs, valids; tapvid3d:
    /// tracks_XYZ, visibility).
    #[arg(long, value_enum)]
    pub layout: Option<Layout>,
    /// The device.
    #[command(flatten)]
    pub device: DeviceArgs,
}

/// Writes the completed tracks.
pub fn run(args: &CompleteArgs) -> Result<()> {
    let device = args.device.backend.device()?;
    let c = complete_run(&RunDir::new(&args.run), &args.out, args.layout, &device)?;
    eprintln!(
        "wrote {}: {} tracks × {} frames, {} observed entries kept, {} filled",
        args.out.display(),
        c.tracks,
        c.frames,
        c.observed,
        c.filled
    );
    let b = &c.blend;
    for (k, name) in ["short", "long"].iter().enumerate() {
        let w = if k == 0 { &b.short } else { &b.long };
        let count = b.validated[k];
        if count == 0 || !b.cross_fitted[k] {
            let why = if count == 0 {
                "nothing to validate".to_string()
            } else {
                format!("no blend beat it on {count} validation entries")
            };
            eprintln!("  {name} gaps: the field's fill ({why})");
            continue;
        }
        let weights: Vec<String> = w
            .iter()
            .map(|(f, v)| format!("{} {v:.2}", f.label()))
            .collect();
        eprintln!(
            "  {name} gaps (weights from {count} validation entries): {}",
            weights.join(", ")
        );
    }
    Ok(())
}
