//! The mesh experiments: `novel_points` (after Tab. 1: fit on 25 % of an animated mesh's
//! vertices, predict the other 75 %) and `mesh_alignment` (after Tab. 3: align the frame-0
//! template to per-frame target surfaces with sparse guidance keypoints, Eq. 14).
//!
//! Both read any user's sequence ([`load_sequence`]: `.traj` with an optional OBJ for the
//! faces, `.anime`, `.npy`/`.npz`, a clip `A..B` with a stride) and write one
//! [`MeshRecord`] per run.

use std::ops::Range;
use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::backend::BackendKind;
use crate::checkpoint::{Precision, encode_checkpoint};
use crate::data::mesh::{
    SurfaceSamples, TriMesh, as_points, read_obj, unique_edges, warp_mesh_sequence,
};
use crate::data::{Trajectories, anime, npy, traj};
use crate::field::baselines::Baseline;
use crate::field::baselines::bone_cloud::BoneCloudConfig;
use crate::field::baselines::dct::DctConfig;
use crate::field::baselines::mlp::MlpConfig;
use crate::field::dpf::DpfConfig;
use crate::field::{DomaFieldConfig, MotionField, Variant};
use crate::jacobian::JacobianKind;
use crate::metrics::{EPE_SCALE, chamfer_with_normals, evaluate_epe, std_edges, std_vertices};
use crate::register::{RegistrationConfig, RegistrationTask, register};
use crate::train::{FitConfig, Fitted, fit, fit_model};
use crate::{DomaError, Result};

/// Chamfer distances are reported ×1e4 (REFERENCE §7).
pub const CD_SCALE: f64 = 1e4;
/// STD(E) and STD(V) are reported ×1e3: millimetres for data in metres, as in Tab. 3.
pub const STD_SCALE: f64 = 1e3;

/// An animated mesh: vertex trajectories `[T, V, 3]` and, when known, the triangles.
#[derive(Clone, Debug)]
pub struct Sequence {
    /// A short name for the records (the file stem).
    pub name: String,
    /// The vertices' positions in every frame.
    pub trajectories: Trajectories,
    /// The triangles (vertex order = trajectory point order).
    pub faces: Option<Vec<[u32; 3]>>,
    /// The normalisation applied: `x' = (x − center) / scale`.
    pub center: [f32; 3],
    /// See `center`.
    pub scale: f32,
}

/// Loads `data` (`.traj`, `.anime`, `.npy`, `.npz`, or a folder of OBJ frames with equal
/// vertex counts); the faces come from `mesh` (an OBJ
/// whose vertices are the points in order), else from the `.anime`, else from a sibling
/// `NAME.obj` next to a `.traj`. Then keeps `frames` every `stride`-th frame, and
/// normalises the coordinates ([`Trajectories::normalized`]: frame 0's bounding box centred,
/// its longest side spanning `[−1, 1]`); every metric is in these units. An OBJ whose
/// vertex count differs from the point count is refused, naming the file.
pub fn load_sequence(
    data: &Path,
    mesh: Option<&Path>,
    frames: Option<Range<usize>>,
    stride: usize,
) -> Result<Sequence> {
    let ext = data
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let (trajectories, mut faces) = match ext.as_str() {
        _ if data.is_dir() => {
            let (t, f) = crate::data::mesh::read_obj_sequence(data)?;
            (t, Some(f))
        }
        "traj" => (traj::read_traj(data)?, None),
        "anime" => {
            let a = anime::read_anime(data)?;
            (a.trajectories, Some(a.faces))
        }
        "npy" => (npy::read_npy_trajectories(data)?, None),
        "npz" => (npy::read_npz_trajectories(data, None)?, None),
        _ => {
            return Err(DomaError::Malformed {
                path: data.to_path_buf(),
                reason:
                    "unknown format: expected .traj, .anime, .npy, .npz or a folder of .obj frames"
                        .into(),
            });
        }
    };
    let sibling = data.with_extension("obj");
    let obj = mesh
        .map(Path::to_path_buf)
        .or_else(|| (faces.is_none() && ext == "traj" && sibling.is_file()).then_some(sibling));
    if let Some(obj) = obj {
        let m = read_obj(&obj)?;
        if m.vertices.len() != trajectories.points() {
            return Err(DomaError::Malformed {
                path: obj,
                reason: format!(
                    "{} vertices, but {} has {} points",
                    m.vertices.len(),
                    data.display(),
                    trajectories.points()
                ),
            });
        }
        faces = Some(m.faces);
    }
    let trajectories = match frames {
        Some(r) => trajectories.select_frames(r, stride)?,
        None if stride > 1 => trajectories.select_frames(0..trajectories.frames(), stride)?,
        None => trajectories,
    };
    // Fit and measure in normalised coordinates, so that one ω₀ suits every user's units.
    let (trajectories, center, scale) = trajectories.normalized();
    let name = data
        .file_stem()
        .map_or("data".into(), |s| s.to_string_lossy().into_owned());
    Ok(Sequence {
        name,
        trajectories,
        faces,
        center,
        scale,
    })
}

