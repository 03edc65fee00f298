//! From a [`RunSpec`] to what a fit runs: its [`FitConfig`] (the defaults, a config file,
//! the recipe and the flags, in that order), its [`RunConfig`], and a [`NewFit`] with its
//! data read once.

use std::path::{Path, PathBuf};

use super::{
    GAP_FILLING_FRAMES_PER_ITERATION, GAP_FILLING_H_WEIGHT, GAP_FILLING_ITERATIONS, ModelChoice,
    RunSpec, check_fraction, check_held_fraction,
};
use crate::backend::BackendKind;
use crate::data::layout::TrackFile;
use crate::data::sequence::Sequence;
use crate::field::dpf::DpfConfig;
use crate::field::model::ModelConfig;
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::loss::DataPenalty;
use crate::run::RunConfig;
use crate::train::select::Weight;
use crate::train::select::{Penalty, WeightSearch, choose_weight};
use crate::train::{FitConfig, RecipeChoice, SmoothnessSampling};
use crate::{DomaError, Result};

impl RunSpec {
    /// `self` with every field it leaves unset taken from `defaults`.
    pub fn or(self, defaults: &RunSpec) -> Result<RunSpec> {
        let fields = |spec: &RunSpec| match serde_json::to_value(spec) {
            Ok(serde_json::Value::Object(m)) => Ok(m),
            other => Err(DomaError::InvalidData(format!(
                "fit options do not serialise to an object: {other:?}"
            ))),
        };
        let mut merged = fields(defaults)?;
        merged.extend(fields(&self)?);
        serde_json::from_value(serde_json::Value::Object(merged))
            .map_err(|e| DomaError::InvalidConfig(format!("fit options: {e}")))
    }

    /// Refuses values no fit can take, naming the field: a count of 0, a fraction outside
    /// `(0, 1)` (`[0, 1)` for `test_fraction`). The command line's parsers refuse them before; JSON and Python reach here.
    pub fn validate(&self) -> Result<()> {
        let counts = [
            ("iterations", self.iterations),
            ("stride", self.stride),
            ("checkpoint_every", self.checkpoint_every),
            ("points_per_step", self.points_per_step),
            ("frames_per_step", self.frames_per_step),
            ("frames_per_iteration", self.frames_per_iteration),
            ("until_converged", self.until_converged),
        ];
        if let Some((name, Some(n))) = counts.iter().find(|(_, n)| *n == Some(0)) {
            return Err(DomaError::InvalidConfig(format!(
                "{name}: {n} is not at least 1"
            )));
        }
        if let Some(f) = self.test_fraction {
            check_held_fraction(f)
                .map_err(|e| DomaError::InvalidConfig(format!("test_fraction: {e}")))?;
        }
        if let Some(p) = self.visibility_threshold
            && !(p > 0.0 && p <= 1.0)
        {
            return Err(DomaError::InvalidConfig(format!(
                "visibility_threshold: {p} is not a probability in (0, 1]"
            )));
        }
        if let Some([a, b]) = self.holdout_span
            && (a == 0 || a > b)
        {
            return Err(DomaError::InvalidConfig(format!(
                "holdout_span: [{a}, {b}] must be lengths of at least 1 frame, shortest first"
            )));
        }
        if let Some(f) = self.holdout_observations {
            check_fraction(f)
                .map_err(|e| DomaError::InvalidConfig(format!("holdout_observations: {e}")))?;
        }
        Ok(())
    }

    /// `self` with its relative paths (data, config, mesh) taken relative to `base`.
    pub fn relative_to(mut self, base: &Path) -> RunSpec {
        for p in [&mut self.data, &mut self.config, &mut self.mesh]
            .into_iter()
            .flatten()
        {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        }
        self
    }

