//! What a new fit is asked for: the data and the overrides of the fit recipe, from
//! `doma fit`'s flags or from one entry of a batch manifest ([`crate::batch`]). Both go
//! through [`RunSpec::run_config`], so a manifest entry means exactly what the same flags
//! mean on the command line.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::RunConfig;
use crate::backend::BackendKind;
use crate::data::layout::{CoordFrame, Layout, TrackFile};
use crate::data::sequence::Sequence;
use crate::field::dpf::DpfConfig;
use crate::field::model::ModelConfig;
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::loss::DataPenalty;
use crate::train::select::Weight;
use crate::train::select::{Penalty, WeightSearch, choose_weight};
use crate::train::{FitConfig, Recipe, RecipeChoice, SmoothnessSampling};
use crate::{DomaError, Result};

/// The model of a fit named in a few letters: a DOMA variant, or the frame-wise DPF
/// baseline (one SIREN per frame, sized to the clip's frames).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ModelChoice {
    /// DOMA-Trans (Eq. 10).
    Trans,
    /// DOMA-SE(3) (Eq. 11).
    Se3,
    /// DOMA-Scaled SE(3) (Eq. 12).
    ScaledSe3,
    /// DOMA-Affinity (Eq. 4).
    Affinity,
    /// The frame-wise DPF baseline.
    Dpf,
}

impl ModelChoice {
    /// The DOMA variant, or `None` for DPF.
    pub fn variant(self) -> Option<Variant> {
        match self {
            ModelChoice::Trans => Some(Variant::Trans),
            ModelChoice::Se3 => Some(Variant::Se3),
            ModelChoice::ScaledSe3 => Some(Variant::ScaledSe3),
            ModelChoice::Affinity => Some(Variant::Affinity),
            ModelChoice::Dpf => None,
        }
    }
}

impl From<Variant> for ModelChoice {
    fn from(v: Variant) -> Self {
        match v {
            Variant::Trans => ModelChoice::Trans,
            Variant::Se3 => ModelChoice::Se3,
            Variant::ScaledSe3 => ModelChoice::ScaledSe3,
            Variant::Affinity => ModelChoice::Affinity,
        }
    }
}

crate::names::value_names!(ModelChoice);

