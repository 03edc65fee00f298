//! The recipe of a fit, saved as a run's `config.json`: the model, the optimiser, the
//! schedule, the loss weights and the `L_H` sample points, each an explicit field.

use std::path::Path;

use burn::config::Config;
use burn::optim::AdamConfig;
use serde_json::Value;

use crate::field::model::ModelConfig;
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::loss::{DataPenalty, SmoothnessNorm};
use crate::{DomaError, Result};

/// Adam as the authors run it: PyTorch's defaults, `ε = 1e-8`.
pub fn default_adam() -> AdamConfig {
    AdamConfig::new().with_epsilon(1e-8)
}

/// The shape of the learning rate after its flat (or warm-up) start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Decay {
    /// The authors' LambdaLR: a linear decay towards 0 at the end of the budget.
    Linear,
    /// A half cosine from the base rate towards 0 at the end of the budget.
    Cosine,
}

/// The learning-rate schedule: `iterations` passes over the frames, Adam's base rate, and
/// the authors' LambdaLR (flat, then a linear decay), or a linear warm-up followed by a
/// cosine decay for shorter budgets.
#[derive(Config, Debug, PartialEq)]
pub struct ScheduleConfig {
    /// Iterations (passes over all frames); the paper's budget is 1000.
    #[config(default = 1000)]
    pub iterations: usize,
    /// Adam's base learning rate (1e-4 for the DOMA variants).
    #[config(default = 1e-4)]
    pub learning_rate: f64,
    /// Iterations at the full learning rate before the linear decay (the authors' 10 for
    /// a fit, 0 for a registration).
    #[config(default = 10)]
    pub lr_flat_iterations: usize,
    /// The decay after the start (`None`: the authors' linear one; a config without the
    /// field reads as `None`).
    pub decay: Option<Decay>,
    /// With [`Decay::Cosine`]: iterations of linear warm-up from `lr / warmup` to `lr`
    /// (`None` or 0: none).
    pub warmup_iterations: Option<usize>,
}

impl ScheduleConfig {
    /// The learning-rate factor during iteration `e` (0-based): 1 for the first
    /// `lr_flat_iterations + 1` iterations, then a linear decay,
    /// `1 − (e − flat) / (iterations − flat + 1)` (the authors' LambdaLR).
    ///
    /// With [`Decay::Cosine`]: `(e + 1) / w` during the `w` warm-up iterations, then
    /// `½ (1 + cos(π (e − w) / (iterations − w)))`.
    pub fn lr_factor(&self, e: usize) -> f64 {
        if self.decay == Some(Decay::Cosine) {
            let warmup = self.warmup_iterations.unwrap_or(0);
            if e < warmup {
                return (e + 1) as f64 / warmup as f64;
            }
            let span = self.iterations.saturating_sub(warmup).max(1) as f64;
            let p = ((e - warmup) as f64 / span).min(1.0);
            return 0.5 * (1.0 + (std::f64::consts::PI * p).cos());
        }
        let flat = self.lr_flat_iterations;
        if e <= flat {
            1.0
        } else {
            1.0 - (e - flat) as f64 / (self.iterations + 1 - flat) as f64
        }
    }

    /// The learning rate during iteration `e`.
    pub fn learning_rate_at(&self, e: usize) -> f64 {
        self.learning_rate * self.lr_factor(e)
    }

    /// Refuses values that cannot run.
    pub fn validate(&self) -> Result<()> {
        if self.iterations == 0 {
            return Err(DomaError::InvalidConfig(
                "iterations must be at least 1".into(),
            ));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return Err(DomaError::InvalidConfig(format!(
                "learning rate {} must be positive",
                self.learning_rate
            )));
        }
        if self.decay == Some(Decay::Cosine)
            && self.warmup_iterations.unwrap_or(0) >= self.iterations
        {
            return Err(DomaError::InvalidConfig(format!(
                "{} warm-up iterations leave none of the {} to decay over",
                self.warmup_iterations.unwrap_or(0),
                self.iterations
            )));
        }
        Ok(())
    }
}

/// Stopping a fit once the EPE on held-back training tracks stops improving: usable on a
/// user's data, where no ground truth exists. The held-back tracks are not fitted.
///
/// In JSON, every field but `patience` may be left out (its default is used).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Convergence {
    /// Stop when the validation EPE has not improved for this many iterations.
    pub patience: usize,
    /// The fraction of the training tracks held back (drawn among those seen in the
    /// reference frame); default 0.1.
    #[serde(default = "Convergence::default_fraction")]
    pub validation_fraction: f64,
    /// Iterations between two validation EPEs; default 10.
    #[serde(default = "Convergence::default_every")]
    pub every: usize,
    /// The relative drop below the best EPE so far that counts as an improvement; default
    /// 0.01.
    #[serde(default = "Convergence::default_min_improvement")]
    pub min_improvement: f64,
    /// Iterations of cool-down after the plateau: the learning rate falls linearly from its
    /// value there towards 0, then the fit stops (`None`: as many as `patience`; 0: stop at
    /// the plateau). Most of a fit's error goes during a decay, so stopping on a plateau
    /// at a high rate would keep a rough field.
    #[serde(default)]
    pub cooldown: Option<usize>,
}

impl Convergence {
    fn default_fraction() -> f64 {
        0.1
    }
    fn default_every() -> usize {
        10
    }
    fn default_min_improvement() -> f64 {
        0.01
    }

    /// Stop after `patience` iterations without improvement; the other fields at their
    /// defaults.
    pub fn new(patience: usize) -> Self {
        Convergence {
            patience,
            validation_fraction: Self::default_fraction(),
            every: Self::default_every(),
            min_improvement: Self::default_min_improvement(),
            cooldown: None,
        }
    }

