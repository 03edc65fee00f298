//! `doma fit`: fit a motion field to a user's data into a resumable run folder.

use std::path::PathBuf;

use crate::backend::BackendKind;
use crate::cli::{ClipArgs, RecipeArgs, WeightSearchArgs, fraction, weight};
use crate::data::layout::{CoordFrame, Layout};
use crate::field::Variant;
use crate::jacobian::JacobianKind;
use crate::loss::DataPenalty;
use crate::run::{FitOutcome, ModelChoice, RunConfig, RunDir, RunSpec, fit_run};
use crate::train::FitConfig;
use crate::train::select::Weight;
use crate::{DomaError, Result};

/// The flags of `doma fit`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Fit a motion field to your own data into a run folder (resumable)")]
pub struct FitArgs {
    /// The data: .traj, .anime, .npy, .npz, or a folder of OBJ frames with equal vertex counts.
    #[arg(required_unless_present = "resume")]
    pub data: Option<PathBuf>,
    /// The run folder to create (it must not hold a run yet).
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    pub out: Option<PathBuf>,
    /// Continue the interrupted run in this folder from its last checkpoint.
    #[arg(long, conflicts_with_all = ["data", "config", "variant", "iters", "test_fraction", "mesh", "frames", "stride", "jacobian", "h_weight", "seed", "checkpoint_every", "points_per_step", "frames_per_step", "layout", "frame", "count_hidden", "reference_frame", "drop_unobserved", "holdout_observations", "confidence", "robust", "recipe", "until_converged"])]
    pub resume: Option<PathBuf>,
    /// A fit config (JSON, the `fit` part of a run's config.json; missing fields take
    /// their defaults); flags override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The DOMA variant (also sets the authors' `L_H` sampling for it).
    #[arg(long, value_enum)]
    pub variant: Option<Variant>,
    /// The compute backend (default flex; a resumed fit keeps its own).
    #[arg(long, value_enum)]
    pub backend: Option<BackendKind>,
    /// How the spatial Jacobian is computed.
    #[arg(long, value_enum)]
    pub jacobian: Option<JacobianKind>,
    /// Iterations (passes over all frames).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub iters: Option<u64>,
    /// The fraction of points held out for the report.
    #[arg(long, value_parser = fraction)]
    pub test_fraction: Option<f64>,
    /// The weight of the smoothness loss L_H (0 = off), or `auto`: chosen by validation on
    /// held-out training points before the fit (the grid goes into config.json and the
    /// plots).
    #[arg(long, value_parser = weight, allow_negative_numbers = true)]
    pub h_weight: Option<Weight>,
    /// How an `auto` weight is searched.
    #[command(flatten)]
    pub search: WeightSearchArgs,
    /// The clip and the faces.
    #[command(flatten)]
    pub clip: ClipArgs,
    /// Iterations between checkpoints.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_every: Option<u64>,
    /// Seed of the weights, the split and the frame order.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Training points per step: a fresh random subset of K each step (default: all of
    /// them, the paper's protocol), so that a step's memory does not grow with the tracks.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub points_per_step: Option<u64>,
    /// Frames per Adam step: each step minimises the sum of B frames' losses (default 1,
    /// the paper's protocol).
    #[arg(long, value_name = "B", value_parser = clap::value_parser!(u64).range(1..))]
    pub frames_per_step: Option<u64>,
    /// The layout of a tracker's .npz (default: detected from its keys).
    #[arg(long, value_enum)]
    pub layout: Option<Layout>,
    /// The coordinate frame of a tracker's tracks: PointOdyssey's are in the world frame
    /// unless `camera` (its extrinsics applied); TAPVid-3D's are in the camera frame.
    #[arg(long, value_enum)]
    pub frame: Option<CoordFrame>,
    /// Count PointOdyssey's valid but hidden entries (its ground truth) as observed.
    #[arg(long)]
    pub count_hidden: bool,
    /// The frame whose positions are the field's input x (default: the frame with the most
    /// observed points), counted within the clip.
    #[arg(long, value_name = "K")]
    pub reference_frame: Option<usize>,
    /// Go on without the tracks that are never observed (`complete` records the kept
    /// indices) rather than refuse them.
    #[arg(long)]
    pub drop_unobserved: bool,
    /// Hide this fraction of the observations from the fit, in spans of 2–10 frames, and
    /// report the EPE on them beside linear interpolation and k-NN.
    #[arg(long, value_name = "F", value_parser = fraction)]
    pub holdout_observations: Option<f64>,
    /// The key of a `[T, N]` array of per-observation confidence weights in a tracker's
    /// .npz: each observation's share of the trajectory loss.
    #[arg(long, value_name = "KEY")]
    pub confidence: Option<String>,
    /// A robust trajectory loss for tracks with outliers: `huber[:DELTA]` or
    /// `charbonnier[:EPSILON]` (normalised units, default 0.01), or `l1` (the paper's).
    #[arg(long, value_name = "PENALTY", value_parser = data_penalty)]
    pub robust: Option<DataPenalty>,
    /// The recipe and the stop on convergence.
    #[command(flatten)]
    pub recipe: RecipeArgs,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Parses `l1`, `huber[:DELTA]` or `charbonnier[:EPSILON]`.
pub fn data_penalty(s: &str) -> std::result::Result<DataPenalty, String> {
    let (kind, scale) = match s.split_once(':') {
        Some((k, v)) => (
            k,
            v.parse::<f64>()
                .map_err(|_| format!("`{v}` is not a number"))?,
        ),
        None => (s, 0.01),
    };
    let penalty = match kind {
        "l1" if !s.contains(':') => DataPenalty::L1,
        "huber" => DataPenalty::Huber { delta: scale },
        "charbonnier" => DataPenalty::Charbonnier { epsilon: scale },
        _ => {
            return Err(format!(
                "`{s}` is not l1, huber[:DELTA] or charbonnier[:EPSILON]"
            ));
        }
    };
    penalty.validate()?;
    Ok(penalty)
}

impl FitArgs {
    /// What the flags ask for, as a [`RunSpec`] (the same that a batch manifest's entry
    /// deserialises into).
    pub fn spec(&self) -> RunSpec {
        RunSpec {
            data: self.data.clone(),
            config: self.config.clone(),
            model: self.variant.map(ModelChoice::from),
            backend: self.backend,
            jacobian: self.jacobian,
            iterations: self.iters.map(|i| i as usize),
            h_weight: self.h_weight,
            seed: self.seed,
            mesh: self.clip.mesh.clone(),
            frames: self.clip.frames.clone().map(|r| [r.start, r.end]),
            stride: self.clip.stride.map(|s| s as usize),
            test_fraction: self.test_fraction,
            checkpoint_every: self.checkpoint_every.map(|k| k as usize),
            points_per_step: self.points_per_step.map(|k| k as usize),
            frames_per_step: self.frames_per_step.map(|b| b as usize),
            layout: self.layout,
            frame: self.frame,
            count_hidden: self.count_hidden.then_some(true),
            reference_frame: self.reference_frame,
            drop_unobserved: self.drop_unobserved.then_some(true),
            holdout_observations: self.holdout_observations,
            confidence: self.confidence.clone(),
            data_penalty: self.robust,
            recipe: self.recipe.recipe,
            until_converged: self.recipe.until_converged.map(|p| p as usize),
        }
    }

