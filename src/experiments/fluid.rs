//! The fluid experiment (supplement, Tab. A8): 10-frame clips of a particle simulation,
//! half of the particles for training and half for testing, frame-wise DPF against
//! DOMA-Trans and DOMA-Affinity at hidden widths 64 and 128 (2 hidden layers), EPE ×1e-4
//! averaged over the clips.
//!
//! Clips are frames `[t, t + 10)` for `t = start, start + step, …` (or a given list); each clip's first frame
//! is canonical and each clip is normalised like every sequence in doma. A clip whose mean
//! particle displacement (first to last frame, normalised units) is below `min_motion` is
//! skipped as trivial, like the authors' static beginning and steady end.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::backend::BackendKind;
use crate::checkpoint::Precision;
use crate::data::Trajectories;
use crate::data::sequence::{load_sequence, split_indices};
use crate::experiments::Experiment;
use crate::experiments::meshes::AlignModel;
use crate::field::MotionField;
use crate::field::model::ModelName;
use crate::jacobian::JacobianKind;
use crate::metrics::{EPE_SCALE, evaluate_epe};
use crate::prelude::*;
use crate::siren::SirenShape;
use crate::train::{FitConfig, Trainer};
use crate::{DomaError, Result};

/// What to run.
#[derive(Clone, Debug)]
pub struct FluidJob {
    /// The particle sequence (a `.traj`, `.npy`, …).
    pub data: PathBuf,
    /// Frames per clip (the paper: 10).
    pub clip_len: usize,
    /// The first clip's first frame.
    pub start: usize,
    /// Frames between clip starts (the paper: 5).
    pub step: usize,
    /// Explicit clip starts, instead of `start, start + step, …`.
    pub clips: Option<Vec<usize>>,
    /// Clips whose mean displacement is below this (normalised units) are skipped.
    pub min_motion: f64,
    /// The models.
    pub models: Vec<AlignModel>,
    /// Hidden widths (the paper: 64 and 128).
    pub widths: Vec<usize>,
    /// Iterations per fit (the paper: 5000).
    pub iterations: usize,
    /// The backend.
    pub backend: BackendKind,
    /// Seeds the split and the weights.
    pub seed: u64,
    /// No progress bars.
    pub quiet: bool,
    /// Record a learning curve point (train and test EPE) every this many iterations
    /// (0 = none).
    pub eval_every: usize,
}

/// One point of a learning curve: the error on the training and on the held-out
/// particles after `iteration` iterations. A gap that grows while the training error
/// falls is overfitting.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CurvePoint {
    /// Iterations done.
    pub iteration: usize,
    /// EPE ×1e-4 on the training particles.
    pub train_epe_x1e4: f64,
    /// EPE ×1e-4 on the held-out particles.
    pub test_epe_x1e4: f64,
}

/// One fit's record.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FluidRecord {
    /// `fluid`.
    pub experiment: Experiment,
    /// The clip's first frame.
    pub clip_start: usize,
    /// The clip's mean particle displacement (normalised units).
    pub motion: f64,
    /// The model's paper name.
    pub variant: ModelName,
    /// Hidden width.
    pub hidden: usize,
    /// Iterations.
    pub iters: usize,
    /// EPE ×1e-4 on the held-out half.
    pub epe_x1e4: f64,
    /// Trainable parameters.
    pub params: usize,
    /// f32 checkpoint bytes.
    pub checkpoint_bytes: u64,
    /// Fit seconds.
    pub seconds: f64,
    /// The learning curve, when asked for ([`FluidJob::eval_every`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub curve: Vec<CurvePoint>,
}

