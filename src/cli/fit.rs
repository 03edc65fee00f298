//! `doma fit`: fit a motion field to a user's data into a resumable run folder.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::backend::BackendKind;
use crate::cli::{ClipArgs, WeightSearchArgs, fraction, weight};
use crate::experiments::meshes::Weight;
use crate::field::model::ModelConfig;
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::run::{FitOutcome, RunConfig, RunDir, fit_run};
use crate::train::select::{Penalty, choose_weight};
use crate::train::{FitConfig, SmoothnessSampling};
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
    #[arg(long, conflicts_with_all = ["data", "config", "variant", "iters", "test_fraction", "mesh", "frames", "stride", "jacobian", "h_weight", "seed", "checkpoint_every"])]
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
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

impl FitArgs {
    /// The fit recipe: the `--config` file (or the defaults: DOMA-Affinity, analytic
    /// Jacobian), then the flags over it.
    pub fn fit_config(&self) -> Result<FitConfig> {
        let mut fit = match &self.config {
            Some(path) => FitConfig::load_partial(path)?,
            None => FitConfig::doma(DomaFieldConfig::new(Variant::Affinity))
                .with_jacobian(JacobianKind::Analytic),
        };
        if let Some(v) = self.variant {
            let shape = match &fit.model {
                ModelConfig::Doma(c) => c.shape.clone(),
                _ => crate::siren::SirenShape::new(),
            };
            fit.model = ModelConfig::Doma(DomaFieldConfig::new(v).with_shape(shape));
            fit.smoothness_sampling = SmoothnessSampling::authors(v);
        }
        if let Some(j) = self.jacobian {
            fit.jacobian = j;
        }
        if let Some(i) = self.iters {
            fit.schedule.iterations = i as usize;
        }
        if let Some(Weight::Fixed(w)) = self.h_weight {
            fit.loss.smoothness_weight = w;
        }
        if let Some(s) = self.seed {
            fit.seed = s;
        }
        Ok(fit)
    }

    /// The run config of a new fit of `data`.
    fn run_config(&self, data: &Path) -> Result<RunConfig> {
        let data = absolute(data)?;
        let mut config = RunConfig::new(data, self.fit_config()?);
        config.mesh = self.clip.mesh.as_deref().map(absolute).transpose()?;
        config.frames = self.clip.frames.clone().map(|r| [r.start, r.end]);
        config.stride = self.clip.stride.map_or(1, |s| s as usize);
        config.backend = self.backend.unwrap_or(BackendKind::Flex);
        if let Some(t) = self.test_fraction {
            config.test_fraction = t;
        }
        if let Some(k) = self.checkpoint_every {
            config.checkpoint_every = k as usize;
        }
        if self.h_weight == Some(Weight::Auto) {
            config.validate()?;
            let search = self.search.search()?;
            let (train, _) = config.split(&config.load()?.trajectories)?;
            let device = config.backend.device()?;
            let choice = choose_weight(
                &config.fit,
                Penalty::Smoothness,
                &train,
                &search,
                &device,
                |p| {
                    eprintln!(
                        "weight {:e}: validation EPE {:.2}e-4",
                        p.weight, p.validation_epe_x1e4
                    )
                },
            )?;
            eprintln!("chose the L_H weight {:e}", choice.weight);
            config.fit.loss.smoothness_weight = choice.weight;
            config.weight_search = Some(choice);
        }
        Ok(config)
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

/// Set by SIGINT or SIGTERM; the fit loop polls it after every iteration.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);
/// Which of the two it was, for the exit status (128 + the signal).
static SIGNAL: std::sync::atomic::AtomicI32 = std::sync::atomic::AtomicI32::new(0);

extern "C" fn on_signal(signal: libc::c_int) {
    SIGNAL.store(signal, Ordering::SeqCst);
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Fits (or resumes) the run; Ctrl-C saves a checkpoint and exits with status 130.
pub fn run(args: &FitArgs) -> Result<()> {
    // Ctrl-C, and the SIGTERM that schedulers, `timeout` and `docker stop` send, finish
    // the iteration, save a checkpoint and exit cleanly.
    // SAFETY: the handler only stores to atomics, which is async-signal-safe.
    unsafe {
        for signal in [libc::SIGINT, libc::SIGTERM] {
            libc::signal(signal, on_signal as *const () as libc::sighandler_t);
        }
    }
    let (run, config) = match (&args.resume, &args.data, &args.out) {
        (Some(dir), _, _) => (RunDir::new(dir), None),
        (None, Some(data), Some(out)) => (RunDir::new(out), Some(args.run_config(data)?)),
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
    match fit_run(&run, config, &device, &INTERRUPTED, None, !args.quiet)? {
        FitOutcome::Finished(report) => {
            let text = serde_json::to_string_pretty(&report)
                .map_err(|e| DomaError::InvalidData(e.to_string()))?;
            println!("{text}");
            eprintln!("wrote {}", run.dir.display());
            Ok(())
        }
        FitOutcome::Interrupted { iterations_done } => {
            let signal = match SIGNAL.load(Ordering::SeqCst) {
                0 => libc::SIGINT,
                s => s,
            };
            eprintln!(
                "interrupted after {iterations_done} iterations; the checkpoint is saved. Continue with: doma fit --resume {}",
                run.dir.display()
            );
            std::process::exit(128 + signal);
        }
    }
}