/// One run's record (one JSON object per run); the fields that do not apply are omitted.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct MeshRecord {
    /// `novel_points` or `mesh_alignment`.
    pub experiment: String,
    /// The sequence (file stem) and clip.
    pub sequence: String,
    /// The model: a DOMA variant's paper name or `DPF`.
    pub variant: String,
    /// The regulariser: `none`, `a`, `h` or `ah`.
    pub reg: String,
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
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut cd, mut cdn) = (0.0, 0.0);
    for k in 0..truth.frames() {
        let (p, t) = (as_points(predicted.frame(k)), as_points(truth.frame(k)));
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

/// The settings of `novel_points`.
#[derive(Clone, Debug)]
pub struct NovelPointsJob {
    /// The animated mesh (faces required for CD/CDN).
    pub sequence: Sequence,
    /// The variants.
    pub variants: Vec<Variant>,
    /// The baselines (Tab. 1's other rows).
    pub baselines: Vec<Baseline>,
    /// Iterations per fit.
    pub iterations: usize,
    /// The fraction of vertices used for training (the paper: 0.25).
    pub train_fraction: f64,
    /// Surface samples per mesh and frame for CD/CDN (the paper: 10⁶).
    pub samples: usize,
    /// The backend.
    pub backend: BackendKind,
    /// How `L_H` would be differentiated (unused without a regulariser; kept for speed).
    pub jacobian: JacobianKind,
    /// Seeds the split, the weights and the samples.
    pub seed: u64,
    /// No progress bars.
    pub quiet: bool,
}

/// A seeded split of `n` indices into `round(fraction · n)` and the rest.
pub fn split_indices(n: usize, fraction: f64, seed: u64) -> Result<(Vec<usize>, Vec<usize>)> {
    let n_train = (fraction * n as f64).round() as usize;
    if !(fraction > 0.0 && fraction < 1.0) || n_train == 0 || n_train >= n {
        return Err(DomaError::InvalidConfig(format!(
            "a training fraction of {fraction} does not split {n} points into two non-empty sets"
        )));
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    let test = order.split_off(n_train);
    Ok((order, test))
}

/// Runs `novel_points`: one record per variant, `on_run` after each.
pub fn novel_points(
    job: &NovelPointsJob,
    mut on_run: impl FnMut(&MeshRecord),
) -> Result<Vec<MeshRecord>> {
    let device = job.backend.device()?;
    let seq = &job.sequence;
    let data = &seq.trajectories;
    let (train_idx, test_idx) = split_indices(data.points(), job.train_fraction, job.seed)?;
    let (train, test) = (
        data.select_points(&train_idx)?,
        data.select_points(&test_idx)?,
    );
    let canonical = seq
        .faces
        .as_ref()
        .map(|f| TriMesh::new(as_points(data.frame(0)), f.clone()))
        .transpose()
        .map_err(DomaError::InvalidData)?;
    let mut records = Vec::new();
    let ad = device.clone().autodiff();
    let base = FitConfig::new(DomaFieldConfig::new(Variant::Trans))
        .with_iterations(job.iterations)
        .with_jacobian(job.jacobian)
        .with_seed(job.seed)
        .with_quiet(job.quiet);
    let ctx = NovelContext {
        job,
        test: &test,
        full: data,
        canonical: canonical.as_ref(),
        device: &device,
    };
    for &variant in &job.variants {
        let mut config = base.clone();
        config.field = DomaFieldConfig::new(variant);
        let fitted = fit(&config, &train, &device)?;
        let record = ctx.record(variant.paper_name(), fitted)?;
        on_run(&record);
        records.push(record);
    }
    for &baseline in &job.baselines {
        let config = base.clone().with_learning_rate(baseline.learning_rate());
        let t = data.frames();
        let record = match baseline {
            Baseline::Mlp | Baseline::MlpPe6 => {
                let octaves = if baseline == Baseline::MlpPe6 { 6 } else { 0 };
                let model = MlpConfig::new()
                    .with_pe_octaves(octaves)
                    .init(job.seed, &ad);
                ctx.record(
                    baseline.paper_name(),
                    fit_model(model, &config, &train, &device)?,
                )?
            }
            Baseline::DctNerf => {
                let model = DctConfig::new(t).init(job.seed, &ad);
                ctx.record(
                    baseline.paper_name(),
                    fit_model(model, &config, &train, &device)?,
                )?
            }
            Baseline::BoneCloud => {
                let model = BoneCloudConfig::new(t).init(train.frame(0), job.seed, &ad);
                ctx.record(
                    baseline.paper_name(),
                    fit_model(model, &config, &train, &device)?,
                )?
            }
        };
        on_run(&record);
        records.push(record);
    }
    Ok(records)
}

/// What every `novel_points` fit is measured against.
struct NovelContext<'a> {
    job: &'a NovelPointsJob,
    test: &'a Trajectories,
    full: &'a Trajectories,
    canonical: Option<&'a TriMesh>,
    device: &'a burn::tensor::Device,
}

impl NovelContext<'_> {
    /// EPE on the held-out points, CD/CDN of the warped canonical mesh, size: one record.
    fn record<M: MotionField + burn::module::Module>(
        &self,
        name: &str,
        fitted: Fitted<M>,
    ) -> Result<MeshRecord> {
        let (job, device) = (self.job, self.device);
        let epe = evaluate_epe(&fitted.field, self.test, device)?;
        let (cd, cdn) = match self.canonical {
            Some(mesh) => {
                let warped = warp_mesh_sequence(&fitted.field, mesh, self.full.frames(), device)?;
                let (cd, cdn) =
                    mesh_chamfer(&warped, self.full, &mesh.faces, job.samples, job.seed)?;
                (Some(cd * CD_SCALE), Some(cdn))
            }
            None => (None, None),
        };
        Ok(MeshRecord {
            experiment: "novel_points".into(),
            sequence: job.sequence.name.clone(),
            variant: name.into(),
            reg: "none".into(),
            iters: job.iterations,
            backend: job.backend,
            epe_x1e4: Some(epe * EPE_SCALE),
            cd_x1e4: cd,
            cdn,
            std_e: None,
            std_v: None,
            params: fitted.field.param_count(),
            checkpoint_bytes: encode_checkpoint(fitted.field, Precision::F32)?.len() as u64,
            seconds: fitted.seconds,
        })
    }
}