/// A new fit: the data and what differs from the default recipe (DOMA-Affinity, the
/// analytic Jacobian, 1000 iterations, no `L_H`, every track fitted; tracks with gaps:
/// [`GAP_FILLING_H_WEIGHT`] and [`GAP_FILLING_ITERATIONS`]).
///
/// This one type is the fit's options everywhere: `doma fit`'s flags (clap, the doc line of
/// each field is its `--help`), a batch manifest's entry (serde, the same names with `_`)
/// and the keywords of the Python `doma.fit` (turned into this type by serde). Every field
/// is optional; unknown fields are refused, so a misspelt override is an error and not a
/// silent default. Enums read and print one spelling ([`crate::names`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    /// The data: .traj, .anime, .npy, .npz, .c3d, or a folder of OBJ frames with equal vertex counts.
    #[arg(value_name = "DATA", required_unless_present = "resume")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<PathBuf>,
    /// A fit config (JSON, the `fit` part of a run's config.json; missing fields take
    /// their defaults); the other options override it.
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub config: Option<PathBuf>,
    /// The model: a DOMA variant (which also sets the authors' `L_H` sampling for it) or
    /// the frame-wise `dpf` baseline.
    #[arg(long = "variant", value_name = "MODEL")]
    #[serde(default, alias = "variant", skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelChoice>,
    /// The compute backend (default flex).
    #[arg(skip)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backend: Option<BackendKind>,
    /// How the spatial Jacobian is computed.
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jacobian: Option<JacobianKind>,
    /// Iterations (passes over all frames; default 1000, or 300 for tracks with gaps).
    #[arg(long = "iters", value_name = "N", value_parser = at_least_one)]
    #[serde(default, alias = "iters", skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
    /// Adam's base learning rate (default 1e-4, the authors'; `--recipe fast` scales it
    /// by 1.5, and this value wins over the recipe's).
    #[arg(long, value_name = "LR", value_parser = positive)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub learning_rate: Option<f64>,
    /// The initialisation's weight scale α: every SIREN weight but the output layer's is
    /// drawn α times wider (default 1, the authors' initialisation; docs/speed.md, "Time
    /// to accuracy").
    #[arg(long, value_name = "ALPHA", value_parser = positive)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_scale: Option<f64>,
    /// The weight of the smoothness loss L_H (Eq. 13; 0 = off; default 0, or 0.1 for tracks
    /// with gaps), or `auto`: chosen by validation on held-out training points before the
    /// fit (the grid goes into config.json and the plots).
    #[arg(long, value_name = "W", allow_negative_numbers = true)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub h_weight: Option<Weight>,
    /// The weight of the temporal smoothness loss L_T (the squared acceleration of the
    /// fitted tracks' warped positions, every frame, seen or not; not in the paper; default
    /// 0 = off).
    #[arg(long, value_name = "W", value_parser = non_negative)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_weight: Option<f64>,
    /// Seed of the weights, the split and the frame order.
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// An OBJ whose vertices are the points in order, for the faces (default: NAME.obj next
    /// to a .traj, or the .anime's own faces).
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<PathBuf>,
    /// A clip of the frames, `A..B` (B excluded) or `A..=B`; in JSON `[A, B]`.
    #[arg(long, value_name = "A..B", value_parser = clip)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<[usize; 2]>,
    /// Keep every N-th frame of the clip.
    #[arg(long, value_name = "N", value_parser = at_least_one)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stride: Option<usize>,
    /// The fraction of tracks held out of the fit for the report (default 0: every track
    /// is fitted; the paper's Tab. 1 protocol holds out 0.75).
    #[arg(long, value_name = "F", value_parser = held_fraction)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_fraction: Option<f64>,
    /// Iterations between checkpoints.
    #[arg(long, value_name = "N", value_parser = at_least_one)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoint_every: Option<usize>,
    /// Training points per step: a fresh random subset of K each step (default: all of
    /// them, the paper's protocol), so that a step's memory does not grow with the tracks.
    #[arg(long, value_name = "K", value_parser = at_least_one)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points_per_step: Option<usize>,
    /// Frames per Adam step: each step minimises the sum of B frames' losses (default 1,
    /// the paper's protocol).
    #[arg(long, value_name = "B", value_parser = at_least_one)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_per_step: Option<usize>,
    /// The layout of a tracker's .npz (default: detected from its keys).
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layout: Option<Layout>,
    /// The coordinate frame of a tracker's tracks: PointOdyssey's are in the world frame
    /// unless `camera` (its extrinsics applied); TAPVid-3D's are in the camera frame.
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<CoordFrame>,
    /// Count PointOdyssey's valid but hidden entries (its ground truth) as observed.
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count_hidden: Option<bool>,
    /// The frame whose positions are the field's input x (default: the frame with the most
    /// observed points), counted within the clip; a frame where no track is observed is
    /// refused.
    #[arg(long, value_name = "K")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_frame: Option<usize>,
    /// Go on without the tracks that are never observed (`complete` records the kept
    /// indices) rather than refuse them.
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drop_unobserved: Option<bool>,
    /// Hide this fraction of the observations from the fit, in spans inside each track's
    /// observations, and report the error of the fill on them beside linear and spline
    /// interpolation, the neighbours' motion and a low-rank (PCA) reconstruction.
    #[arg(long, value_name = "F", value_parser = fraction)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_observations: Option<f64>,
    /// The lengths of the held-out spans, `A..=B` frames (default 2..=10; `A..B` excludes B).
    #[arg(long, value_name = "A..=B", value_parser = span_lengths)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_span: Option<[usize; 2]>,
    /// The probability from which a tracker's float visibility counts as observed
    /// (default 0.5); a bool or 0/1 visibility is read as it is.
    #[arg(long, value_name = "P")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visibility_threshold: Option<f64>,
    /// The key of a `[T, N]` array of per-observation confidence weights in a tracker's
    /// .npz: each observation's share of the trajectory loss.
    #[arg(long, value_name = "KEY")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<String>,
    /// A robust trajectory loss for tracks with outliers: `huber[:DELTA]` or
    /// `charbonnier[:EPSILON]` (normalised units, default 0.01), or `l1` (the paper's).
    #[arg(long, value_name = "PENALTY")]
    #[serde(
        default,
        alias = "data_penalty",
        with = "penalty_text",
        skip_serializing_if = "Option::is_none"
    )]
    pub robust: Option<DataPenalty>,
    /// A named recipe: `paper` (the paper's protocol, the default) or `fast` (1.5 times the
    /// learning rate, warm-up and cosine decay, 256 training points and 64 `L_H` samples
    /// per step; docs/speed.md). The other options override its settings.
    #[arg(long)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recipe: Option<Recipe>,
    /// Stop once the EPE on a held-back tenth of the training tracks (checked every 10
    /// iterations) has not improved by 1 % for PATIENCE iterations, after a cool-down of
    /// PATIENCE more iterations whose learning rate falls linearly to 0; the held-back
    /// tracks are not fitted.
    #[arg(long, value_name = "PATIENCE", value_parser = at_least_one)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub until_converged: Option<usize>,
}

