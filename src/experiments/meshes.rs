//! The mesh experiments: `novel_points` (after Tab. 1: fit on 25 % of an animated mesh's
//! vertices, predict the other 75 %) and `mesh_alignment` (after Tab. 3: align the frame-0
//! template to per-frame target surfaces with sparse guidance keypoints, Eq. 14).
//!
//! Both read any user's sequence ([`load_sequence`]: `.traj` with an optional OBJ for the
//! faces, `.anime`, `.npy`/`.npz`, a clip `A..B` with a stride) and write one
//! [`MeshRecord`] per run.

use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::backend::BackendKind;
use crate::checkpoint::Precision;
use crate::data::Trajectories;
use crate::data::mesh::{SurfaceSamples, TriMesh, as_points, unique_edges};
use crate::data::sequence::{Sequence, split_indices};
use crate::experiments::Experiment;
use crate::field::baselines::Baseline;
use crate::field::dpf::DpfConfig;
use crate::field::model::{Model, ModelConfig, ModelName};
use crate::field::{DomaFieldConfig, MotionField, Variant};
use crate::jacobian::JacobianKind;
use crate::metrics::{EPE_SCALE, chamfer_with_normals, evaluate_epe, std_edges, std_vertices};
use crate::prelude::*;
use crate::register::{RegistrationConfig, RegistrationTask, register};
use crate::siren::SirenShape;
use crate::train::{FitConfig, Fitted, Trainer};
use crate::warp::warp_mesh_sequence;
use crate::{DomaError, Result};

/// Chamfer distances are reported ×1e4 (REFERENCE §7).
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
    /// The regulariser: `none`, `a`, `h` or `ah`.
    pub reg: AlignReg,
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
    /// The Jacobian method of the SIREN models (their fused value path; `L_H` is off).
    pub jacobian: JacobianKind,
    /// Seeds the split, the weights and the samples.
    pub seed: u64,
    /// No progress bars.
    pub quiet: bool,
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
    let ctx = NovelContext {
        job,
        test: &test,
        full: data,
        canonical: canonical.as_ref(),
        device: &device,
    };
    let mut records = Vec::new();
    for model in job.models(data.frames()) {
        let config = job.fit_config(model);
        let fitted = Trainer::from_config(&config, &train, &device)?
            .progress(!job.quiet)
            .run()?;
        let record = ctx.record(config.model.name(), fitted)?;
        on_run(&record);
        records.push(record);
    }
    Ok(records)
}

impl NovelPointsJob {
    /// The models to fit, in the table's order: the variants, then the baselines for a
    /// `frames`-frame sequence.
    pub fn models(&self, frames: usize) -> Vec<ModelConfig> {
        let variants = self.variants.iter().map(|&v| ModelConfig::doma(v));
        variants
            .chain(self.baselines.iter().map(|b| b.config(frames)))
            .collect()
    }

    /// The fit of `model`: the job's budget and seed, the baseline's learning rate, and
    /// the job's Jacobian method where it applies (a SIREN model); the others are
    /// differentiated by autodiff, the only method that applies to them.
    pub fn fit_config(&self, model: ModelConfig) -> FitConfig {
        let jacobian = if model.is_siren() {
            self.jacobian
        } else {
            JacobianKind::Autodiff
        };
        let lr = match &model {
            ModelConfig::BoneCloud(_) => Baseline::BoneCloud.learning_rate(),
            _ => 1e-4,
        };
        let base = match &model {
            ModelConfig::Doma(field) => FitConfig::doma(field.clone()),
            other => FitConfig::new(other.clone()),
        };
        base.with_iterations(self.iterations)
            .with_learning_rate(lr)
            .with_jacobian(jacobian)
            .with_seed(self.seed)
    }
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
    fn record(&self, name: ModelName, fitted: Fitted<Model>) -> Result<MeshRecord> {
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
            experiment: Experiment::NovelPoints,
            sequence: job.sequence.name.clone(),
            variant: name,
            reg: AlignReg::None,
            iters: job.iterations,
            backend: job.backend,
            epe_x1e4: Some(epe * EPE_SCALE),
            cd_x1e4: cd,
            cdn,
            std_e: None,
            std_v: None,
            params: fitted.field.param_count(),
            checkpoint_bytes: fitted.field.encode(Precision::F32)?.len() as u64,
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
    /// The model with SIREN body `shape`, for a `frames`-frame sequence.
    pub fn config(self, frames: usize, shape: SirenShape) -> ModelConfig {
        let doma = |v| ModelConfig::Doma(DomaFieldConfig::new(v).with_shape(shape.clone()));
        match self {
            AlignModel::Dpf => ModelConfig::Dpf(DpfConfig::new(frames).with_shape(shape)),
            AlignModel::Trans => doma(Variant::Trans),
            AlignModel::Affinity => doma(Variant::Affinity),
        }
    }

    /// The paper's row name.
    pub fn name(self) -> ModelName {
        match self {
            AlignModel::Dpf => ModelName::Dpf,
            AlignModel::Trans => ModelName::DomaTrans,
            AlignModel::Affinity => ModelName::DomaAffinity,
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
    /// No progress bars.
    pub quiet: bool,
}

impl MeshAlignmentJob {
    /// The model config of `model` at the job's SIREN shape, for `frames` frames.
    pub fn model(&self, model: AlignModel, frames: usize) -> ModelConfig {
        let shape = SirenShape::new()
            .with_hidden(self.hidden)
            .with_n_hidden(self.n_hidden);
        model.config(frames, shape)
    }
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
            let field = job.model(model, data.frames()).init(seed, &[], &ad);
            let fitted = register(field, &task, &config, &device, !job.quiet)?;
            let (warped, params, bytes, seconds) = summarise(
                fitted.field,
                fitted.seconds,
                &template,
                data.frames(),
                &device,
            )?;
            let (cd, cdn) = mesh_chamfer(&warped, data, &faces, job.samples, seed)?;
            let record = MeshRecord {
                experiment: Experiment::MeshAlignment,
                sequence: seq.name.clone(),
                variant: model.name(),
                reg,
                iters: job.config.schedule.iterations,
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
fn summarise(
    field: Model,
    seconds: f64,
    template: &TriMesh,
    frames: usize,
    device: &burn::tensor::Device,
) -> Result<(Trajectories, usize, u64, f64)> {
    let warped = warp_mesh_sequence(&field, template, frames, device)?;
    let params = field.param_count();
    let bytes = field.encode(Precision::F32)?.len() as u64;
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
        let reg = r.reg.suffix();
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

/// The default data of the mesh experiments: `data/cdp_male_wave.traj` in the crate.
pub fn default_data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/cdp_male_wave.traj")
}