/// The models of `mesh_alignment`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum AlignModel {
    /// The frame-wise DPF baseline.
    Dpf,
    /// DOMA-Trans.
    Trans,
    /// DOMA-Affinity.
    Affinity,
}

impl AlignModel {
    /// The paper's row name.
    pub fn paper_name(self) -> &'static str {
        match self {
            AlignModel::Dpf => "DPF",
            AlignModel::Trans => "DOMA-Trans",
            AlignModel::Affinity => "DOMA-Affinity",
        }
    }
}

/// The regularisers of Tab. 3.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum AlignReg {
    /// Neither.
    None,
    /// AIAP ("-A").
    A,
    /// The smoothness loss ("-H").
    H,
    /// Both ("-AH").
    Ah,
}

impl AlignReg {
    /// The suffix of the paper's rows.
    pub fn suffix(self) -> &'static str {
        match self {
            AlignReg::None => "",
            AlignReg::A => "-A",
            AlignReg::H => "-H",
            AlignReg::Ah => "-AH",
        }
    }

    /// The lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            AlignReg::None => "none",
            AlignReg::A => "a",
            AlignReg::H => "h",
            AlignReg::Ah => "ah",
        }
    }
}

/// The settings of `mesh_alignment`.
#[derive(Clone, Debug)]
pub struct MeshAlignmentJob {
    /// The animated mesh (faces required): frame 0 is the template, every frame's
    /// true surface is a target.
    pub sequence: Sequence,
    /// Guidance keypoints: this many vertices, a fixed seeded subset.
    pub keypoints: usize,
    /// The models.
    pub models: Vec<AlignModel>,
    /// The regularisers.
    pub regs: Vec<AlignReg>,
    /// The loop's weights and sizes (AIAP and `L_H` weights are set per regulariser).
    pub config: RegistrationConfig,
    /// `w_A` of "-A" (the authors: 1).
    pub aiap_weight: f64,
    /// `w_H` of "-H" (the authors: 0.001).
    pub h_weight: f64,
    /// SIREN width and depth (the authors' registration: 128, 3).
    pub hidden: usize,
    /// Hidden sine layers after the first.
    pub n_hidden: usize,
    /// Surface samples per mesh and frame for CD/CDN.
    pub samples: usize,
    /// The backend.
    pub backend: BackendKind,
}

