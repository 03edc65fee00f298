//! `doma fluid`: supplement Tab. A8 (DPF vs Trans vs Affinity on clips of a fluid).

use std::path::PathBuf;

use crate::cli::{AlignModelArgs, ExperimentArgs, check_widths, non_negative};
use crate::experiments::fluid::{self, FluidJob, FluidRecord};
use crate::{DomaError, Result};

/// The flags of `doma fluid`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "DPF vs Trans vs Affinity on 10-frame clips of a fluid simulation (Tab. A8)")]
pub struct FluidArgs {
    /// The particle sequence (default: the crate's data/taichi_mpm3d_fluid.traj).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Frames per clip.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(2..))]
    pub clip_len: u64,
    /// The first clip's first frame.
    #[arg(long, default_value_t = 10)]
    pub start: u64,
    /// Frames between clip starts.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..))]
    pub step: u64,
    /// Explicit clip starts (comma-separated), instead of --start/--step.
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["start", "step"])]
    pub clips: Option<Vec<usize>>,
    /// Skip clips whose mean particle displacement (normalised units) is below this.
    #[arg(long, default_value_t = 0.02, value_parser = non_negative)]
    pub min_motion: f64,
    /// The models.
    #[command(flatten)]
    pub models: AlignModelArgs,
    /// Hidden widths (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "64,128")]
    pub widths: Vec<usize>,
    /// Iterations per fit (the paper: 5000).
    #[arg(long, default_value_t = 5000, value_parser = clap::value_parser!(u64).range(1..))]
    pub iters: u64,
    /// Record train and test EPE every this many iterations (a learning curve, in the
    /// JSON records; 0 = none).
    #[arg(long, default_value_t = 0)]
    pub eval_every: usize,
    /// With --eval-every: write one learning-curve PNG per clip and width here.
    #[arg(long)]
    pub png_dir: Option<PathBuf>,
    /// Fit nothing: read these record files (written by --json; comma-separated), print
    /// their table, and with --png-dir draw their curves, with --json merge them.
    #[arg(long, value_delimiter = ',')]
    pub records: Vec<PathBuf>,
    /// Backend, seed, progress and JSON records.
    #[command(flatten)]
    pub common: ExperimentArgs,
}

impl FluidArgs {
    /// The library job these flags describe.
    pub fn job(&self) -> FluidJob {
        FluidJob {
            data: self.data.clone().unwrap_or_else(fluid::default_data),
            clip_len: self.clip_len as usize,
            start: self.start as usize,
            step: self.step as usize,
            clips: self.clips.clone(),
            min_motion: self.min_motion,
            models: self.models.model.clone(),
            widths: self.widths.clone(),
            iterations: self.iters as usize,
            backend: self.common.backend,
            seed: self.common.seed,
            quiet: self.common.quiet,
            eval_every: self.eval_every,
        }
    }

    /// Refuses flag combinations that cannot run, before any fit.
    fn check(&self) -> Result<()> {
        self.common.check_json()?;
        check_widths(&self.widths)?;
        if let Some(dir) = &self.png_dir {
            if self.eval_every == 0 && self.records.is_empty() {
                return Err(DomaError::Usage(
                    "--png-dir draws learning curves: it needs --eval-every N".into(),
                ));
            }
            // Fail now, not after hours of fitting.
            std::fs::create_dir_all(dir)
                .map_err(|e| DomaError::Usage(format!("--png-dir {}: {e}", dir.display())))?;
        }
        Ok(())
    }
}

/// Fits every clip (or reads `--records`), then prints the table, draws the curves and
/// writes the records, as asked.
pub fn run(args: &FluidArgs) -> Result<()> {
    args.check()?;
    let records = if args.records.is_empty() {
        let job = args.job();
        fluid::run(
            &job,
            |r| {
                for c in &r.curve {
                    eprintln!(
                        "  {} it: train EPE {:.2}e-4, test EPE {:.2}e-4",
                        c.iteration, c.train_epe_x1e4, c.test_epe_x1e4
                    );
                }
                eprintln!(
                    "clip {} {} {}D: EPE {:.2}e-4 in {:.1} s",
                    r.clip_start, r.variant, r.hidden, r.epe_x1e4, r.seconds
                )
            },
            |start, motion| {
                eprintln!(
                    "clip {start}: skipped (mean motion {motion:.4} < {})",
                    job.min_motion
                )
            },
        )?
    } else {
        let mut records = Vec::new();
        for path in &args.records {
            records.extend(crate::io::load_json::<Vec<FluidRecord>>(path)?);
        }
        records
    };
    print!("{}", fluid::table(&records));
    if let Some(dir) = &args.png_dir {
        for path in fluid::curve_plots(&records, dir)? {
            eprintln!("wrote {}", path.display());
        }
    }
    args.common.write_json(&records)
}