/// A count of at least one.
fn at_least_one(s: &str) -> std::result::Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("`{s}` is not a whole number of at least 1")),
    }
}

/// A finite number above 0.
fn positive(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a finite number above 0")),
    }
}

/// A finite number of at least 0.
fn non_negative(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a finite number of at least 0")),
    }
}

/// A fraction strictly between 0 and 1.
pub fn fraction(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("`{s}` is not a number"))?;
    check_fraction(v)
}

/// The `L_H` weight (Eq. 13) of a fit of tracks with gaps whose options set none: the
/// best of 0, 0.1 and 0.3 for the fill on the shared marker recordings (docs/results.md).
pub const GAP_FILLING_H_WEIGHT: f64 = 0.1;

/// The iterations of a fit of tracks with gaps whose options set neither a budget nor a
/// schedule (`--iters`, `--config`, `--recipe`, `--until-converged`): on the shared marker
/// recordings the fill at 300 iterations was as good as at the paper's 1000 or better, in
/// under a third of the time (docs/results.md, real markers).
pub const GAP_FILLING_ITERATIONS: usize = 300;

/// A fraction of at least 0 and below 1 (0: nothing held out).
pub fn held_fraction(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("`{s}` is not a number"))?;
    check_held_fraction(v)
}

/// `v` when it lies in `[0, 1)`.
fn check_held_fraction(v: f64) -> std::result::Result<f64, String> {
    if (0.0..1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("`{v}` must be at least 0 and below 1"))
    }
}

/// `v` when it lies strictly between 0 and 1.
fn check_fraction(v: f64) -> std::result::Result<f64, String> {
    if v > 0.0 && v < 1.0 {
        Ok(v)
    } else {
        Err(format!("`{v}` must be strictly between 0 and 1"))
    }
}

/// Span lengths `A..=B` (or `A..B`, B excluded) as the inclusive `[A, B]`, at least 1.
fn span_lengths(s: &str) -> std::result::Result<[usize; 2], String> {
    let r = crate::data::parse_frame_range(s)?;
    if r.start == 0 || r.is_empty() {
        return Err(format!("`{s}` must hold lengths of at least 1 frame"));
    }
    Ok([r.start, r.end - 1])
}

/// A clip `A..B` or `A..=B` as `[A, B)`.
fn clip(s: &str) -> std::result::Result<[usize; 2], String> {
    crate::data::parse_frame_range(s).map(|r| [r.start, r.end])
}

