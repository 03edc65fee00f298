//! `doma novel-points`: Tab. 1 (fit 25 % of an animated mesh's vertices, predict the rest).

use crate::Result;
use crate::cli::{ExperimentArgs, RecipeArgs, RegWeightArgs, SequenceArgs};
use crate::experiments::meshes::{self, MeshRecord, NovelPointsJob};
use crate::experiments::synthetic::Regularizer;
use crate::field::Variant;
use crate::field::baselines::Baseline;
use crate::jacobian::JacobianKind;

/// The flags of `doma novel-points`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Fit 25 % of an animated mesh's vertices, predict the rest (paper Tab. 1)")]
pub struct NovelPointsArgs {
    /// The sequence.
    #[command(flatten)]
    pub sequence: SequenceArgs,
    /// The DOMA variants (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "trans,se3,scaled-se3,affinity"
    )]
    pub variant: Vec<Variant>,
    /// Baselines to run too (comma-separated): mlp, mlp-pe6, dct-nerf, banmo,
    /// bone-cloud.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub baselines: Vec<Baseline>,
    /// Iterations per fit (the paper: 1000).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    pub iters: u64,
    /// The recipe and the stop on convergence.
    #[command(flatten)]
    pub recipe: RecipeArgs,
    /// The regularisers (comma-separated): none, h (smoothness, Eq. 13), e (elasticity);
    /// one row per model and regulariser.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "none")]
    pub reg: Vec<Regularizer>,
    /// The regularisers' weights, fixed or searched.
    #[command(flatten)]
    pub weights: RegWeightArgs,
    /// Surface samples per mesh and frame for CD/CDN (the paper: 1000000).
    #[arg(long, default_value_t = 100_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub samples: u64,
    /// Backend, seed, progress and JSON records.
    #[command(flatten)]
    pub common: ExperimentArgs,
}

impl NovelPointsArgs {
    /// The library job these flags describe (loads the sequence).
    pub fn job(&self) -> Result<NovelPointsJob> {
        Ok(NovelPointsJob {
            sequence: self.sequence.load(1)?,
            variants: self.variant.clone(),
            baselines: self.baselines.clone(),
            iterations: self.iters as usize,
            recipe: self.recipe.choice(),
            train_fraction: 0.25,
            samples: self.samples as usize,
            backend: self.common.backend,
            // The fused value path of the SIREN layers; the baselines take autodiff.
            jacobian: JacobianKind::Analytic,
            seed: self.common.seed,
            quiet: self.common.quiet,
            regs: self.reg.clone(),
            h_weight: self.weights.h_weight,
            e_weight: self.weights.e_weight,
            search: self.weights.search.search()?,
        })
    }
}

/// Prints the records' table and writes their JSON.
pub(crate) fn finish(records: &[MeshRecord], common: &ExperimentArgs) -> Result<()> {
    print!("{}", meshes::table(records));
    common.write_json(&records)
}

/// Runs every fit, then prints the table.
pub fn run(args: &NovelPointsArgs) -> Result<()> {
    args.common.check_json()?;
    let job = args.job()?;
    SequenceArgs::announce(
        "novel_points",
        &job.sequence,
        job.iterations as u64,
        job.backend,
    );
    let records = meshes::novel_points(&job, |r| {
        let weight = r
            .weight
            .map_or(String::new(), |w| format!(" (weight {w:e})"));
        eprintln!(
            "{}{}{weight} EPE {:.2}e-4 in {:.1} s",
            r.variant,
            r.reg.suffix(),
            r.epe_x1e4.unwrap_or(f64::NAN),
            r.seconds
        )
    })?;
    finish(&records, &args.common)
}