/// Runs `mesh_alignment`: one record per (model, regulariser).
pub fn mesh_alignment(
    job: &MeshAlignmentJob,
    mut on_run: impl FnMut(&MeshRecord),
) -> Result<Vec<MeshRecord>> {
    let device = job.backend.device()?;
    let ad = device.clone().autodiff();
    let seq = &job.sequence;
    let data = &seq.trajectories;
    let faces = seq.faces.clone().ok_or_else(|| {
        DomaError::InvalidData(format!(
            "mesh_alignment needs faces for {}: give --mesh",
            seq.name
        ))
    })?;
    let template =
        TriMesh::new(as_points(data.frame(0)), faces.clone()).map_err(DomaError::InvalidData)?;
    let n_key = job.keypoints.min(data.points());
    let (key_idx, _) = split_indices(
        data.points(),
        n_key as f64 / data.points() as f64,
        job.config.seed,
    )?;
    let task = RegistrationTask {
        template: template.clone(),
        keypoints: data.select_points(&key_idx)?,
        targets: data.clone(),
        target_faces: faces.clone(),
    };
    let edges = unique_edges(&faces);
    let mut records = Vec::new();
    for &model in &job.models {
        for &reg in &job.regs {
            let aiap = matches!(reg, AlignReg::A | AlignReg::Ah);
            let h = matches!(reg, AlignReg::H | AlignReg::Ah);
            let config = job
                .config
                .clone()
                .with_aiap_weight(if aiap { job.aiap_weight } else { 0.0 })
                .with_smoothness_weight(if h { job.h_weight } else { 0.0 });
            let seed = job.config.seed;
            // Each model is fitted, evaluated and sized by the same code.
            let (warped, params, bytes, seconds) = match model {
                AlignModel::Dpf => {
                    let field = DpfConfig::new(data.frames())
                        .with_hidden(job.hidden)
                        .with_n_hidden(job.n_hidden)
                        .init(seed, &ad);
                    let f = register(field, &task, &config, &device)?;
                    summarise(f.field, f.seconds, &template, data.frames(), &device)?
                }
                AlignModel::Trans | AlignModel::Affinity => {
                    let variant = if model == AlignModel::Trans {
                        Variant::Trans
                    } else {
                        Variant::Affinity
                    };
                    let field = DomaFieldConfig::new(variant)
                        .with_hidden(job.hidden)
                        .with_n_hidden(job.n_hidden)
                        .init(seed, &ad);
                    let f = register(field, &task, &config, &device)?;
                    summarise(f.field, f.seconds, &template, data.frames(), &device)?
                }
            };
            let (cd, cdn) = mesh_chamfer(&warped, data, &faces, job.samples, seed)?;
            let record = MeshRecord {
                experiment: "mesh_alignment".into(),
                sequence: seq.name.clone(),
                variant: model.paper_name().into(),
                reg: reg.name().into(),
                iters: job.config.iterations,
                backend: job.backend,
                epe_x1e4: None,
                cd_x1e4: Some(cd * CD_SCALE),
                cdn: Some(cdn),
                std_e: Some(std_edges(&warped, &edges)? * STD_SCALE),
                std_v: Some(std_vertices(&warped)? * STD_SCALE),
                params,
                checkpoint_bytes: bytes,
                seconds,
            };
            on_run(&record);
            records.push(record);
        }
    }
    Ok(records)
}

/// The warped template in every frame, the parameter count and the checkpoint size.
fn summarise<M: MotionField + burn::module::Module>(
    field: M,
    seconds: f64,
    template: &TriMesh,
    frames: usize,
    device: &burn::tensor::Device,
) -> Result<(Trajectories, usize, u64, f64)> {
    let warped = warp_mesh_sequence(&field, template, frames, device)?;
    let params = field.param_count();
    let bytes = encode_checkpoint(field, Precision::F32)?.len() as u64;
    Ok((warped, params, bytes, seconds))
}

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

/// The records as a table: one row per run, the metrics that apply as columns.
pub fn table(records: &[MeshRecord]) -> String {
    let mut out = format!(
        "{:<22} {:>10} {:>10} {:>8} {:>9} {:>9} {:>10} {:>12} {:>9}\n",
        "model",
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
        let reg = match r.reg.as_str() {
            "none" => String::new(),
            other => format!("-{}", other.to_uppercase()),
        };
        out += &format!(
            "{:<22} {:>10} {:>10} {:>8} {:>9} {:>9} {:>10} {:>12} {:>9.1}\n",
            format!("{}{reg}", r.variant),
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

/// Writes the records as a JSON array, atomically.
pub fn write_json(path: &Path, records: &[MeshRecord]) -> Result<()> {
    crate::checkpoint::save_json(&records, path)
}

/// The default data of the mesh experiments: `data/cdp_male_wave.traj` in the crate.
pub fn default_data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/cdp_male_wave.traj")
}