    /// The fit recipe: the `config` file (or the defaults: DOMA-Affinity, analytic
    /// Jacobian), then the overrides over it. A DPF model needs the clip's frame count,
    /// `frames`.
    pub fn fit_config(&self, frames: impl FnOnce() -> Result<usize>) -> Result<FitConfig> {
        let mut fit = match &self.config {
            Some(path) => FitConfig::load_partial(path)?,
            None => FitConfig::doma(DomaFieldConfig::new(Variant::Affinity))
                .with_jacobian(JacobianKind::Analytic),
        };
        let shape = match &fit.model {
            ModelConfig::Doma(c) => c.shape.clone(),
            ModelConfig::Dpf(c) => c.shape.clone(),
            _ => crate::siren::SirenShape::new(),
        };
        match self.model.map(|m| (m, m.variant())) {
            Some((_, Some(v))) => {
                fit.model = ModelConfig::Doma(DomaFieldConfig::new(v).with_shape(shape));
                fit.smoothness_sampling = SmoothnessSampling::authors(v);
            }
            Some((_, None)) => {
                fit.model = ModelConfig::Dpf(DpfConfig::new(frames()?).with_shape(shape));
            }
            None => {}
        }
        if let Some(a) = self.init_scale {
            match &mut fit.model {
                ModelConfig::Doma(c) => c.shape.init_scale = Some(a),
                ModelConfig::Dpf(c) => c.shape.init_scale = Some(a),
                other => {
                    return Err(DomaError::InvalidConfig(format!(
                        "init_scale: the {} model has no SIREN to scale",
                        other.name()
                    )));
                }
            }
        }
        if let Some(s) = self.time_scale {
            match &mut fit.model {
                ModelConfig::Doma(c) => c.time_scale = Some(s),
                other => {
                    return Err(DomaError::InvalidConfig(format!(
                        "time_scale: the {} model reads no time through a DOMA field",
                        other.name()
                    )));
                }
            }
        }
        // After the model (whose variant sets the `L_H` sampling), before the flags.
        let mut fit = RecipeChoice {
            recipe: self.recipe,
            until_converged: self.until_converged,
        }
        .apply(fit);
        if let Some(j) = self.jacobian {
            fit.jacobian = j;
        }
        if self.step.is_some() {
            fit.step = self.step;
        }
        if let Some(o) = self.optimizer {
            fit.soap = o.soap();
        }
        if let Some(i) = self.iterations {
            fit.schedule.iterations = i;
        }
        if let Some(lr) = self.learning_rate {
            fit.schedule.learning_rate = lr;
        }
        if let Some(Weight::Fixed(w)) = self.h_weight {
            fit.loss.smoothness_weight = w;
        }
        if self.t_weight.is_some() {
            fit.loss.temporal_weight = self.t_weight;
        }
        if let Some(s) = self.seed {
            fit.seed = s;
        }
        if self.points_per_step.is_some() {
            fit.points_per_step = self.points_per_step;
        }
        if self.frames_per_step.is_some() {
            fit.frames_per_step = self.frames_per_step;
        }
        if self.frames_per_iteration.is_some() {
            fit.frames_per_iteration = self.frames_per_iteration;
        }
        if let Some(p) = self.robust {
            fit.loss.data_penalty = (p != DataPenalty::L1).then_some(p);
        }
        // A user's fit takes the fused step where it applies (the experiments keep the
        // paper's composed step unless asked).
        fit.step = fit.step.or(Some(crate::train::StepKind::Auto));
        Ok(fit)
    }

    /// The run config of this fit without its data read: what the options say, checked
    /// where the data is not needed. A DPF model's frame count is set by
    /// [`RunSpec::prepare`], from the data.
    pub(crate) fn run_config(&self) -> Result<RunConfig> {
        let data = self
            .data
            .as_deref()
            .ok_or_else(|| DomaError::Usage("no data given".into()))?;
        let data = absolute(data)?;
        let mut config = RunConfig::new(
            data,
            FitConfig::doma(DomaFieldConfig::new(Variant::Affinity)),
        );
        config.mesh = self.mesh.as_deref().map(absolute).transpose()?;
        config.frames = self.frames;
        config.stride = self.stride.unwrap_or(1);
        config.backend = self.backend.unwrap_or(BackendKind::Flex);
        if let Some(t) = self.test_fraction {
            config.test_fraction = t;
        }
        if let Some(k) = self.checkpoint_every {
            config.checkpoint_every = k;
        }
        config.tracks = TrackFile {
            layout: self.layout,
            frame: self.frame,
            count_hidden: self.count_hidden.unwrap_or(false),
            confidence: self.confidence.clone(),
            visibility_threshold: self.visibility_threshold,
        };
        config.reference_frame = self.reference_frame;
        config.drop_unobserved = self.drop_unobserved.unwrap_or(false);
        config.model_outputs = self.model_outputs.unwrap_or(false);
        config.holdout_observations = self.holdout_observations;
        config.holdout_span = self.holdout_span;
        config.blind_validation = self.blind_validation.unwrap_or(true);
        config.fits = self.fits.unwrap_or(1);
        if let Some([a, b]) = self.frames
            && a >= b
        {
            return Err(DomaError::InvalidConfig(format!(
                "the clip {a}..{b} holds no frame"
            )));
        }
        // The frame count of a DPF model is the data's; 1 stands in until it is read.
        config.fit = self.fit_config(|| Ok(1))?;
        Ok(config)
    }

