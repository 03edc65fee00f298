//! The files of a run folder ([`RunDir`]) and a fitted run opened from one ([`OpenRun`]).

use std::path::PathBuf;

use burn::tensor::Device;

use super::RunConfig;
use crate::checkpoint::decode_checkpoint;
use crate::data::sequence::Sequence;
use crate::field::model::{Model, ModelConfig};
use crate::{DomaError, Result};

/// A fitted run opened for warping or showing it (`warp`, `export`, `view`).
pub struct OpenRun {
    /// Its config.
    pub config: RunConfig,
    /// Its fitted field.
    pub field: Model,
    /// Its data, normalised as when it was fitted.
    pub data: Sequence,
    /// The frames asked for, checked to lie within the data's.
    pub frames: std::ops::Range<usize>,
}

/// The files of a run folder.
#[derive(Clone, Debug)]
pub struct RunDir {
    /// The folder.
    pub dir: PathBuf,
}

impl RunDir {
    /// The run folder `dir`.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        RunDir { dir: dir.into() }
    }
    /// `config.json`.
    pub fn config(&self) -> PathBuf {
        self.dir.join("config.json")
    }
    /// `model.bpk`.
    pub fn model(&self) -> PathBuf {
        self.dir.join("model.bpk")
    }
    /// `resume.ckpt`.
    pub fn resume(&self) -> PathBuf {
        self.dir.join("resume.ckpt")
    }
    /// `history.json`.
    pub fn history(&self) -> PathBuf {
        self.dir.join("history.json")
    }
    /// `report.json`.
    pub fn report(&self) -> PathBuf {
        self.dir.join("report.json")
    }
    /// `canonical.npy`.
    pub fn canonical(&self) -> PathBuf {
        self.dir.join("canonical.npy")
    }
    /// `fits/K`: the folder of fit `k` (from 2) of a run that combines several
    /// ([`RunConfig::fits`]), a run folder of its own.
    pub fn member(&self, k: usize) -> RunDir {
        RunDir::new(self.dir.join("fits").join(k.to_string()))
    }

    /// The run's data as [`RunConfig::load`] gives it, with the canonical positions the fit
    /// learned (`canonical.npy`), if it learned any.
    pub fn load_data(&self, config: &RunConfig) -> Result<Sequence> {
        let mut data = config.load()?;
        let path = self.canonical();
        if path.is_file() {
            let array = crate::data::npy::read_npy(&path)?;
            let points = data.trajectories.points();
            if array.shape != [points, 3] {
                return Err(DomaError::Malformed {
                    path,
                    reason: format!(
                        "shape {:?}, but the run's data has {points} tracks",
                        array.shape
                    ),
                });
            }
            data.trajectories =
                data.trajectories
                    .with_canonical(array.data)
                    .map_err(|e| DomaError::Malformed {
                        path,
                        reason: e.to_string(),
                    })?;
        }
        Ok(data)
    }

    /// The run's config; a folder without one is not a run.
    pub fn load_config(&self) -> Result<RunConfig> {
        let path = self.config();
        if !self.dir.exists() {
            return Err(DomaError::io(
                &self.dir,
                std::io::Error::new(std::io::ErrorKind::NotFound, "no such run folder"),
            ));
        }
        if !path.is_file() {
            return Err(DomaError::Malformed {
                path: self.dir.clone(),
                reason: "not a doma run folder (no config.json)".into(),
            });
        }
        let given: serde_json::Value = crate::io::load_json(&path)?;
        let malformed = |e: serde_json::Error| DomaError::Malformed {
            path: path.clone(),
            reason: e.to_string(),
        };
        let config: RunConfig = serde_json::from_value(given.clone()).map_err(malformed)?;
        // A field that no run config has (an edit with a typo, another layout) is refused
        // rather than ignored.
        let known = serde_json::to_value(&config).map_err(malformed)?;
        if let Some(field) = crate::io::unknown_field(&given, &known, "") {
            return Err(DomaError::Malformed {
                path,
                reason: format!("no run config has the field `{field}`"),
            });
        }
        config.validate().map_err(|e| DomaError::Malformed {
            path,
            reason: e.to_string(),
        })?;
        Ok(config)
    }

    /// The fitted field (from `model.bpk`, else from the last checkpoint, read in memory:
    /// nothing is written into the run folder).
    pub fn load_field(&self, config: &RunConfig, device: &Device) -> Result<Model> {
        let canonical = self.canonical_training_points(config)?;
        let fresh = config.fit.model.init(config.fit.seed, &canonical, device);
        let path = self.model();
        if path.is_file() {
            let bytes = std::fs::read(&path).map_err(|e| DomaError::io(&path, e))?;
            return fresh.decode(&bytes).map_err(|e| DomaError::Malformed {
                path,
                reason: format!(
                    "does not hold the model that {} describes: {e}",
                    self.config().display()
                ),
            });
        }
        let snapshot = self.read_resume()?;
        decode_checkpoint(fresh, &snapshot.model).map_err(|e| DomaError::Malformed {
            path: self.resume(),
            reason: format!("the model part: {e}"),
        })
    }

    /// Loads the run's config, field and data, and checks `frames` (default: all of the
    /// run's frames) against them.
    pub fn open(&self, frames: Option<std::ops::Range<usize>>, device: &Device) -> Result<OpenRun> {
        let config = self.load_config()?;
        let field = self.load_field(&config, device)?;
        let data = self.load_data(&config)?;
        let total = data.trajectories.frames();
        let frames = frames.unwrap_or(0..total);
        if frames.start >= frames.end || frames.end > total {
            return Err(DomaError::InvalidConfig(format!(
                "frames {}..{} are not within the run's {total} frames",
                frames.start, frames.end
            )));
        }
        Ok(OpenRun {
            config,
            field,
            data,
            frames,
        })
    }

    /// The canonical training points, which place BoneCloud's bones (the other models do
    /// not read them; the parameters come from the checkpoint anyway).
    fn canonical_training_points(&self, config: &RunConfig) -> Result<Vec<f32>> {
        if !matches!(config.fit.model, ModelConfig::BoneCloud(_)) {
            return Ok(Vec::new());
        }
        let sequence = config.load()?;
        Ok(config.split(&sequence.trajectories)?.0.canonical().to_vec())
    }
}
