//! The mesh experiments: `novel_points` (after Tab. 1: fit on 25 % of an animated mesh's
//! vertices, predict the other 75 %) and `mesh_alignment` (after Tab. 3: align the frame-0
//! template to per-frame target surfaces with sparse guidance keypoints, Eq. 14).
//!
//! Both read any user's sequence ([`crate::data::sequence::load_sequence`]: `.traj` with an optional OBJ for the
//! faces, `.anime`, `.npy`/`.npz`, a clip `A..B` with a stride) and write one
//! [`MeshRecord`] per run.

mod alignment;
mod novel_points;

pub use alignment::{AlignModel, AlignReg, MeshAlignmentJob, mesh_alignment};
pub use novel_points::{NovelPointsJob, novel_points};

use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::Result;
use crate::backend::BackendKind;
use crate::data::Trajectories;
use crate::data::mesh::{SurfaceSamples, as_points};
use crate::experiments::{Experiment, RowReg};
use crate::field::model::ModelName;
use crate::metrics::chamfer_with_normals;

/// Chamfer distances are reported ×1e4 (docs/reference.md §7).
pub const CD_SCALE: f64 = 1e4;
/// STD(E) and STD(V) are reported ×1e3: millimetres for data in metres, as in Tab. 3.
pub const STD_SCALE: f64 = 1e3;

/// One run's record (one JSON object per run); the fields that do not apply are omitted.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct MeshRecord {
    /// `novel_points` or `mesh_alignment`.
    pub experiment: Experiment,
    /// The sequence (file stem) and clip.
    pub sequence: String,
    /// The model: a DOMA variant's or a baseline's paper name.
    pub variant: ModelName,
    /// The regulariser: `none`, `h`, `e` (Tab. 1) or `a`, `h`, `ah` (Tab. 3).
    pub reg: RowReg,
    /// The regulariser's weight, when it has one.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub weight: Option<f64>,
    /// How the weight was chosen by validation (`--h-weight auto`): the grid and each
    /// weight's validation EPE.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub weight_search: Option<crate::train::select::WeightChoice>,
    /// Iterations.
    pub iters: usize,
    /// The backend.
    pub backend: BackendKind,
    /// EPE × 10⁴ on the held-out vertices (`novel_points`).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub epe_x1e4: Option<f64>,
    /// Chamfer distance × 10⁴, averaged over frames.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub cd_x1e4: Option<f64>,
    /// Normal Chamfer distance, averaged over frames.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub cdn: Option<f64>,
    /// STD(E) × 10³ (mm for data in metres).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub std_e: Option<f64>,
    /// STD(V) × 10³ (mm for data in metres).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub std_v: Option<f64>,
    /// Trainable parameters.
    pub params: usize,
    /// The f32 burnpack checkpoint's size in bytes.
    pub checkpoint_bytes: u64,
    /// Wall time of the fit loop, seconds.
    pub seconds: f64,
}

/// CD and CDN between the `predicted` and `truth` poses of a mesh, per frame on `samples`
/// fresh area-weighted surface points each (with face normals), averaged over frames.
pub fn mesh_chamfer(
    predicted: &Trajectories,
    truth: &Trajectories,
    faces: &[[u32; 3]],
    samples: usize,
    seed: u64,
) -> Result<(f64, f64)> {
    mesh_chamfer_with(
        |k| Ok(as_points(predicted.frame(k))),
        truth,
        faces,
        samples,
        seed,
    )
}

/// [`mesh_chamfer`] with the predicted mesh of frame `k` made on demand by `predicted(k)`
/// (e.g. warped through a field), so that one frame is in memory at a time. The samples
/// are drawn in the same order, so the result is the same.
pub fn mesh_chamfer_with(
    mut predicted: impl FnMut(usize) -> Result<Vec<[f32; 3]>>,
    truth: &Trajectories,
    faces: &[[u32; 3]],
    samples: usize,
    seed: u64,
) -> Result<(f64, f64)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut cd, mut cdn) = (0.0, 0.0);
    for k in 0..truth.frames() {
        let (p, t) = (predicted(k)?, as_points(truth.frame(k)));
        let sp = SurfaceSamples::draw(&p, faces, samples, &mut rng)?;
        let st = SurfaceSamples::draw(&t, faces, samples, &mut rng)?;
        let (d, n) = chamfer_with_normals(
            &sp.points(&p, faces),
            &sp.normals(&p, faces),
            &st.points(&t, faces),
            &st.normals(&t, faces),
        )?;
        cd += d;
        cdn += n;
    }
    let t = truth.frames() as f64;
    Ok((cd / t, cdn / t))
}

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

/// The records as a table: one row per run, the metrics that apply as columns.
pub fn table(records: &[MeshRecord]) -> String {
    let mut out = format!(
        "{:<22} {:>10} {:>10} {:>10} {:>8} {:>9} {:>9} {:>10} {:>12} {:>9}\n",
        "model",
        "weight",
        "EPE x1e-4",
        "CD x1e-4",
        "CDN",
        "STD(E)",
        "STD(V)",
        "params",
        "ckpt bytes",
        "seconds"
    );
    for r in records {
        let reg = r.reg.suffix();
        // A searched weight is marked: "1e-2 (auto)" would not fit; "auto:" prefixes it.
        let weight = match (r.weight, &r.weight_search) {
            (Some(w), Some(_)) => format!("auto:{w:e}"),
            (Some(w), None) => format!("{w:e}"),
            (None, _) => "-".into(),
        };
        out += &format!(
            "{:<22} {:>10} {:>10} {:>10} {:>8} {:>9} {:>9} {:>10} {:>12} {:>9.1}\n",
            format!("{}{reg}", r.variant),
            weight,
            fmt_opt(r.epe_x1e4, 2),
            fmt_opt(r.cd_x1e4, 3),
            fmt_opt(r.cdn, 4),
            fmt_opt(r.std_e, 2),
            fmt_opt(r.std_v, 2),
            r.params,
            r.checkpoint_bytes,
            r.seconds
        );
    }
    out
}

/// The default data of the mesh experiments: `data/cdp_male_wave.traj` in the crate.
pub fn default_data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/cdp_male_wave.traj")
}
