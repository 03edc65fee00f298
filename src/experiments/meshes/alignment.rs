//! `mesh_alignment` (after Tab. 3): align the frame-0 template to per-frame target surfaces
//! with sparse guidance keypoints (Eq. 14); CD, CDN, STD(E), STD(V).

use serde::{Deserialize, Serialize};

use super::{CD_SCALE, MeshRecord, STD_SCALE, mesh_chamfer};
use crate::backend::BackendKind;
use crate::checkpoint::Precision;
use crate::data::mesh::{TriMesh, as_points, unique_edges};
use crate::data::sequence::{Sequence, split_indices};
use crate::experiments::Experiment;
use crate::field::dpf::DpfConfig;
use crate::field::model::{ModelConfig, ModelName};
use crate::field::{DomaFieldConfig, Variant};
use crate::metrics::{std_edges, std_vertices};
use crate::prelude::*;
use crate::register::{RegistrationConfig, RegistrationTask, register};
use crate::siren::SirenShape;
use crate::warp::warp_mesh_sequence;
use crate::{DomaError, Result};

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
    /// The registration task: the frame-0 template, a fixed seeded subset of the vertices
    /// as guidance keypoints, and every frame's true surface as a target.
    pub fn task(&self) -> Result<RegistrationTask> {
        let seq = &self.sequence;
        let data = &seq.trajectories;
        let faces = seq.faces.clone().ok_or_else(|| {
            DomaError::InvalidData(format!(
                "mesh_alignment needs faces for {}: give --mesh",
                seq.name
            ))
        })?;
        let template = TriMesh::new(as_points(data.frame(0)), faces.clone())
            .map_err(DomaError::InvalidData)?;
        let n_key = self.keypoints.min(data.points());
        let fraction = n_key as f64 / data.points() as f64;
        let (key_idx, _) = split_indices(data.points(), fraction, self.config.seed)?;
        Ok(RegistrationTask {
            template,
            keypoints: data.select_points(&key_idx)?,
            targets: data.clone(),
            target_faces: faces,
        })
    }

    /// The loop's config for `reg`: the AIAP and `L_H` weights on or off.
    pub fn config_for(&self, reg: AlignReg) -> RegistrationConfig {
        let aiap = matches!(reg, AlignReg::A | AlignReg::Ah);
        let h = matches!(reg, AlignReg::H | AlignReg::Ah);
        self.config
            .clone()
            .with_aiap_weight(if aiap { self.aiap_weight } else { 0.0 })
            .with_smoothness_weight(if h { self.h_weight } else { 0.0 })
    }

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
    let data = &job.sequence.trajectories;
    // Every model's size is checked before anything is built: an allocation too large
    // for memory aborts the process rather than failing.
    for &model in &job.models {
        job.model(model, data.frames()).validate()?;
    }
    let device = job.backend.device()?;
    let ad = device.clone().autodiff();
    let task = job.task()?;
    let edges = unique_edges(&task.target_faces);
    let mut records = Vec::new();
    for &model in &job.models {
        for &reg in &job.regs {
            let config = job.config_for(reg);
            let seed = job.config.seed;
            let field = job.model(model, data.frames()).init(seed, &[], &ad);
            let fitted = register(field, &task, &config, &device, !job.quiet)?;
            let warped = warp_mesh_sequence(&fitted.field, &task.template, data.frames(), &device)?;
            let (cd, cdn) = mesh_chamfer(&warped, data, &task.target_faces, job.samples, seed)?;
            let record = MeshRecord {
                experiment: Experiment::MeshAlignment,
                sequence: job.sequence.name.clone(),
                variant: model.name(),
                reg: reg.into(),
                weight: match reg {
                    AlignReg::None => None,
                    AlignReg::A => Some(job.aiap_weight),
                    AlignReg::H | AlignReg::Ah => Some(job.h_weight),
                },
                weight_search: None,
                iters: job.config.schedule.iterations,
                backend: job.backend,
                epe_x1e4: None,
                cd_x1e4: Some(cd * CD_SCALE),
                cdn: Some(cdn),
                std_e: Some(std_edges(&warped, &edges)? * STD_SCALE),
                std_v: Some(std_vertices(&warped)? * STD_SCALE),
                params: fitted.field.param_count(),
                checkpoint_bytes: fitted.field.encode(Precision::F32)?.len() as u64,
                seconds: fitted.seconds,
            };
            on_run(&record);
            records.push(record);
        }
    }
    Ok(records)
}

crate::names::value_names!(AlignModel, AlignReg);
