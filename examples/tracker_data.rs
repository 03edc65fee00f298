//! Tracker-like test data from the shipped animated meshes: a camera, vertices facing away
//! from it hidden, dropout spans and late-starting tracks, in PointOdyssey's and TAPVid-3D's
//! layouts ([`doma::data::tracker`]).
//!
//! ```sh
//! cargo run --release --example tracker_data -- OUT_DIR
//! ```
//! writes `OUT_DIR/{cdp_male_wave,md2_faerie}_{pointodyssey,tapvid3d}.npz` and prints what
//! fraction of the entries each hides.

use std::path::PathBuf;

use anyhow::Context;
use doma::data::layout::Layout;
use doma::data::mesh::read_obj;
use doma::data::tracker::{TrackerConfig, simulate};
use doma::data::traj::read_traj;

fn main() -> anyhow::Result<()> {
    let out: PathBuf = std::env::args()
        .nth(1)
        .context("usage: tracker_data OUT_DIR")?
        .into();
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data");
    // The faerie's clips are joined end to end; its "taunt" clip is one motion.
    for (name, frames) in [("cdp_male_wave", None), ("md2_faerie", Some(95..112))] {
        let mut truth = read_traj(data.join(format!("{name}.traj")))?;
        if let Some(range) = frames {
            truth = truth.select_frames(range, 1)?;
        }
        let mesh = read_obj(data.join(format!("{name}.obj")))?;
        let view = simulate(&truth, &mesh.faces, &TrackerConfig::default())?;
        let observed = view.observed();
        let hidden = observed.iter().filter(|&&o| !o).count();
        for layout in [Layout::PointOdyssey, Layout::TapVid3d] {
            let path = out.join(format!("{name}_{layout}.npz"));
            view.write(&path, layout)?;
            println!(
                "{}: {} frames × {} tracks, {:.1} % of the entries unobserved",
                path.display(),
                truth.frames(),
                truth.points(),
                100.0 * hidden as f64 / observed.len() as f64
            );
        }
    }
    Ok(())
}