    /// Sets the cool-down after the plateau.
    pub fn with_cooldown(mut self, cooldown: Option<usize>) -> Self {
        self.cooldown = cooldown;
        self
    }

    /// The cool-down in iterations (`patience` unless set).
    pub fn cooldown_iterations(&self) -> usize {
        self.cooldown.unwrap_or(self.patience)
    }

    /// Sets the held-back fraction.
    pub fn with_validation_fraction(mut self, fraction: f64) -> Self {
        self.validation_fraction = fraction;
        self
    }

    /// Sets the iterations between two validation EPEs.
    pub fn with_every(mut self, every: usize) -> Self {
        self.every = every;
        self
    }

    /// Sets the relative improvement that counts.
    pub fn with_min_improvement(mut self, min_improvement: f64) -> Self {
        self.min_improvement = min_improvement;
        self
    }

    /// Refuses a zero patience or period, and a fraction outside (0, 1).
    pub fn validate(&self) -> Result<()> {
        if self.patience == 0 || self.every == 0 {
            return Err(DomaError::InvalidConfig(
                "the patience and the validation period must be at least 1 iteration".into(),
            ));
        }
        if !(self.validation_fraction > 0.0 && self.validation_fraction < 1.0) {
            return Err(DomaError::InvalidConfig(format!(
                "the validation fraction {} is not strictly between 0 and 1",
                self.validation_fraction
            )));
        }
        if !(self.min_improvement.is_finite() && (0.0..1.0).contains(&self.min_improvement)) {
            return Err(DomaError::InvalidConfig(format!(
                "the minimum improvement {} is not in [0, 1)",
                self.min_improvement
            )));
        }
        Ok(())
    }

    /// The iteration count at which the validation curve `epes` (iteration count after
    /// which each EPE was measured, EPE) first reached its plateau: its best EPE so far
    /// (each improvement at least `min_improvement` below the previous best) `patience`
    /// iterations or more behind the measurement. One pass over the curve.
    pub fn plateau(&self, epes: impl IntoIterator<Item = (usize, f64)>) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for (done, epe) in epes {
            let improved = match best {
                None => epe.is_finite(),
                Some((_, b)) => epe < b * (1.0 - self.min_improvement),
            };
            if improved {
                best = Some((done, epe));
            }
            if let Some((at, _)) = best
                && done - at >= self.patience
            {
                return Some(done);
            }
        }
        None
    }

    /// Whether the curve `epes` has reached a plateau ([`Convergence::plateau`]).
    pub fn converged(&self, epes: impl IntoIterator<Item = (usize, f64)>) -> bool {
        self.plateau(epes).is_some()
    }
}

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
}

impl LossConfig {
    /// Refuses negative or non-finite weights, and a robust penalty's bad scale.
    pub fn validate(&self) -> Result<()> {
        check_weights(&[
            ("smoothness weight", self.smoothness_weight),
            ("elasticity weight", self.elasticity_weight),
        ])?;
        self.penalty().validate().map_err(DomaError::InvalidConfig)
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
    /// Stop early once the EPE on held-back training tracks stops improving (`None`: run
    /// the whole budget, the paper's protocol).
    pub until_converged: Option<Convergence>,
    /// The name of the recipe the settings came from ([`super::Recipe`]); a label only:
    /// the settings themselves are the other fields.
    pub recipe: Option<super::Recipe>,
}

impl FitConfig {
    /// A fit of a DOMA field with the authors' `L_H` sampling for its variant
    /// ([`SmoothnessSampling::authors`]).
    pub fn doma(field: DomaFieldConfig) -> Self {
        let sampling = SmoothnessSampling::authors(field.variant);
        FitConfig::new(ModelConfig::Doma(field)).with_smoothness_sampling(sampling)
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
        if let Some(c) = &self.until_converged {
            c.validate()?;
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

/// The JSON object in the config file `path`.
fn read_object(path: &Path) -> Result<serde_json::Map<String, Value>> {
    let text = crate::io::read_input_text(path, crate::io::InputKind::Config)?;
    let given: Value = serde_json::from_str(&text).map_err(|e| DomaError::Malformed {
        path: path.to_path_buf(),
        reason: format!("not JSON: {e}"),
    })?;
    match given {
        Value::Object(fields) => Ok(fields),
        _ => Err(DomaError::Malformed {
            path: path.to_path_buf(),
            reason: "a fit config is a JSON object".into(),
        }),
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

/// The first field of `given` (as a dotted path below `at`) that `known`, a full config of
/// the same kind, does not have. Objects are compared key by key; a field whose known
/// value is not an object (a number, or `null` for an unset option) is not looked into.
pub(crate) fn unknown_field(given: &Value, known: &Value, at: &str) -> Option<String> {
    let (Value::Object(given), Value::Object(known)) = (given, known) else {
        return None;
    };
    given.iter().find_map(|(key, value)| {
        let path = if at.is_empty() {
            key.clone()
        } else {
            format!("{at}.{key}")
        };
        match known.get(key) {
            None => Some(path),
            Some(k) => unknown_field(value, k, &path),
        }
    })
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

/// Overlays `given` on `base`, object by object.
fn merge(base: &mut Value, given: Value) {
    match (base, given) {
        (Value::Object(b), Value::Object(g)) => {
            for (k, v) in g {
                match b.get_mut(&k) {
                    Some(slot) => merge(slot, v),
                    None => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (slot, v) => *slot = v,
    }
}
