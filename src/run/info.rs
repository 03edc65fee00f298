//! `doma info`: what a run folder holds.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::RunDir;
use crate::Result;
use crate::field::model::{ModelConfig, ModelName};
use crate::io::load_json;
use crate::train::IterationRecord;

/// What `doma info` prints.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RunInfo {
    /// The model's paper name (a DOMA variant's, or a baseline's).
    pub variant: ModelName,
    /// The SIREN's hidden width (SIREN-based models).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub hidden: Option<usize>,
    /// Its hidden sine layers after the first.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub n_hidden: Option<usize>,
    /// Trainable parameters.
    pub params: usize,
    /// `model.bpk` bytes (0 before the fit finishes).
    pub checkpoint_bytes: u64,
    /// The data file.
    pub data: PathBuf,
    /// Frames and points of the (clipped) data.
    pub frames: usize,
    /// See `frames`.
    pub points: usize,
    /// Iterations done of those configured.
    pub iterations_done: usize,
    /// Iterations configured.
    pub iterations: usize,
    /// For tracks with gaps: the entries the fit saw, of `frames × points`.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub observed_entries: Option<usize>,
    /// For tracks with gaps: the frame of the canonical positions, and the tracks not
    /// observed there (placed by their neighbours, learned with the field).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub reference_frame: Option<usize>,
    /// See `reference_frame`.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub tracks_unseen_in_reference: Option<usize>,
    /// The tracks the field was fitted to (of `points`); the others are held out for the
    /// report (`test_fraction`).
    #[serde(default)]
    pub fitted_tracks: usize,
    /// The test fraction of the split.
    #[serde(default)]
    pub test_fraction: f64,
    /// For tracks with gaps: the frames where no fitted track is observed (they add
    /// nothing to the fit; the field there follows from the frames around them).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub frames_without_observations: Option<usize>,
    /// The fits whose fills `complete` combines ([`super::RunConfig::fits`]), and those of
    /// them finished (`model.bpk` written).
    #[serde(default = "super::one_fit")]
    pub fits: usize,
    /// See `fits`.
    #[serde(default)]
    pub fits_finished: usize,
}

/// Describes the run in `run`.
pub fn info(run: &RunDir) -> Result<RunInfo> {
    let config = run.load_config()?;
    let seq = config.load()?;
    let history: Vec<IterationRecord> = if run.history().is_file() {
        load_json(&run.history())?
    } else {
        Vec::new()
    };
    let data = &seq.trajectories;
    let masked = data.observed().is_some();
    let unseen = (0..data.points())
        .filter(|&i| !data.is_observed(data.reference(), i))
        .count();
    let (fitted, _) = config.split_indices(data.points())?;
    let empty_frames = (0..data.frames())
        .filter(|&k| !fitted.iter().any(|&i| data.is_observed(k, i)))
        .count();
    let model = &config.fit.model;
    let shape = match model {
        ModelConfig::Doma(c) => Some(&c.shape),
        ModelConfig::Dpf(c) => Some(&c.shape),
        _ => None,
    };
    Ok(RunInfo {
        variant: model.name(),
        hidden: shape.map(|s| s.hidden),
        n_hidden: shape.map(|s| s.n_hidden),
        params: model.num_params(),
        checkpoint_bytes: std::fs::metadata(run.model()).map(|m| m.len()).unwrap_or(0),
        data: config.data.clone(),
        frames: seq.trajectories.frames(),
        points: seq.trajectories.points(),
        iterations_done: history.len(),
        iterations: config.fit.schedule.iterations,
        observed_entries: masked.then(|| data.observed_count()),
        reference_frame: masked.then(|| data.reference()),
        tracks_unseen_in_reference: masked.then_some(unseen),
        fitted_tracks: fitted.len(),
        test_fraction: config.test_fraction,
        frames_without_observations: masked.then_some(empty_frames),
        fits: config.fits,
        fits_finished: usize::from(run.model().is_file())
            + (2..=config.fits)
                .filter(|&k| run.member(k).model().is_file())
                .count(),
    })
}
