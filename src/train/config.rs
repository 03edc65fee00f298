//! The recipe of a fit, saved as a run's `config.json`: the model, the optimiser, the
//! schedule, the loss weights and the `L_H` sample points, each an explicit field.

use std::path::Path;

use burn::config::Config;
use burn::optim::AdamConfig;
use serde_json::Value;

use super::schedule::{Convergence, ScheduleConfig, default_adam};
use crate::field::model::ModelConfig;
use crate::field::{DomaFieldConfig, Variant};
use crate::gaps::blend::Validation;
use crate::io::{merge, read_object, unknown_field};
use crate::jacobian::JacobianKind;
use crate::loss::{DataPenalty, SmoothnessNorm};
use crate::{DomaError, Result};

/// The builders of a config that nests a [`ScheduleConfig`] (a fit's, a registration's),
/// written once: `FitConfig::doma(field).with_iterations(200)`.
pub trait WithSchedule: Sized {
    /// The nested schedule.
    fn schedule_mut(&mut self) -> &mut ScheduleConfig;

    /// Sets the number of iterations.
    fn with_iterations(mut self, iterations: usize) -> Self {
        self.schedule_mut().iterations = iterations;
        self
    }

    /// Sets Adam's base learning rate.
    fn with_learning_rate(mut self, learning_rate: f64) -> Self {
        self.schedule_mut().learning_rate = learning_rate;
        self
    }
}

impl WithSchedule for FitConfig {
    fn schedule_mut(&mut self) -> &mut ScheduleConfig {
        &mut self.schedule
    }
}

/// Refuses the first of `weights` (name, value) that is negative or not finite.
pub fn check_weights(weights: &[(&str, f64)]) -> Result<()> {
    match weights.iter().find(|(_, w)| !(w.is_finite() && *w >= 0.0)) {
        Some((name, w)) => Err(DomaError::InvalidConfig(format!(
            "{name} {w} must be finite and non-negative"
        ))),
        None => Ok(()),
    }
}

/// The weights of the regularisers next to the trajectory L1.
#[derive(Config, Debug, PartialEq)]
pub struct LossConfig {
    /// The weight `w_H` of the smoothness loss `L_H` (Eq. 13; 0 = off; the paper's "-H"
    /// uses 0.1).
    #[config(default = 0.0)]
    pub smoothness_weight: f64,
    /// The per-entry penalty of `L_H`.
    #[config(default = "SmoothnessNorm::Squared")]
    pub smoothness_norm: SmoothnessNorm,
    /// The weight `w_E` of the elasticity loss (0 = off).
    #[config(default = 0.0)]
    pub elasticity_weight: f64,
    /// The per-coordinate penalty of the trajectory loss: a robust one for tracks with
    /// outliers (`None`: the paper's L1; a config without the field reads as `None`).
    pub data_penalty: Option<DataPenalty>,
    /// The weight `w_T` of the temporal smoothness loss `L_T` ([`crate::loss::acceleration`];
    /// not in the paper; `None` or 0: off).
    pub temporal_weight: Option<f64>,
}

impl LossConfig {
    /// Refuses negative or non-finite weights, and a robust penalty's bad scale.
    pub fn validate(&self) -> Result<()> {
        check_weights(&[
            ("smoothness weight", self.smoothness_weight),
            ("elasticity weight", self.elasticity_weight),
            ("temporal weight", self.temporal_weight()),
        ])?;
        self.penalty().validate().map_err(DomaError::InvalidConfig)
    }

    /// The weight `w_T` of `L_T` (0 unless one is set).
    pub fn temporal_weight(&self) -> f64 {
        self.temporal_weight.unwrap_or(0.0)
    }

    /// The trajectory loss's penalty ([`DataPenalty::L1`] unless one is set).
    pub fn penalty(&self) -> DataPenalty {
        self.data_penalty.unwrap_or(DataPenalty::L1)
    }
}

/// Where `L_H` is evaluated: at most `max_points` training points (a fresh random subset
/// each step; `None`: all of them), jittered by Gaussian noise of standard deviation
/// `jitter`.
#[derive(Config, Debug, PartialEq)]
pub struct SmoothnessSampling {
    /// At most this many points carry `L_H` (`None`: every training point).
    pub max_points: Option<usize>,
    /// The standard deviation of the jitter (0: the training points themselves).
    #[config(default = 0.0)]
    pub jitter: f64,
}

impl SmoothnessSampling {
    /// The authors' choice for `variant` (docs/reference.md §4.2): Affinity uses a random subset
    /// of at most 1024 training points jittered by `σ = 0.1`; the other variants use every
    /// training point, unjittered.
    pub fn authors(variant: Variant) -> Self {
        if variant == Variant::Affinity {
            SmoothnessSampling::new()
                .with_max_points(Some(1024))
                .with_jitter(0.1)
        } else {
            SmoothnessSampling::new()
        }
    }