/// The mean displacement from the first to the last frame.
pub fn mean_motion(clip: &Trajectories) -> f64 {
    let (a, b) = (clip.frame(0), clip.frame(clip.frames() - 1));
    let n = clip.points();
    (0..n)
        .map(|i| {
            (0..3)
                .map(|c| (b[3 * i + c] as f64 - a[3 * i + c] as f64).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .sum::<f64>()
        / n as f64
}

impl FluidJob {
    /// The first frame of every clip: the explicit list, or `start, start + step, …`.
    /// A listed clip that runs past the sequence is refused before any fit.
    pub fn clip_starts(&self) -> Result<Vec<usize>> {
        let total = load_sequence(&self.data, None, None, 1)?
            .trajectories
            .frames();
        let len = self.clip_len;
        Ok(match &self.clips {
            Some(list) => {
                if let Some(bad) = list.iter().find(|&&s| s + len > total) {
                    return Err(DomaError::InvalidConfig(format!(
                        "clip {bad}: frames {bad}..{} run past the sequence's {total} frames",
                        bad + len
                    )));
                }
                list.clone()
            }
            None if self.start + len <= total => {
                (self.start..=total - len).step_by(self.step).collect()
            }
            None => Vec::new(),
        })
    }
}

/// Runs the job; `on_run` after each fit, `on_skip(start, motion)` for a trivial clip.
pub fn run(
    job: &FluidJob,
    mut on_run: impl FnMut(&FluidRecord),
    mut on_skip: impl FnMut(usize, f64),
) -> Result<Vec<FluidRecord>> {
    let device = job.backend.device()?;
    if job.clip_len < 2 || job.step == 0 {
        return Err(DomaError::InvalidConfig(
            "clips need at least 2 frames and a step of at least 1".into(),
        ));
    }
    // Every network's size first: a job that cannot run fits nothing.
    for &model in &job.models {
        for &hidden in &job.widths {
            let shape = SirenShape::new().with_hidden(hidden);
            FitConfig::new(model.config(job.clip_len, shape)).validate()?;
        }
    }
    let starts = job.clip_starts()?;
    let mut records = Vec::new();
    for start in starts {
        let clip =
            load_sequence(&job.data, None, Some(start..start + job.clip_len), 1)?.trajectories;
        let motion = mean_motion(&clip);
        if motion < job.min_motion {
            on_skip(start, motion);
            continue;
        }
        let (train_idx, test_idx) = split_indices(clip.points(), 0.5, job.seed)?;
        let (train, test) = (
            clip.select_points(&train_idx)?,
            clip.select_points(&test_idx)?,
        );
        for &model in &job.models {
            for &hidden in &job.widths {
                let shape = SirenShape::new().with_hidden(hidden);
                let config = FitConfig::new(model.config(clip.frames(), shape))
                    .with_iterations(job.iterations)
                    .with_jacobian(JacobianKind::Analytic)
                    .with_seed(job.seed);
                let clip_run = ClipRun {
                    job,
                    start,
                    motion,
                    model,
                    hidden,
                    train: &train,
                    test: &test,
                    device: &device,
                };
                let r = clip_run.fit(&config)?;
                on_run(&r);
                records.push(r);
            }
        }
    }
    Ok(records)
}

/// One model's fit on one clip.
struct ClipRun<'a> {
    job: &'a FluidJob,
    start: usize,
    motion: f64,
    model: AlignModel,
    hidden: usize,
    train: &'a Trajectories,
    test: &'a Trajectories,
    device: &'a burn::tensor::Device,
}

impl ClipRun<'_> {
    /// Fits `field` to the training half (recording the learning curve if asked) and
    /// scores it on the held-out half.
    fn fit(&self, config: &FitConfig) -> Result<FluidRecord> {
        let mut curve = Vec::new();
        let trainer = Trainer::from_config(config, self.train, self.device)?;
        let fitted =
            trainer
                .progress(!self.job.quiet)
                .run_observed(self.job.eval_every, |r, f| {
                    curve.push(CurvePoint {
                        iteration: r.iteration + 1,
                        train_epe_x1e4: evaluate_epe(&f, self.train, self.device)? * EPE_SCALE,
                        test_epe_x1e4: evaluate_epe(&f, self.test, self.device)? * EPE_SCALE,
                    });
                    Ok(())
                })?;
        Ok(FluidRecord {
            experiment: Experiment::Fluid,
            clip_start: self.start,
            motion: self.motion,
            variant: self.model.name(),
            hidden: self.hidden,
            iters: self.job.iterations,
            epe_x1e4: evaluate_epe(&fitted.field, self.test, self.device)? * EPE_SCALE,
            params: fitted.field.param_count(),
            checkpoint_bytes: fitted.field.encode(Precision::F32)?.len() as u64,
            seconds: fitted.seconds,
            curve,
        })
    }
}

/// The table of Tab. A8: mean EPE over the clips, one row per model, one column per width.
pub fn table(records: &[FluidRecord]) -> String {
    let mut widths: Vec<usize> = records.iter().map(|r| r.hidden).collect();
    widths.sort_unstable();
    widths.dedup();
    let mut models: Vec<ModelName> = Vec::new();
    for r in records {
        if !models.contains(&r.variant) {
            models.push(r.variant);
        }
    }
    let clips = {
        let mut c: Vec<usize> = records.iter().map(|r| r.clip_start).collect();
        c.sort_unstable();
        c.dedup();
        c.len()
    };
    let mut out = format!("{:<16}", format!("EPE x1e-4 ({clips} clips)"));
    for w in &widths {
        out += &format!(" | {:>9}", format!("{w}D"));
    }
    out += "\n";
    for m in models {
        out += &format!("{m:<16}");
        for &w in &widths {
            let v: Vec<f64> = records
                .iter()
                .filter(|r| r.variant == m && r.hidden == w)
                .map(|r| r.epe_x1e4)
                .collect();
            let cell = if v.is_empty() {
                "-".into()
            } else {
                format!("{:.2}", v.iter().sum::<f64>() / v.len() as f64)
            };
            out += &format!(" | {cell:>9}");
        }
        out += "\n";
    }
    out
}

/// One learning-curve picture per clip and width (`fluid_clip{start}_{hidden}d.png` in
/// `dir`): EPE ×1e-4 against iterations, log scale, each model's held-out error with its
/// training error in a lighter shade. Records without a curve are left out. Returns the
/// paths written.
pub fn curve_plots(records: &[FluidRecord], dir: &Path) -> Result<Vec<PathBuf>> {
    use crate::plot::{Series, line_plot};
    std::fs::create_dir_all(dir).map_err(|e| DomaError::io(dir, e))?;
    let mut keys: Vec<(usize, usize)> = records
        .iter()
        .filter(|r| !r.curve.is_empty())
        .map(|r| (r.clip_start, r.hidden))
        .collect();
    keys.sort_unstable();
    keys.dedup();
    let palette = [[200, 40, 40], [40, 60, 200], [30, 150, 70], [150, 60, 170]];
    let light = |c: [u8; 3]| c.map(|v| v + (255 - v) / 2);
    let mut written = Vec::new();
    for (start, hidden) in keys {
        let runs: Vec<&FluidRecord> = records
            .iter()
            .filter(|r| r.clip_start == start && r.hidden == hidden && !r.curve.is_empty())
            .collect();
        let names: Vec<(String, String)> = runs
            .iter()
            .map(|r| {
                (
                    format!("{} test", r.variant),
                    format!("{} train", r.variant),
                )
            })
            .collect();
        let mut series = Vec::new();
        for (i, (r, (test, train))) in runs.iter().zip(&names).enumerate() {
            let color = palette[i % palette.len()];
            let pts = |f: fn(&CurvePoint) -> f64| {
                r.curve.iter().map(|c| (c.iteration as f64, f(c))).collect()
            };
            series.push(Series {
                name: test,
                color,
                points: pts(|c| c.test_epe_x1e4),
            });
            series.push(Series {
                name: train,
                color: light(color),
                points: pts(|c| c.train_epe_x1e4),
            });
        }
        let figure = line_plot(
            &format!("Fluid clip {start}, {hidden}-wide"),
            "iteration",
            "EPE ×1e-4",
            &series,
            true,
        );
        let path = dir.join(format!("fluid_clip{start}_{hidden}d.png"));
        figure.save_png_and_svg(&path)?;
        written.push(path);
    }
    Ok(written)
}

/// The default particle data: the crate's `data/taichi_mpm3d_fluid.traj`.
pub fn default_data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/taichi_mpm3d_fluid.traj")
}
