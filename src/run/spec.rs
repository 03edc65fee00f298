//! What a new fit is asked for: the data and the overrides of the fit recipe, from
//! `doma fit`'s flags or from one entry of a batch manifest ([`crate::batch`]). Both go
//! through [`RunSpec::run_config`], so a manifest entry means exactly what the same flags
//! mean on the command line.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::RunConfig;
use crate::backend::BackendKind;
use crate::data::layout::{CoordFrame, Layout, TrackFile};
use crate::field::dpf::DpfConfig;
use crate::field::model::ModelConfig;
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::loss::DataPenalty;
use crate::train::select::Weight;
use crate::train::select::{Penalty, WeightChoice, WeightSearch, choose_weight};
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

/// A new fit: the data and what differs from the default recipe (DOMA-Affinity, the
/// analytic Jacobian, 1000 iterations, no `L_H`, the paper's 25 % / 75 % split). Every
/// field is optional but `data`; unknown fields are refused, so a misspelt override is an
/// error and not a silent default.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    /// The data: .traj, .anime, .npy, .npz, or a folder of OBJ frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<PathBuf>,
    /// A fit config (JSON, the `fit` part of a run's config.json; missing fields take
    /// their defaults), under the other overrides.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub config: Option<PathBuf>,
    /// The model (a DOMA variant also sets the authors' `L_H` sampling for it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelChoice>,
    /// The compute backend (default flex).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backend: Option<BackendKind>,
    /// How the spatial Jacobian is computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jacobian: Option<JacobianKind>,
    /// Iterations (passes over all frames).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
    /// The weight of `L_H` (Eq. 13), or `auto`: chosen by validation before the fit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub h_weight: Option<Weight>,
    /// Seed of the weights, the split and the frame order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// An OBJ for the faces.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<PathBuf>,
    /// The clip `[start, end)` of the frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<[usize; 2]>,
    /// Every `stride`-th frame of the clip.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stride: Option<usize>,
    /// The fraction of points held out for the report.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_fraction: Option<f64>,
    /// Iterations between checkpoints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoint_every: Option<usize>,
    /// Training points per step (`FitConfig::points_per_step`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points_per_step: Option<usize>,
    /// Frames per Adam step (`FitConfig::frames_per_step`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_per_step: Option<usize>,
    /// The layout of a tracker's `.npz` (default: detected from its keys).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layout: Option<Layout>,
    /// The coordinate frame of a tracker's tracks (default: the layout's own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<CoordFrame>,
    /// Count PointOdyssey's valid but hidden entries as observed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count_hidden: Option<bool>,
    /// The reference frame of the canonical positions (default: the most observed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_frame: Option<usize>,
    /// Go on without the tracks never observed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drop_unobserved: Option<bool>,
    /// Hide this fraction of the observations from the fit, in spans, to measure gap
    /// filling.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_observations: Option<f64>,
    /// The key of a tracker file's per-observation confidence weights.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<String>,
    /// The trajectory loss's per-coordinate penalty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_penalty: Option<DataPenalty>,
    /// A named recipe, applied over the config before the other fields.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recipe: Option<Recipe>,
    /// Stop once the EPE on held-back training tracks has not improved for this many
    /// iterations.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub until_converged: Option<usize>,
}

impl RunSpec {
    /// `self` with every field it leaves unset taken from `defaults`.
    pub fn or(self, defaults: &RunSpec) -> RunSpec {
        let d = defaults.clone();
        RunSpec {
            data: self.data.or(d.data),
            config: self.config.or(d.config),
            model: self.model.or(d.model),
            backend: self.backend.or(d.backend),
            jacobian: self.jacobian.or(d.jacobian),
            iterations: self.iterations.or(d.iterations),
            h_weight: self.h_weight.or(d.h_weight),
            seed: self.seed.or(d.seed),
            mesh: self.mesh.or(d.mesh),
            frames: self.frames.or(d.frames),
            stride: self.stride.or(d.stride),
            test_fraction: self.test_fraction.or(d.test_fraction),
            checkpoint_every: self.checkpoint_every.or(d.checkpoint_every),
            points_per_step: self.points_per_step.or(d.points_per_step),
            frames_per_step: self.frames_per_step.or(d.frames_per_step),
            layout: self.layout.or(d.layout),
            frame: self.frame.or(d.frame),
            count_hidden: self.count_hidden.or(d.count_hidden),
            reference_frame: self.reference_frame.or(d.reference_frame),
            drop_unobserved: self.drop_unobserved.or(d.drop_unobserved),
            holdout_observations: self.holdout_observations.or(d.holdout_observations),
            confidence: self.confidence.or(d.confidence),
            data_penalty: self.data_penalty.or(d.data_penalty),
            recipe: self.recipe.or(d.recipe),
            until_converged: self.until_converged.or(d.until_converged),
        }
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
        if let Some(Weight::Fixed(w)) = self.h_weight {
            fit.loss.smoothness_weight = w;
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
        if let Some(p) = self.data_penalty {
            fit.loss.data_penalty = (p != DataPenalty::L1).then_some(p);
        }
        Ok(fit)
    }

    /// The run config of this fit, checked; with `h_weight = auto`, after the weight
    /// search (`search`; `on_weight` hears each weight's validation EPE). The data must
    /// exist and load.
    pub fn run_config(
        &self,
        search: &WeightSearch,
        on_weight: impl FnMut(&crate::train::select::GridPoint),
    ) -> Result<RunConfig> {
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
        };
        config.reference_frame = self.reference_frame;
        config.drop_unobserved = self.drop_unobserved.unwrap_or(false);
        config.holdout_observations = self.holdout_observations;
        if let Some([a, b]) = self.frames
            && a >= b
        {
            return Err(DomaError::InvalidConfig(format!(
                "the clip {a}..{b} holds no frame"
            )));
        }
        config.fit = self.fit_config(|| Ok(config.load()?.trajectories.frames()))?;
        config.validate()?;
        if self.h_weight == Some(Weight::Auto) {
            config.weight_search = Some(self.choose_h_weight(&config, search, on_weight)?);
            config.fit.loss.smoothness_weight =
                config.weight_search.as_ref().map_or(0.0, |c| c.weight);
        }
        Ok(config)
    }

    fn choose_h_weight(
        &self,
        config: &RunConfig,
        search: &WeightSearch,
        on_weight: impl FnMut(&crate::train::select::GridPoint),
    ) -> Result<WeightChoice> {
        search.validate()?;
        let (train, _) = config.split(&config.load()?.trajectories)?;
        let device = config.backend.device()?;
        choose_weight(
            &config.fit,
            Penalty::Smoothness,
            &train,
            search,
            &device,
            on_weight,
        )
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
