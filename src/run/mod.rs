//! A fit of a user's own data, kept in a run folder (`doma fit`, `eval`, `warp`, `info`):
//!
//! | file | what |
//! |---|---|
//! | `config.json` | [`RunConfig`]: the data, the split, the normalisation and the [`FitConfig`] |
//! | `resume.ckpt` | the last checkpoint: parameters, Adam's state, the random stream, the history |
//! | `history.json` | one [`crate::train::IterationRecord`] per finished iteration |
//! | `model.bpk` | the fitted field's parameters (burnpack), once the fit is done |
//! | `report.json` | [`Report`]: the metrics on the held-out points |
//! | `canonical.npy` | the canonical positions `[N, 3]` (normalised) of every track, where the fit learned those of tracks unseen in the reference frame |
//! | `fits/2/`, … | the other fits of a run whose fill combines several ([`RunConfig::fits`]), each a run folder of its own |
//!
//! `.lock` holds the process id of the fit that holds the folder ([`RunLock`]).
//!
//! Every file is written atomically. A checkpoint is written every `checkpoint_every`
//! iterations and on an interrupt; a resumed fit restores the parameters (with the ids
//! that key Adam's state), Adam's state and the random stream, so it reaches the same
//! weights as an uninterrupted fit on the same device. A non-finite loss stops the fit with
//! an error naming the iteration and leaves the last good checkpoint in place.

mod claim;
mod complete;
mod eval;
mod fit;
mod folder;
mod gap_report;
mod gap_table;
mod info;
mod lock;
mod plot;
mod prediction;
mod recording;
pub mod report;
mod resume;
mod spec;
mod warp;

pub use claim::Claim;
pub use complete::{
    CompletedTracks, Completion, FillPolicy, FilledGap, MaxGap, OutputKind, complete_run,
    complete_run_with, complete_tracks, complete_without_fit, extrapolates_by_default,
    output_kind_for,
};
pub use eval::{eval_run, eval_run_as, evaluate};
pub use fit::{FitOutcome, fit_run, fit_run_locked};
pub use folder::{OpenRun, RunDir};
pub use gap_report::{GapErrors, GapReport, gap_report};
pub use gap_table::{
    GapRow, GapTable, filled_by, gap_rows, gaps_csv, gaps_csv_path, gaps_html_path, mm_per_unit,
    names_and_rate,
};
pub use info::{RunInfo, info};
pub use lock::RunLock;
pub use plot::{GAP_FIGURES, plot_run};
pub use prediction::{field_at_frames, field_everywhere};
pub use recording::{RecordingFill, fill_recording};
pub use report::write_gap_report;
pub use spec::{
    GAP_FILLING_FRAMES_PER_ITERATION, GAP_FILLING_H_WEIGHT, GAP_FILLING_ITERATIONS, ModelChoice,
    NewFit, RunSpec, fraction,
};
pub use warp::warp_run;

use std::borrow::Cow;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::data::Trajectories;
use crate::data::layout::TrackFile;
use crate::data::sequence::{HoldOut, LoadOptions, Sequence, load_sequence_with, split_indices};
use crate::gaps::spans::DEFAULT_SPANS;
use crate::train::FitConfig;
use crate::{DomaError, Result};

/// What a run fits and how; saved as `config.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunConfig {
    /// The data file or OBJ folder (absolute path).
    pub data: PathBuf,
    /// An OBJ for the faces, if given.
    pub mesh: Option<PathBuf>,
    /// The clip `[start, end)`, if any.
    pub frames: Option<[usize; 2]>,
    /// Every `stride`-th frame of the clip.
    pub stride: usize,
    /// The fraction of tracks held out of the fit for the report (0: every track is
    /// fitted; the paper's Tab. 1: 0.75).
    pub test_fraction: f64,
    /// Iterations between checkpoints.
    pub checkpoint_every: usize,
    /// The compute backend (a resumed fit uses the same one).
    #[serde(default = "default_backend")]
    pub backend: crate::backend::BackendKind,
    /// The fit (variant, iterations, learning rate, regularisers, seed, …).
    pub fit: FitConfig,
    /// How the fit's `L_H` weight was chosen by validation (`--h-weight auto`): the grid and
    /// each weight's validation EPE; the chosen weight is in `fit`.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub weight_search: Option<crate::train::select::WeightChoice>,
    /// How a tracker's `.npz` is read (its layout and frame).
    #[serde(default)]
    pub tracks: TrackFile,
    /// The reference frame of the canonical positions, within the clip (default: the
    /// frame with the most observed points).
    #[serde(default)]
    pub reference_frame: Option<usize>,
    /// Go on without the tracks that are never observed rather than refuse them.
    #[serde(default)]
    pub drop_unobserved: bool,
    /// Fit a C3D file's model outputs (the points that `POINT:ANGLES`, `FORCES`, `MOMENTS`,
    /// `POWERS`, ... list) as markers. False for a new fit; absent (true) in runs fitted
    /// before they were told apart, which fitted every point.
    #[serde(default = "fitted_every_point")]
    pub model_outputs: bool,
    /// The fraction of the observations hidden from the fit, in spans of frames, to
    /// measure gap filling (seeded by the fit's seed).
    #[serde(default)]
    pub holdout_observations: Option<f64>,
    /// The shortest and longest span of the held-out observations, in frames (default
    /// 2 and 10).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_span: Option<[usize; 2]>,
    /// On tracks with gaps, hide one draw of doma's fill's validation spans from the fit
    /// (seeded by the fit's seed), so that `complete` weighs the field's fills where the
    /// field has not seen the answer ([`crate::gaps::blend`]). A new fit's default; absent
    /// (false) in runs fitted before it was.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub blind_validation: bool,
    /// The fits whose fills doma's fill combines, entry by entry (their median; the mean
    /// of two): this run's field and `fits − 1` more in `fits/2`, `fits/3`, … ([`RunDir::member`]),
    /// each fitted as this one with the next seed, and so with its own initial weights,
    /// frame order, blind spans and validation draws. Each fill weighs its fillers on a few
    /// validation spans per class of gap length, and a fill that chose wrongly on them
    /// costs the combination a half (two fits) or nothing (three); docs/gap-filling.md.
    #[serde(default = "one_fit", skip_serializing_if = "is_one_fit")]
    pub fits: usize,
    /// A digest of the data as the fit read it ([`data_digest`]), so that a run whose data
    /// file was replaced or edited since is refused rather than read with another
    /// normalisation (absent in runs made before it was recorded: not checked).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_digest: Option<String>,
}

