//! The 2-D image deformation experiment (supplement, Tab. A7): the pixels of an image on a
//! grid in `[−1, 1]²` (y up) move through `T = 30` frames of rotation (`2π/T` per frame),
//! scaling (`linspace(0.5, 1.5, T)`), shearing (`x' = x + s y`, `s = linspace(0, 1.5, T)`)
//! and translation (`linspace(−1, 1, T)` added to both coordinates; docs/reference.md §6.2). A seeded
//! 25 % of the pixels train Trans and Affinity at hidden widths 32, 64 and 128 (no
//! regulariser); the EPE ×1e-4 is on the other 75 %.
//!
//! The pixels are 3-D points with `z = 0` so that the same 3-D fields fit them (the
//! authors' 2-D fields have 2 and 6 outputs; ours 3 and 12, with `z` learnt to stay 0). The
//! authors' cat photograph is not available; the colours come from a procedural image
//! (rings and a checkerboard), which only matters for the pictures.

use std::path::PathBuf;

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::Result;
use crate::backend::BackendKind;
use crate::data::Trajectories;
use crate::data::mesh::as_points;
use crate::experiments::Experiment;
use crate::field::model::ModelName;
use crate::field::{DomaFieldConfig, Variant};
use crate::metrics::{EPE_SCALE, epe, predict};
use crate::plot::{Rgb, ramp};
use crate::prelude::*;
use crate::train::{FitConfig, Trainer};

/// The four 2-D motions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Motion2d {
    /// `2π/T` per frame about the origin.
    Rotation,
    /// `linspace(0.5, 1.5, T)`.
    Scaling,
    /// `x' = x + s y`, `s = linspace(0, 1.5, T)`.
    Shearing,
    /// `linspace(−1, 1, T)` added to x and y.
    Translation,
}

impl Motion2d {
    /// The four, in the table's column order.
    pub const ALL: [Motion2d; 4] = [
        Motion2d::Rotation,
        Motion2d::Scaling,
        Motion2d::Shearing,
        Motion2d::Translation,
    ];

    /// Where pixel `(x, y)` is at frame `k` of `t`.
    pub fn apply(self, x: f64, y: f64, k: usize, t: usize) -> (f64, f64) {
        let lin = |a: f64, b: f64| a + (b - a) * k as f64 / (t.max(2) - 1) as f64;
        match self {
            Motion2d::Rotation => {
                let (s, c) = (2.0 * std::f64::consts::PI * k as f64 / t as f64).sin_cos();
                (c * x - s * y, s * x + c * y)
            }
            Motion2d::Scaling => {
                let s = lin(0.5, 1.5);
                (s * x, s * y)
            }
            Motion2d::Shearing => (x + lin(0.0, 1.5) * y, y),
            Motion2d::Translation => {
                let c = lin(-1.0, 1.0);
                (x + c, y + c)
            }
        }
    }
}

/// The pixel centres of an `r × r` grid in `[−1, 1]²`, row-major from the top row (y up).
pub fn grid(r: usize) -> Vec<(f64, f64)> {
    let at = |i: usize| -1.0 + 2.0 * (i as f64 + 0.5) / r as f64;
    (0..r)
        .flat_map(|row| (0..r).map(move |col| (at(col), -at(row))))
        .collect()
}

/// The sequence of `motion` on `pixels`, `[T, N, 3]` with `z = 0`.
pub fn sequence(motion: Motion2d, pixels: &[(f64, f64)], frames: usize) -> Result<Trajectories> {
    let mut positions = Vec::with_capacity(frames * pixels.len() * 3);
    for k in 0..frames {
        for &(x, y) in pixels {
            let (u, v) = motion.apply(x, y, k, frames);
            positions.extend([u as f32, v as f32, 0.0]);
        }
    }
    Trajectories::new(frames, pixels.len(), positions)
}

/// The procedural image: colour rings by radius, darkened on a checkerboard.
pub fn colour(x: f64, y: f64) -> Rgb {
    let r = (x * x + y * y).sqrt();
    let base = ramp((3.0 * r).fract());
    let checker = ((x * 4.0 + 8.0).floor() as i64 + (y * 4.0 + 8.0).floor() as i64) % 2 == 0;
    if checker {
        base.map(|c| (c as f64 * 0.55) as u8)
    } else {
        base
    }
}

/// What to run.
#[derive(Clone, Debug)]
pub struct Image2dJob {
    /// Grid resolution (the paper: 512).
    pub resolution: usize,
    /// Frames (the paper: 30).
    pub frames: usize,
    /// The motions.
    pub motions: Vec<Motion2d>,
    /// The variants (the paper: Trans, Affinity).
    pub variants: Vec<Variant>,
    /// Hidden widths (the paper: 32, 64, 128).
    pub widths: Vec<usize>,
    /// Iterations per fit.
    pub iterations: usize,
    /// The backend.
    pub backend: BackendKind,
    /// Seeds the split and the weights.
    pub seed: u64,
    /// No progress bars.
    pub quiet: bool,
    /// Write PNGs of the last frame (truth and each fit at the smallest width) here.
    pub png_dir: Option<PathBuf>,
}

