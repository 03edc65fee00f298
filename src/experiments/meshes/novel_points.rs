//! `novel_points` (after Tab. 1): fit on 25 % of an animated mesh's vertices, predict the
//! other 75 %; EPE, and CD/CDN of the warped canonical mesh.

use super::{CD_SCALE, MeshRecord, mesh_chamfer};
use crate::backend::BackendKind;
use crate::checkpoint::Precision;
use crate::data::Trajectories;
use crate::data::mesh::{TriMesh, as_points};
use crate::data::sequence::{Sequence, split_indices};
use crate::experiments::Experiment;
use crate::field::Variant;
use crate::field::baselines::Baseline;
use crate::field::model::{Model, ModelConfig, ModelName};
use crate::jacobian::JacobianKind;
use crate::metrics::{EPE_SCALE, evaluate_epe};
use crate::prelude::*;
use crate::train::{FitConfig, Fitted, Trainer};
use crate::warp::warp_mesh_sequence;
use crate::{DomaError, Result};

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
            reg: super::AlignReg::None,
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
