//! `novel_points` (after Tab. 1): fit on 25 % of an animated mesh's vertices, predict the
//! other 75 %; EPE, and CD/CDN of the warped canonical mesh.

use super::{CD_SCALE, MeshRecord, mesh_chamfer_with};
use crate::backend::BackendKind;
use crate::checkpoint::Precision;
use crate::data::Trajectories;
use crate::data::mesh::{TriMesh, as_points};
use crate::data::sequence::{Sequence, split_indices};
use crate::experiments::synthetic::Regularizer;
use crate::experiments::{Experiment, RowReg};
use crate::field::Variant;
use crate::field::baselines::Baseline;
use crate::field::model::{Model, ModelConfig, ModelName};
use crate::jacobian::JacobianKind;
use crate::metrics::{EPE_SCALE, evaluate_epe};
use crate::prelude::*;
use crate::train::select::{Penalty, Weight, WeightChoice, WeightSearch, choose_weight};
use crate::train::{FitConfig, Fitted, RecipeChoice, Trainer};
use crate::warp::warp_points;
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
    /// Iterations per fit (the budget: a fit that stops on convergence runs fewer).
    pub iterations: usize,
    /// The recipe and the stop on convergence (its iterations give way to `iterations`).
    pub recipe: RecipeChoice,
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
    /// The regularisers: one row per model and regulariser (Tab. 2's "", "-H", "-E").
    pub regs: Vec<Regularizer>,
    /// `w_H` of the "-H" rows: a number, or chosen by validation.
    pub h_weight: Weight,
    /// `w_E` of the "-E" rows.
    pub e_weight: Weight,
    /// How an `auto` weight is searched.
    pub search: WeightSearch,
}

/// Runs `novel_points`: one record per model and regulariser, `on_run` after each.
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
        for &reg in &job.regs {
            let (config, search) =
                job.regularised(job.fit_config(model.clone()), reg, &train, &device)?;
            let fitted = Trainer::from_config(&config, &train, &device)?
                .progress(!job.quiet)
                .run()?;
            let mut record = ctx.record(config.model.name(), fitted)?;
            record.reg = reg.into();
            record.weight = match reg {
                Regularizer::None => None,
                Regularizer::H => Some(config.loss.smoothness_weight),
                Regularizer::E => Some(config.loss.elasticity_weight),
            };
            record.weight_search = search;
            on_run(&record);
            records.push(record);
        }
    }
    Ok(records)
}

impl NovelPointsJob {
    /// `config` with `reg`'s weight: as given, or searched on the training points
    /// `train` (the held-out points are not passed, so they cannot be read).
    pub fn regularised(
        &self,
        config: FitConfig,
        reg: Regularizer,
        train: &Trajectories,
        device: &burn::tensor::Device,
    ) -> Result<(FitConfig, Option<WeightChoice>)> {
        let (penalty, weight) = match reg {
            Regularizer::None => return Ok((config, None)),
            Regularizer::H => (Penalty::Smoothness, self.h_weight),
            Regularizer::E => (Penalty::Elasticity, self.e_weight),
        };
        match weight {
            Weight::Fixed(w) => Ok((penalty.with_weight(&config, w), None)),
            Weight::Auto => {
                let name = config.model.name();
                let choice = choose_weight(&config, penalty, train, &self.search, device, |p| {
                    if !self.quiet {
                        eprintln!(
                            "  {name}{}: weight {:e}: validation EPE {:.2}e-4",
                            RowReg::from(reg).suffix(),
                            p.weight,
                            p.validation_epe_x1e4
                        );
                    }
                })?;
                Ok((penalty.with_weight(&config, choice.weight), Some(choice)))
            }
        }
    }

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
            ModelConfig::Banmo(_) => Baseline::Banmo.learning_rate(),
            _ => 1e-4,
        };
        let base = match &model {
            ModelConfig::Doma(field) => FitConfig::doma(field.clone()),
            other => FitConfig::new(other.clone()),
        };
        self.recipe
            .apply(base.with_learning_rate(lr))
            .with_iterations(self.iterations)
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
                let frames = self.full.frames();
                let warp = |k| {
                    let t = crate::data::normalized_time(k, frames);
                    warp_points(&fitted.field, &mesh.vertices, t, device)
                };
                let (cd, cdn) =
                    mesh_chamfer_with(warp, self.full, &mesh.faces, job.samples, job.seed)?;
                (Some(cd * CD_SCALE), Some(cdn))
            }
            None => (None, None),
        };
        Ok(MeshRecord {
            experiment: Experiment::NovelPoints,
            sequence: job.sequence.name.clone(),
            variant: name,
            reg: RowReg::None,
            weight: None,
            weight_search: None,
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