/// A [`DataPenalty`] in its one spelling (`huber:0.01`); a manifest written before that
/// spelling (`{"huber": {"delta": 0.01}}`) still reads.
mod penalty_text {
    use serde::{Deserialize, Deserializer, Serializer};

    use crate::loss::DataPenalty;

    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Given {
        Text(String),
        Tagged(DataPenalty),
    }

    pub fn serialize<S: Serializer>(p: &Option<DataPenalty>, s: S) -> Result<S::Ok, S::Error> {
        match p {
            Some(p) => s.collect_str(p),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<DataPenalty>, D::Error> {
        match Option::<Given>::deserialize(d)? {
            None => Ok(None),
            Some(Given::Text(t)) => t.parse().map(Some).map_err(serde::de::Error::custom),
            Some(Given::Tagged(p)) => {
                p.validate().map_err(serde::de::Error::custom)?;
                Ok(Some(p))
            }
        }
    }
}

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
        // After the model (whose variant sets the `L_H` sampling), before the flags.
        let mut fit = RecipeChoice {
            recipe: self.recipe,
            until_converged: self.until_converged,
        }
        .apply(fit);
        if let Some(j) = self.jacobian {
            fit.jacobian = j;
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
        if let Some(p) = self.robust {
            fit.loss.data_penalty = (p != DataPenalty::L1).then_some(p);
        }
        Ok(fit)
    }

    /// The run config of this fit without its data read: what the options say, checked
    /// where the data is not needed. A DPF model's frame count is set by
    /// [`RunSpec::prepare`], from the data.
    fn run_config(&self) -> Result<RunConfig> {
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
        config.holdout_observations = self.holdout_observations;
        config.holdout_span = self.holdout_span;
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
    /// checked, and the sequence that [`super::fit_run`] fits. With `h_weight = auto`, the
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
        // Sparse tracks with gaps: the gap-filling defaults where the options set nothing
        // (docs/results.md, real markers: without L_H the field strays inside gaps, and
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_entry_reads_from_json_and_refuses_unknown_fields() {
        let spec: RunSpec = serde_json::from_str(
            r#"{"data": "a.traj", "model": "scaled-se3", "h_weight": "auto", "frames": [0, 20]}"#,
        )
        .unwrap();
        assert_eq!(spec.model, Some(ModelChoice::ScaledSe3));
        assert_eq!(spec.h_weight, Some(Weight::Auto));
        assert_eq!(spec.frames, Some([0, 20]));
        let err = serde_json::from_str::<RunSpec>(r#"{"data": "a", "iteration": 5}"#)
            .unwrap_err()
            .to_string();
        assert!(err.contains("iteration"), "{err}");
        let err = serde_json::from_str::<RunSpec>(r#"{"h_weight": -1}"#)
            .unwrap_err()
            .to_string();
        assert!(err.contains("non-negative"), "{err}");
    }

    #[test]
    fn overrides_fall_back_to_the_defaults_and_paths_to_the_base() {
        let defaults = RunSpec {
            iterations: Some(50),
            seed: Some(3),
            ..RunSpec::default()
        };
        let item = RunSpec {
            data: Some("seq.traj".into()),
            seed: Some(7),
            ..RunSpec::default()
        }
        .or(&defaults)
        .unwrap()
        .relative_to(Path::new("/data"));
        assert_eq!(item.iterations, Some(50));
        assert_eq!(item.seed, Some(7));
        assert_eq!(item.data.as_deref(), Some(Path::new("/data/seq.traj")));
        let fit = item.fit_config(|| unreachable!("not DPF")).unwrap();
        assert_eq!((fit.schedule.iterations, fit.seed), (50, 7));
        let dpf = RunSpec {
            model: Some(ModelChoice::Dpf),
            ..RunSpec::default()
        }
        .fit_config(|| Ok(12))
        .unwrap();
        assert_eq!(dpf.model.frames(), Some(12));
    }
}