/// A digest of a loaded sequence: FNV-1a (64 bits) over its size, positions, mask,
/// confidence weights and normalisation. Loading is deterministic, so the same file and
/// options give the same digest; any change to what the fit would see changes it.
pub fn data_digest(data: &Sequence) -> String {
    let t = &data.trajectories;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h = (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    eat(&(t.frames() as u64).to_le_bytes());
    eat(&(t.points() as u64).to_le_bytes());
    for v in t
        .positions()
        .iter()
        .chain(&data.center)
        .chain([&data.scale])
    {
        eat(&v.to_bits().to_le_bytes());
    }
    if let Some(o) = t.observed() {
        eat(&o.iter().map(|&b| b as u8).collect::<Vec<_>>());
    }
    for k in 0..t.frames() {
        for w in t.weights_in_frame(k).unwrap_or(&[]) {
            eat(&w.to_bits().to_le_bytes());
        }
    }
    format!("fnv1a64:{h:016x}")
}

/// The most fits a run combines ([`RunConfig::fits`]).
pub const MAX_FITS: usize = 9;

pub(super) fn one_fit() -> usize {
    1
}

/// Runs fitted before model outputs were told apart fitted every point of a C3D file.
fn fitted_every_point() -> bool {
    true
}

fn is_one_fit(fits: &usize) -> bool {
    *fits == 1
}

fn default_backend() -> crate::backend::BackendKind {
    crate::backend::BackendKind::Flex
}

impl RunConfig {
    /// A run of `data` with the given fit, every track fitted (no track held out) and a
    /// checkpoint every 50 iterations.
    pub fn new(data: PathBuf, fit: FitConfig) -> Self {
        RunConfig {
            data,
            mesh: None,
            frames: None,
            stride: 1,
            test_fraction: 0.0,
            checkpoint_every: 50,
            backend: default_backend(),
            fit,
            weight_search: None,
            tracks: TrackFile::default(),
            reference_frame: None,
            drop_unobserved: false,
            model_outputs: false,
            holdout_observations: None,
            holdout_span: None,
            blind_validation: true,
            fits: 1,
            data_digest: None,
        }
    }

    /// This config with what its data turned out to be written down: the reference frame
    /// the canonical positions were taken at, and the data's digest ([`data_digest`]).
    pub fn recording(mut self, data: &Sequence) -> Self {
        self.reference_frame = Some(data.trajectories.reference());
        self.data_digest = Some(data_digest(data));
        self
    }

    /// Refuses values that cannot run.
    pub fn validate(&self) -> Result<()> {
        self.fit.validate()?;
        if !(0.0..1.0).contains(&self.test_fraction) {
            return Err(DomaError::InvalidConfig(format!(
                "the test fraction {} must be at least 0 and below 1",
                self.test_fraction
            )));
        }
        if self.checkpoint_every == 0 || self.stride == 0 {
            return Err(DomaError::InvalidConfig(
                "checkpoint interval and stride must be at least 1".into(),
            ));
        }
        if !(1..=MAX_FITS).contains(&self.fits) {
            return Err(DomaError::InvalidConfig(format!(
                "{} fits: a run combines 1 to {MAX_FITS}",
                self.fits
            )));
        }
        Ok(())
    }

    /// The config of fit `k` (from 2) of this run ([`RunConfig::fits`]): this one with
    /// the seed `k − 1` past its own, a fit of its own.
    pub fn member(&self, k: usize) -> RunConfig {
        let mut member = self.clone();
        member.fit.seed = self.fit.seed.wrapping_add(k as u64 - 1);
        member.fits = 1;
        member.data_digest = None;
        member
    }

    /// Loads the run's data, normalised as when it was fitted, with its held-out
    /// observations hidden.
    pub fn load(&self) -> Result<Sequence> {
        let data = self.load_unchecked()?;
        if let Some(fitted) = &self.data_digest {
            let now = data_digest(&data);
            if now != *fitted {
                return Err(DomaError::Malformed {
                    path: self.data.clone(),
                    reason: format!(
                        "reads differently from when the run was fitted (digest {fitted} \
                         then, {now} now): it was replaced or edited since; put the fitted \
                         data back, or fit this data again"
                    ),
                });
            }
        }
        Ok(data)
    }

    fn load_unchecked(&self) -> Result<Sequence> {
        load_sequence_with(
            &self.data,
            &LoadOptions {
                mesh: self.mesh.clone(),
                frames: self.frames.map(|[a, b]| a..b),
                stride: self.stride,
                file: self.tracks.clone(),
                reference: self.reference_frame,
                drop_unobserved: self.drop_unobserved,
                model_outputs: self.model_outputs,
                hold_out: self.holdout_observations.map(|fraction| HoldOut {
                    fraction,
                    spans: self.holdout_span.map_or(DEFAULT_SPANS, |[a, b]| a..=b),
                    seed: self.fit.seed,
                }),
                blind_validation: self.blind_validation.then_some(self.fit.seed),
                validation: self.fit.validation(),
            },
        )
    }

    /// The indices of the training and held-out points of `n` (a seeded split; every
    /// point trains at a test fraction of 0).
    pub fn split_indices(&self, n: usize) -> Result<(Vec<usize>, Vec<usize>)> {
        if self.test_fraction == 0.0 {
            return Ok(((0..n).collect(), Vec::new()));
        }
        split_indices(n, 1.0 - self.test_fraction, self.fit.seed).map_err(|e| {
            DomaError::Malformed {
                path: self.data.clone(),
                reason: format!("{e} (--test-fraction {})", self.test_fraction),
            }
        })
    }

    /// The training and held-out points of `data` (a seeded split; no held-out points
    /// at a test fraction of 0, and then `data` itself, not a copy of a long recording).
    pub fn split<'a>(
        &self,
        data: &'a Trajectories,
    ) -> Result<(Cow<'a, Trajectories>, Option<Trajectories>)> {
        let (train, test) = self.split_indices(data.points())?;
        if test.is_empty() {
            return Ok((Cow::Borrowed(data), None));
        }
        let test = data.select_points(&test)?;
        Ok((Cow::Owned(data.select_points(&train)?), Some(test)))
    }

    /// What a report measures: the held-out tracks, or with none held out the fitted
    /// tracks at their observed entries (a training error, named as such).
    pub fn measured<'a>(
        &self,
        data: &'a Trajectories,
    ) -> Result<(Cow<'a, Trajectories>, &'static str)> {
        Ok(match self.split(data)? {
            (_, Some(test)) => (Cow::Owned(test), "the held-out points of the fitted data"),
            (train, None) => (
                train,
                "the fitted tracks' own observations (no track held out: a training error)",
            ),
        })
    }
}