    /// The new fit these options ask for, with its data read once: the run config,
    /// checked, and the sequence that [`crate::run::fit_run`] fits. With `h_weight = auto`, the
    /// weight search runs here, on the same sequence (`search`; `on_weight` hears each
    /// weight's validation EPE).
    pub fn prepare(
        &self,
        search: &WeightSearch,
        on_weight: impl FnMut(&crate::train::select::GridPoint),
    ) -> Result<NewFit> {
        self.validate()?;
        let mut config = self.run_config()?;
        config.validate()?;
        let sequence = config.load()?;
        if let ModelConfig::Dpf(dpf) = &mut config.fit.model
            && self.model == Some(ModelChoice::Dpf)
        {
            dpf.frames = sequence.trajectories.frames();
            // Its size is known now.
            config.validate()?;
        }
        // A long recording's field reads its time stretched, unless the options or the
        // config file chose a scale.
        if let ModelConfig::Doma(c) = &mut config.fit.model
            && c.time_scale.is_none()
        {
            c.time_scale = crate::field::time_scale_for(sequence.trajectories.frames());
        }
        // Sparse tracks with gaps: the gap-filling defaults where the options set nothing
        // (docs/gap-filling.md, real markers: without L_H the field strays inside gaps, and
        // more iterations did not fill them better).
        let gaps = matches!(config.fit.model, ModelConfig::Doma(_))
            && sequence
                .trajectories
                .observed()
                .is_some_and(|o| o.iter().any(|&seen| !seen));
        if gaps && self.config.is_none() {
            if self.h_weight.is_none() {
                config.fit.loss.smoothness_weight = GAP_FILLING_H_WEIGHT;
            }
            if self.iterations.is_none() && self.recipe.is_none() && self.until_converged.is_none()
            {
                config.fit.schedule.iterations = GAP_FILLING_ITERATIONS;
            }
            if self.frames_per_iteration.is_none() {
                config.fit.frames_per_iteration = Some(GAP_FILLING_FRAMES_PER_ITERATION);
            }
        }
        let mut fit = NewFit { config, sequence };
        fit.check()?;
        if self.h_weight == Some(Weight::Auto) {
            search.validate()?;
            let (train, _) = fit.config.split(&fit.sequence.trajectories)?;
            let device = fit.config.backend.device()?;
            let choice = choose_weight(
                &fit.config.fit,
                Penalty::Smoothness,
                &train,
                search,
                &device,
                on_weight,
            )?;
            fit.config.fit.loss.smoothness_weight = choice.weight;
            fit.config.weight_search = Some(choice);
        }
        Ok(fit)
    }
}

/// A new fit, ready to start: its run config and its data, read once
/// ([`RunConfig::load`]: clipped, normalised, held-out observations hidden). Made by
/// [`RunSpec::prepare`] from options, or by [`NewFit::load`] from a run config.
pub struct NewFit {
    /// What is fitted and how; `config.json` of the run.
    pub config: RunConfig,
    /// The data, as `config` reads it.
    pub sequence: Sequence,
}

impl NewFit {
    /// `config`'s fit, with its data read and checked against it.
    pub fn load(config: RunConfig) -> Result<NewFit> {
        config.validate()?;
        let sequence = config.load()?;
        let fit = NewFit { config, sequence };
        fit.check()?;
        Ok(fit)
    }

    /// Refuses a split or a model that the data cannot take.
    fn check(&self) -> Result<()> {
        self.config
            .split_indices(self.sequence.trajectories.points())?;
        self.config
            .fit
            .model
            .check_frames(self.sequence.trajectories.frames())
    }
}

/// `path` made absolute without resolving symbolic links: a link's own name keeps its
/// extension (git-annex, DVC and download caches point at extension-less blobs).
fn absolute(path: &Path) -> Result<PathBuf> {
    let abs = std::path::absolute(path).map_err(|e| DomaError::io(path, e))?;
    // The file must exist now; a fit that starts cannot find it later.
    std::fs::metadata(&abs).map_err(|e| DomaError::io(path, e))?;
    Ok(abs)
}