    /// Refuses an empty sample or a negative jitter.
    pub fn validate(&self) -> Result<()> {
        if self.max_points == Some(0) {
            return Err(DomaError::InvalidConfig(
                "smoothness points must be at least 1".into(),
            ));
        }
        if !(self.jitter.is_finite() && self.jitter >= 0.0) {
            return Err(DomaError::InvalidConfig(format!(
                "smoothness jitter {} must be finite and non-negative",
                self.jitter
            )));
        }
        Ok(())
    }
}

/// Everything that defines a fit; saved as a run's `config.json` (under `fit`), so that
/// any run can be reproduced from its folder. Display flags are not part of it.
#[derive(Config, Debug)]
pub struct FitConfig {
    /// The model: a DOMA variant or a baseline.
    pub model: ModelConfig,
    /// Adam's hyper-parameters.
    #[config(default = "default_adam()")]
    pub optimizer: AdamConfig,
    /// Iterations and learning rate.
    #[config(default = "ScheduleConfig::new()")]
    pub schedule: ScheduleConfig,
    /// The regularisers' weights.
    #[config(default = "LossConfig::new()")]
    pub loss: LossConfig,
    /// Where `L_H` is evaluated.
    #[config(default = "SmoothnessSampling::new()")]
    pub smoothness_sampling: SmoothnessSampling,
    /// How the spatial Jacobian is computed (for `L_H`, the elasticity loss, and the
    /// fused value path of SIREN layers).
    #[config(default = "JacobianKind::Autodiff")]
    pub jacobian: JacobianKind,
    /// Seeds the initial weights, the frame order and the `L_H` samples.
    #[config(default = 0)]
    pub seed: u64,
    /// Training points per step: a fresh random subset of this many each step, so that
    /// a step's memory and time do not grow with the number of tracks (`None`: every
    /// training point, the paper's protocol).
    pub points_per_step: Option<usize>,
    /// Frames per Adam step: each step minimises the sum of that many frames' losses, so an
    /// iteration takes `⌈T / frames⌉` steps (`None`: one frame per step, the paper's
    /// protocol).
    pub frames_per_step: Option<usize>,
    /// Frames per iteration: each iteration takes a fresh random subset of this many
    /// frames, so that a fit's cost is a budget of steps that does not grow with the
    /// frame count (`None`, or a count of at least the frames: every frame once per
    /// iteration, the paper's protocol).
    pub frames_per_iteration: Option<usize>,
    /// Stop early once the EPE on held-back training tracks stops improving (`None`: run
    /// the whole budget, the paper's protocol).
    pub until_converged: Option<Convergence>,
    /// How each step is computed: Burn's operations around the Jacobian method, or the
    /// whole step as one CPU operation ([`super::StepKind`]; `None`: composed).
    pub step: Option<super::StepKind>,
    /// The fused step's update: SOAP, Adam in the eigenbasis of Shampoo's factors
    /// ([`super::fused::SoapConfig`]; `None`: Adam, the paper's optimiser). Only the fused
    /// step computes it: a fit that sets it takes fused steps or is refused.
    pub soap: Option<super::fused::SoapConfig>,
    /// The name of the recipe the settings came from ([`super::Recipe`]); a label only:
    /// the settings themselves are the other fields.
    pub recipe: Option<super::Recipe>,
    /// How doma's fill validates its weights, and which spans a fit of tracks with gaps
    /// hides from the field (`None`: [`Validation::default`], today's choices; a config
    /// file may set any of its fields: [`FitConfig::validation`]).
    pub validation: Option<Validation>,
}

impl FitConfig {
    /// A fit of a DOMA field with the authors' `L_H` sampling for its variant
    /// ([`SmoothnessSampling::authors`]).
    pub fn doma(field: DomaFieldConfig) -> Self {
        let sampling = SmoothnessSampling::authors(field.variant);
        FitConfig::new(ModelConfig::Doma(field)).with_smoothness_sampling(sampling)
    }

    /// The validation of doma's fill this config asks for: its own, or the defaults.
    pub fn validation(&self) -> Validation {
        self.validation.clone().unwrap_or_default()
    }

    /// Sets the weight `w_H` of `L_H`.
    pub fn with_smoothness_weight(mut self, weight: f64) -> Self {
        self.loss.smoothness_weight = weight;
        self
    }

    /// Sets the weight `w_E` of the elasticity loss.
    pub fn with_elasticity_weight(mut self, weight: f64) -> Self {
        self.loss.elasticity_weight = weight;
        self
    }

    /// Refuses values that cannot run, and a Jacobian method that does not apply to the
    /// model.
    pub fn validate(&self) -> Result<()> {
        self.schedule.validate()?;
        self.loss.validate()?;
        self.smoothness_sampling.validate()?;
        if self.points_per_step == Some(0) {
            return Err(DomaError::InvalidConfig(
                "points per step must be at least 1".into(),
            ));
        }
        if self.frames_per_step == Some(0) {
            return Err(DomaError::InvalidConfig(
                "frames per step must be at least 1".into(),
            ));
        }
        if self.frames_per_iteration == Some(0) {
            return Err(DomaError::InvalidConfig(
                "frames per iteration must be at least 1".into(),
            ));
        }
        if let Some(c) = &self.until_converged {
            c.validate()?;
        }
        if let Some(soap) = &self.soap {
            soap.check().map_err(DomaError::InvalidConfig)?;
            if self.step.unwrap_or(super::StepKind::Composed) == super::StepKind::Composed {
                return Err(DomaError::InvalidConfig(
                    "SOAP is computed by the fused step only: use --step fused (or auto)".into(),
                ));
            }
        }
        if let Some(v) = &self.validation {
            v.check().map_err(DomaError::InvalidConfig)?;
        }
        self.model.validate()?;
        self.model.check_jacobian(self.jacobian)
    }

