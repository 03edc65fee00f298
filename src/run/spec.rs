//! What a new fit is asked for: the data and the overrides of the fit recipe, from
//! `doma fit`'s flags or from one entry of a batch manifest ([`crate::batch`]). Both go
//! through [`RunSpec::run_config`], so a manifest entry means exactly what the same flags
//! mean on the command line.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::Result;
use crate::backend::BackendKind;
use crate::data::layout::{CoordFrame, Layout};
use crate::field::Variant;
use crate::jacobian::JacobianKind;
use crate::loss::DataPenalty;
use crate::train::Recipe;
use crate::train::select::Weight;

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
/// [`GAP_FILLING_H_WEIGHT`], [`GAP_FILLING_ITERATIONS`] and
/// [`GAP_FILLING_FRAMES_PER_ITERATION`]).
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
    #[arg(long, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub config: Option<PathBuf>,
    /// The model: a DOMA variant (which also sets the authors' `L_H` sampling for it) or
    /// the frame-wise `dpf` baseline.
    #[arg(long = "variant", value_name = "MODEL", help_heading = "Model")]
    #[serde(default, alias = "variant", skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelChoice>,
    /// The compute backend (default flex).
    #[arg(skip)]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backend: Option<BackendKind>,
    /// How the spatial Jacobian is computed.
    #[arg(long, help_heading = "Model")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jacobian: Option<JacobianKind>,
    /// How each training step is computed: `auto` (the default: the whole step as one CPU
    /// op where it applies, Burn's operations elsewhere), `fused` (refused where it does
    /// not apply) or `composed` (Burn's operations around the Jacobian method).
    #[arg(long, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<crate::train::StepKind>,
    /// The optimiser: `adam` (the default, the paper's) or `soap` (Adam in the eigenbasis
    /// of Shampoo's factors; the fused step only; docs/speed.md, "What was tried").
    #[arg(long, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub optimizer: Option<crate::train::OptimizerKind>,
    /// Iterations (passes over all frames; default 1000, or 300 for tracks with gaps).
    #[arg(long = "iters", value_name = "N", value_parser = at_least_one, help_heading = "Training")]
    #[serde(default, alias = "iters", skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
    /// Adam's base learning rate (default 1e-4, the authors'; `--recipe fast` scales it
    /// by 1.5, and this value wins over the recipe's).
    #[arg(long, value_name = "LR", value_parser = positive, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub learning_rate: Option<f64>,
    /// The initialisation's weight scale α: every SIREN weight but the output layer's is
    /// drawn α times wider (default 1, the authors' initialisation; docs/speed.md, "Time
    /// to accuracy").
    #[arg(long, value_name = "ALPHA", value_parser = positive, help_heading = "Model")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_scale: Option<f64>,
    /// The factor s on the time a DOMA field reads, f(x, s·t) (default: 1 up to 1,000
    /// frames, else the frames over 1,000, so that a long recording's field keeps the
    /// frequencies per frame of a short clip; docs/design.md §7).
    #[arg(long, value_name = "S", value_parser = positive, help_heading = "Model")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_scale: Option<f64>,
    /// The weight of the smoothness loss L_H (Eq. 13; 0 = off; default 0, or 0.1 for tracks
    /// with gaps), or `auto`: chosen by validation on held-out training points before the
    /// fit (the grid goes into config.json and the plots).
    #[arg(
        long,
        value_name = "W",
        allow_negative_numbers = true,
        help_heading = "Training"
    )]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub h_weight: Option<Weight>,
    /// The weight of the temporal smoothness loss L_T (the squared acceleration of the
    /// fitted tracks' warped positions, every frame, seen or not; not in the paper; default
    /// 0 = off).
    #[arg(long, value_name = "W", value_parser = non_negative, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_weight: Option<f64>,
    /// Seed of the weights, the split and the frame order.
    #[arg(long, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// An OBJ whose vertices are the points in order, for the faces (default: NAME.obj next
    /// to a .traj, or the .anime's own faces).
    #[arg(long, help_heading = "Data")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<PathBuf>,
    /// A clip of the frames, `A..B` (B excluded) or `A..=B`; in JSON `[A, B]`.
    #[arg(long, value_name = "A..B", value_parser = clip, help_heading = "Data")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<[usize; 2]>,
    /// Keep every N-th frame of the clip.
    #[arg(long, value_name = "N", value_parser = at_least_one, help_heading = "Data")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stride: Option<usize>,
    /// The fraction of tracks held out of the fit for the report (default 0: every track
    /// is fitted; the paper's Tab. 1 protocol holds out 0.75).
    #[arg(long, value_name = "F", value_parser = held_fraction, help_heading = "Data")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_fraction: Option<f64>,
    /// Iterations between checkpoints.
    #[arg(long, value_name = "N", value_parser = at_least_one, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoint_every: Option<usize>,
    /// Training points per step: a fresh random subset of K each step (default: all of
    /// them, the paper's protocol), so that a step's memory does not grow with the tracks.
    #[arg(long, value_name = "K", value_parser = at_least_one, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points_per_step: Option<usize>,
    /// Frames per Adam step: each step minimises the sum of B frames' losses (default 1,
    /// the paper's protocol).
    #[arg(long, value_name = "B", value_parser = at_least_one, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_per_step: Option<usize>,
    /// Frames per iteration: each iteration visits a fresh random subset of F frames, so
    /// that the fit costs `iterations × F` frame visits whatever the recording's length
    /// (default: every frame, the paper's protocol; tracks with gaps:
    /// 100, [`GAP_FILLING_FRAMES_PER_ITERATION`]).
    #[arg(long, value_name = "F", value_parser = at_least_one, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_per_iteration: Option<usize>,
    /// The layout of a tracker's .npz (default: detected from its keys).
    #[arg(long, help_heading = "Tracker files")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layout: Option<Layout>,
    /// The coordinate frame of a tracker's tracks: PointOdyssey's are in the world frame
    /// unless `camera` (its extrinsics applied); TAPVid-3D's are in the camera frame.
    #[arg(long, help_heading = "Tracker files")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<CoordFrame>,
    /// Count PointOdyssey's valid but hidden entries (its ground truth) as observed.
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", help_heading = "Tracker files")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count_hidden: Option<bool>,
    /// The frame whose positions are the field's input x (default: the frame with the most
    /// observed points), counted within the clip; a frame where no track is observed is
    /// refused.
    #[arg(long, value_name = "K", help_heading = "Tracker files")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_frame: Option<usize>,
    /// Go on without the tracks that are never observed (`complete` records the kept
    /// indices) rather than refuse them.
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", help_heading = "Tracker files")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drop_unobserved: Option<bool>,
    /// Fit the points that a C3D file lists as a model's outputs (`POINT:ANGLES`, `FORCES`,
    /// `MOMENTS`, `POWERS`, ..., as Nexus writes joint angles and forces) as if they were
    /// markers (default false: they are left out of the fit, and a `.c3d` from `complete`
    /// holds them as the input does).
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", help_heading = "Tracker files")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_outputs: Option<bool>,
    /// Hide this fraction of the observations from the fit, in spans inside each track's
    /// observations, and report the error of doma's fill on them beside the field alone and
    /// every filler (the field's fill, spline, linear, the neighbours' motion, iterative PCA,
    /// pattern and rigid-body fill, the Kalman smoother, Gløersen's PCA fill).
    #[arg(long, value_name = "F", value_parser = fraction, help_heading = "Gap filling")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_observations: Option<f64>,
    /// The lengths of the held-out spans, `A..=B` frames (default 2..=10; `A..B` excludes B).
    #[arg(long, value_name = "A..=B", value_parser = span_lengths, help_heading = "Gap filling")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_span: Option<[usize; 2]>,
    /// On tracks with gaps, hide a tenth of the gapped tracks' observations, in spans as
    /// long as the data's gaps, from the fit itself, and weigh the field's fills in doma's
    /// fill on them alone, where the field fills them as it fills a real gap (default true;
    /// `=false` fits every observation, and doma's fill then blends the classic fillers
    /// alone).
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", help_heading = "Gap filling")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blind_validation: Option<bool>,
    /// Fit K fields, with the seed and the K − 1 after it, and fill each gap with the median
    /// of their fills (the mean of two): each weighs its fillers on its own validation
    /// spans, and one that chose wrongly counts for half, or not at all; K times the fit's
    /// and `complete`'s time (default 1; the others are fitted into RUN/fits/2, …).
    #[arg(long, value_name = "K", value_parser = fit_count, help_heading = "Gap filling")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fits: Option<usize>,
    /// The probability from which a tracker's float visibility counts as observed
    /// (default 0.5); a bool or 0/1 visibility is read as it is.
    #[arg(long, value_name = "P", help_heading = "Tracker files")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visibility_threshold: Option<f64>,
    /// The key of a `[T, N]` array of per-observation confidence weights in a tracker's
    /// .npz: each observation's share of the trajectory loss.
    #[arg(long, value_name = "KEY", help_heading = "Tracker files")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<String>,
    /// A robust trajectory loss for tracks with outliers: `huber[:DELTA]` or
    /// `charbonnier[:EPSILON]` (normalised units, default 0.01), or `l1` (the paper's).
    #[arg(long, value_name = "PENALTY", help_heading = "Training")]
    #[serde(
        default,
        alias = "data_penalty",
        with = "penalty_text",
        skip_serializing_if = "Option::is_none"
    )]
    pub robust: Option<DataPenalty>,
    /// A named recipe: `paper` (the paper's protocol, the default), `fast` (1.5 times the
    /// learning rate, warm-up and cosine decay, 256 training points and 64 `L_H` samples
    /// per step) or `soap` (`fast` over 400 iterations at 3 times the rate, stepped by SOAP; the fused step
    /// only); docs/speed.md. The other options override its settings.
    #[arg(long, help_heading = "Training")]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recipe: Option<Recipe>,
    /// Stop once the EPE on a held-back tenth of the training tracks (checked every 10
    /// iterations) has not improved by 1 % for PATIENCE iterations, after a cool-down of
    /// PATIENCE more iterations whose learning rate falls linearly to 0; the held-back
    /// tracks are not fitted.
    #[arg(long, value_name = "PATIENCE", value_parser = at_least_one, help_heading = "Training")]
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