/// One fit's record.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Image2dRecord {
    /// `image2d`.
    pub experiment: Experiment,
    /// The motion.
    pub motion: Motion2d,
    /// The variant's paper name.
    pub variant: ModelName,
    /// Hidden width.
    pub hidden: usize,
    /// Grid resolution.
    pub resolution: usize,
    /// Iterations.
    pub iters: usize,
    /// EPE ×1e-4 on the held-out 75 % of the pixels.
    pub epe_x1e4: f64,
    /// Trainable parameters.
    pub params: usize,
    /// Fit seconds.
    pub seconds: f64,
}

/// Draws `points` coloured by `colours` into a square picture of `[−2.5, 2.5]²`.
fn render(title: &str, points: &[[f32; 3]], colours: &[Rgb]) -> crate::plot::Figure {
    crate::plot::point_picture(title, points, colours, 320)
}

/// A seeded split of the pixels: a quarter for training, the rest held out.
fn split_pixels(n: usize, seed: u64) -> (Vec<usize>, Vec<usize>) {
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    let test = order.split_off(n / 4);
    (order, test)
}

/// Runs the job; `on_run` after each fit.
pub fn run(job: &Image2dJob, mut on_run: impl FnMut(&Image2dRecord)) -> Result<Vec<Image2dRecord>> {
    // Every network's size first: nothing is drawn or written for a job that cannot run.
    for &variant in &job.variants {
        for &hidden in &job.widths {
            FitConfig::doma(DomaFieldConfig::new(variant).with_hidden(hidden)).validate()?;
        }
    }
    let device = job.backend.device()?;
    let pixels = grid(job.resolution);
    let (train_idx, test_idx) = split_pixels(pixels.len(), job.seed);
    let (train_idx, test_idx) = (&train_idx[..], &test_idx[..]);
    let colours: Vec<Rgb> = test_idx
        .iter()
        .map(|&i| colour(pixels[i].0, pixels[i].1))
        .collect();
    if let Some(dir) = &job.png_dir {
        std::fs::create_dir_all(dir).map_err(|e| crate::DomaError::io(dir, e))?;
    }
    let mut records = Vec::new();
    for &motion in &job.motions {
        let all = sequence(motion, &pixels, job.frames)?;
        let (train, test) = (all.select_points(train_idx)?, all.select_points(test_idx)?);
        let last = job.frames - 1;
        if let Some(dir) = &job.png_dir {
            let title = format!("{motion}, frame {last}: true");
            render(&title, &as_points(test.frame(last)), &colours)
                .save(&dir.join(format!("{motion}_truth.png")))?;
        }
        for &variant in &job.variants {
            for &hidden in &job.widths {
                let config = FitConfig::doma(DomaFieldConfig::new(variant).with_hidden(hidden))
                    .with_iterations(job.iterations)
                    .with_jacobian(crate::jacobian::JacobianKind::Analytic)
                    .with_seed(job.seed);
                let fitted = Trainer::from_config(&config, &train, &device)?
                    .progress(!job.quiet)
                    .run()?;
                let predicted = predict(&fitted.field, &test, &device)?;
                let e = epe(&predicted, &test)?;
                if let (Some(dir), true) = (&job.png_dir, Some(&hidden) == job.widths.iter().min())
                {
                    let title = format!(
                        "{motion}, {}-{hidden}: EPE {:.1}",
                        variant.paper_name(),
                        e * EPE_SCALE
                    );
                    render(&title, &as_points(predicted.frame(last)), &colours)
                        .save(&dir.join(format!("{motion}_{variant}_{hidden}.png")))?;
                }
                let record = Image2dRecord {
                    experiment: Experiment::Image2d,
                    motion,
                    variant: ModelName::of_variant(variant),
                    hidden,
                    resolution: job.resolution,
                    iters: job.iterations,
                    epe_x1e4: e * EPE_SCALE,
                    params: fitted.field.param_count(),
                    seconds: fitted.seconds,
                };
                on_run(&record);
                records.push(record);
            }
        }
    }
    Ok(records)
}

/// Tab. A7's layout: one row per (variant, width), one column per motion.
pub fn table(records: &[Image2dRecord]) -> String {
    let mut rows: Vec<(ModelName, usize)> = Vec::new();
    for r in records {
        if !rows.contains(&(r.variant, r.hidden)) {
            rows.push((r.variant, r.hidden));
        }
    }
    let mut out = format!("{:<22}", "EPE (x1e-4)");
    for m in Motion2d::ALL {
        out += &format!(" | {m:>11}");
    }
    out += "\n";
    for (v, h) in rows {
        out += &format!("{:<22}", format!("{v} {h}D"));
        for m in Motion2d::ALL {
            let cell = records
                .iter()
                .find(|r| r.variant == v && r.hidden == h && r.motion == m)
                .map_or("-".to_string(), |r| format!("{:.2}", r.epe_x1e4));
            out += &format!(" | {cell:>11}");
        }
        out += "\n";
    }
    out
}

crate::names::value_names!(Motion2d);