    /// Reads a fit config from a JSON file that may give only some fields: the model
    /// defaults to DOMA-Affinity with the analytic Jacobian (what `doma fit` fits), the
    /// `L_H` sampling to the authors' for the file's variant, and every other missing field
    /// to its default. A field that no fit config has (a typo, or a config of another
    /// layout) is refused, so that nothing in the file is silently ignored. Errors name the
    /// file and the field.
    pub fn load_partial(path: &Path) -> Result<Self> {
        let mut fields = read_object(path)?;
        let malformed = |reason: String| DomaError::Malformed {
            path: path.to_path_buf(),
            reason,
        };
        let model = match fields.get("model") {
            Some(m) => serde_json::from_value::<ModelConfig>(merge_model(m))
                .map_err(|e| malformed(format!("model: {e}")))?,
            None => ModelConfig::doma(Variant::Affinity),
        };
        if let Some(m) = fields.get("model") {
            let known = serde_json::to_value(&model)
                .map_err(|e| malformed(format!("cannot serialise the model: {e}")))?;
            if let Some(field) = unknown_field(m, &known, "model") {
                return Err(malformed(format!("no fit config has the field `{field}`")));
            }
        }
        let base = match &model {
            ModelConfig::Doma(field) => FitConfig::doma(field.clone()),
            other => FitConfig::new(other.clone()),
        }
        .with_jacobian(JacobianKind::Analytic);
        fields.remove("model");
        overlay(&base, Value::Object(fields), path)
    }
}

impl FitConfig {
    /// `self` with the fields that the JSON file `path` gives overlaid, object by object
    /// (a recipe written as a file: `{"schedule": {"iterations": 200}}`). A field that no
    /// fit config has is refused; errors name the file and the field.
    pub fn overlaid(&self, path: &Path) -> Result<Self> {
        overlay(self, Value::Object(read_object(path)?), path)
    }
}

/// `base` with `given` (read from `path`) overlaid, refusing a field no fit config has, then
/// checked.
fn overlay(base: &FitConfig, given: Value, path: &Path) -> Result<FitConfig> {
    let malformed = |reason: String| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    };
    let mut merged = serde_json::to_value(base)
        .map_err(|e| malformed(format!("cannot serialise the config: {e}")))?;
    if let Some(field) = unknown_field(&given, &merged, "") {
        return Err(malformed(format!("no fit config has the field `{field}`")));
    }
    merge(&mut merged, given);
    let config: FitConfig = serde_json::from_value(merged).map_err(|e| malformed(e.to_string()))?;
    config.validate().map_err(|e| malformed(e.to_string()))?;
    Ok(config)
}

/// A partial model config filled from its kind's defaults: `{"doma": {"variant": "trans"}}`
/// gets the paper's SIREN shape, `{"dpf": {"frames": 10}}` the paper's DPF.
fn merge_model(given: &Value) -> Value {
    use crate::field::baselines::{
        banmo::BanmoConfig, bone_cloud::BoneCloudConfig, dct::DctConfig, mlp::MlpConfig,
    };
    use crate::field::dpf::DpfConfig;
    let Some((kind, fields)) = given
        .as_object()
        .filter(|o| o.len() == 1)
        .and_then(|o| o.iter().next())
    else {
        return given.clone();
    };
    let frames = fields
        .get("frames")
        .and_then(Value::as_u64)
        .map(|f| f as usize);
    let default = match (kind.as_str(), frames) {
        ("doma", _) => {
            let variant = fields
                .get("variant")
                .and_then(|v| serde_json::from_value::<Variant>(v.clone()).ok())
                .unwrap_or(Variant::Affinity);
            Some(ModelConfig::doma(variant))
        }
        ("mlp", _) => Some(ModelConfig::Mlp(MlpConfig::new())),
        ("dpf", Some(t)) => Some(ModelConfig::Dpf(DpfConfig::new(t))),
        ("dct-nerf", Some(t)) => Some(ModelConfig::DctNerf(DctConfig::new(t))),
        ("banmo", Some(t)) => Some(ModelConfig::Banmo(BanmoConfig::new(t))),
        ("bone-cloud", Some(t)) => Some(ModelConfig::BoneCloud(BoneCloudConfig::new(t))),
        _ => None,
    };
    match default.and_then(|d| serde_json::to_value(d).ok()) {
        Some(mut d) => {
            merge(&mut d, given.clone());
            d
        }
        None => given.clone(),
    }
}