/// The metrics of a fitted run; saved as `report.json`.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Report {
    /// What was evaluated.
    pub evaluated_on: String,
    /// EPE × 10⁴ over all evaluated points and frames (normalised units).
    pub epe_x1e4: f64,
    /// EPE × 10⁴ per frame (`null` for a frame with no observed entry).
    #[serde(with = "nan_as_null")]
    pub epe_per_frame_x1e4: Vec<f64>,
    /// Frames evaluated.
    pub frames: usize,
    /// Points evaluated.
    pub points: usize,
    /// The field's parameter count.
    pub params: usize,
    /// The size of `model.bpk` in bytes.
    pub checkpoint_bytes: u64,
    /// Iterations fitted.
    pub iterations: usize,
    /// Seconds of fitting (over all resumed parts).
    pub seconds: f64,
    /// Gap filling: the EPE on the observations hidden from the fit, beside two baselines
    /// (`--holdout-observations`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_observations: Option<GapReport>,
    /// The EPE in the data's own units (`epe_x1e4` × 10⁻⁴ × the normalisation's scale), for
    /// data that states its units (a `.c3d` or `.trc`: millimetres, as a lab reads them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub epe: Option<f64>,
    /// The units of `epe` (`mm`, `m`, ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units: Option<String>,
}

impl Report {
    /// This report with its EPE also in `units`, the data's, whose normalisation divided
    /// its coordinates by `scale`.
    pub fn in_units(self, units: Option<String>, scale: f32) -> Report {
        let epe = units.as_ref().map(|_| self.epe_x1e4 * 1e-4 * scale as f64);
        Report { epe, units, ..self }
    }
}

/// A per-frame list with NaN (a frame with nothing to measure) written as JSON's `null`.
mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|x| (!x.is_nan()).then_some(*x)))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let v: Vec<Option<f64>> = Vec::deserialize(d)?;
        Ok(v.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
    }
}