/// A count of fits a run combines (1 to [`super::MAX_FITS`]).
fn fit_count(s: &str) -> std::result::Result<usize, String> {
    match s.parse::<usize>() {
        Ok(k) if (1..=super::MAX_FITS).contains(&k) => Ok(k),
        _ => Err(format!(
            "`{s}` is not a whole number from 1 to {}",
            super::MAX_FITS
        )),
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
/// best of 0, 0.1 and 0.3 for the fill on the shared marker recordings (docs/gap-filling.md).
pub const GAP_FILLING_H_WEIGHT: f64 = 0.1;

/// The iterations of a fit of tracks with gaps whose options set neither a budget nor a
/// schedule (`--iters`, `--config`, `--recipe`, `--until-converged`): on the shared marker
/// recordings the fill at 300 iterations was as good as at the paper's 1000 or better, in
/// under a third of the time (docs/gap-filling.md, real markers).
pub const GAP_FILLING_ITERATIONS: usize = 300;

/// The frames per iteration of a fit of tracks with gaps whose options set none: the
/// 100-frame clips of docs/gap-filling.md are fitted as before, and a recording at its native
/// rate (thousands of frames) costs the same budget of steps, not an epoch per frame
/// (docs/speed.md, native rate).
pub const GAP_FILLING_FRAMES_PER_ITERATION: usize = 100;

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

mod config;

pub use config::NewFit;

#[cfg(test)]
mod tests;