    /// The fit recipe: the `--config` file (or the defaults: DOMA-Affinity, analytic
    /// Jacobian), then the flags over it.
    pub fn fit_config(&self) -> Result<FitConfig> {
        self.spec().fit_config(|| {
            Err(DomaError::Usage(
                "a DPF fit is asked for with --config".into(),
            ))
        })
    }

    /// The run config of a new fit (after the weight search, with `--h-weight auto`).
    fn run_config(&self) -> Result<RunConfig> {
        let search = self.search.search()?;
        let config = self.spec().run_config(&search, |p| {
            eprintln!(
                "weight {:e}: validation EPE {:.2}e-4",
                p.weight, p.validation_epe_x1e4
            )
        })?;
        if let Some(choice) = &config.weight_search {
            eprintln!("chose the L_H weight {:e}", choice.weight);
        }
        Ok(config)
    }
}

/// Fits (or resumes) the run; Ctrl-C saves a checkpoint and exits with status 130.
pub fn run(args: &FitArgs) -> Result<()> {
    let interrupt = crate::cli::interrupt::install();
    let (run, config) = match (&args.resume, &args.data, &args.out) {
        (Some(dir), _, _) => (RunDir::new(dir), None),
        (None, Some(_), Some(out)) => (RunDir::new(out), Some(args.run_config()?)),
        _ => {
            return Err(DomaError::Usage(
                "give DATA and --out, or --resume RUN".into(),
            ));
        }
    };
    // A folder that is not a run fails here, before anything else. A resumed fit runs on
    // the backend it was started on (its Adam state and random stream are that device's).
    let backend = match &config {
        Some(c) => c.backend,
        None => {
            let saved = run.load_config()?.backend;
            if let Some(asked) = args.backend.filter(|&b| b != saved) {
                return Err(DomaError::Usage(format!(
                    "--backend {asked}: {} was fitted on {saved}, and resumes there",
                    run.dir.display()
                )));
            }
            saved
        }
    };
    let device = backend.device()?;
    match fit_run(&run, config, &device, interrupt, None, !args.quiet)? {
        FitOutcome::Finished(report) => {
            let text = serde_json::to_string_pretty(&report)
                .map_err(|e| DomaError::InvalidData(e.to_string()))?;
            println!("{text}");
            eprintln!("wrote {}", run.dir.display());
            Ok(())
        }
        FitOutcome::Interrupted { iterations_done } => {
            eprintln!(
                "interrupted after {iterations_done} iterations; the checkpoint is saved. Continue with: doma fit --resume {}",
                run.dir.display()
            );
            crate::cli::interrupt::exit();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_penalties_parse_with_and_without_a_scale() {
        assert_eq!(data_penalty("l1"), Ok(DataPenalty::L1));
        assert_eq!(
            data_penalty("huber"),
            Ok(DataPenalty::Huber { delta: 0.01 })
        );
        assert_eq!(
            data_penalty("charbonnier:0.002"),
            Ok(DataPenalty::Charbonnier { epsilon: 0.002 })
        );
        for bad in ["huber:-1", "huber:x", "l2", "l1:3", "charbonnier:0"] {
            assert!(data_penalty(bad).is_err(), "{bad}");
        }
    }
}
