//! `doma synthetic`: the synthetic benchmark of Tab. 2.

use crate::Result;
use crate::cli::{ExperimentArgs, RecipeArgs, RegWeightArgs, Selection, selection};
use crate::data::synthetic::Motion;
use crate::experiments::synthetic::{self, Regularizer, SyntheticJob};
use crate::field::Variant;
use crate::jacobian::JacobianKind;
use crate::train::select::Weight;

/// The flags of `doma synthetic`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Fit the synthetic benchmark (paper Tab. 2) and print the EPE table")]
pub struct SyntheticArgs {
    /// The synthetic motions (comma-separated: rotation, scaling, shearing, translation;
    /// or all).
    #[arg(long, default_value = "all", value_parser = selection::<Motion>)]
    pub motion: Selection<Motion>,
    /// The DOMA variants, the degrees of freedom of A (comma-separated: trans, se3,
    /// scaled-se3, affinity; or all).
    #[arg(long, default_value = "all", value_parser = selection::<Variant>)]
    pub variant: Selection<Variant>,
    /// The regulariser: none, the smoothness loss H (Eq. 13) or the elasticity E.
    #[arg(long, value_enum, default_value = "none")]
    pub reg: Regularizer,
    /// The regularisers' weights, fixed or searched.
    #[command(flatten)]
    pub weights: RegWeightArgs,
    /// Iterations (passes over all 20 frames); 1000 is the paper's budget.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..), allow_negative_numbers = true)]
    pub iters: u64,
    /// The recipe and the stop on convergence.
    #[command(flatten)]
    pub recipe: RecipeArgs,
    /// The hidden width of the SIREN.
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u64).range(1..))]
    pub hidden: u64,
    /// How the spatial Jacobian is computed: `analytic` (fused, hand-written backward;
    /// the fastest) or `autodiff` (automatic forward mode; the general reference).
    #[arg(long, value_enum, default_value = "analytic")]
    pub jacobian: JacobianKind,
    /// Backend, seed, progress and JSON records.
    #[command(flatten)]
    pub common: ExperimentArgs,
}

impl SyntheticArgs {
    /// The library job these flags describe.
    pub fn job(&self) -> Result<SyntheticJob> {
        let fixed = |w: Weight| match w {
            Weight::Fixed(w) => w,
            Weight::Auto => 0.0,
        };
        let auto = match self.reg {
            Regularizer::H => self.weights.h_weight == Weight::Auto,
            Regularizer::E => self.weights.e_weight == Weight::Auto,
            Regularizer::None => false,
        };
        let job = SyntheticJob {
            motions: self.motion.items.clone(),
            variants: self.variant.items.clone(),
            reg: self.reg,
            h_weight: fixed(self.weights.h_weight),
            e_weight: fixed(self.weights.e_weight),
            iterations: self.iters as usize,
            recipe: self.recipe.choice(),
            hidden: self.hidden as usize,
            backend: self.common.backend,
            jacobian: self.jacobian,
            seed: self.common.seed,
            quiet: self.common.quiet,
            weight_search: if auto {
                Some(self.weights.search.search()?)
            } else {
                None
            },
        };
        // A model too large is refused naming the flag that sized it.
        for &variant in &job.variants {
            job.fit_config(variant).model.validate().map_err(|e| {
                crate::DomaError::Usage(format!(
                    "--hidden {}: {}",
                    self.hidden,
                    e.to_string().trim_start_matches("invalid configuration: ")
                ))
            })?;
        }
        Ok(job)
    }
}

/// Runs the job: one line per fit as it finishes, then the table.
pub fn run(args: &SyntheticArgs) -> Result<()> {
    args.common.check_json()?;
    let job = args.job()?;
    let runs = synthetic::run(&job, |r| {
        let auto = r
            .weight_search
            .as_ref()
            .map_or(String::new(), |c| format!(" auto {:e}", c.weight));
        eprintln!(
            "{:<11} {:<18} EPE x1e-4 {:>10.2}  ({:.1} s, {:.2} ms/step)",
            r.motion,
            format!("{}{}{auto}", r.variant.paper_name(), r.reg.suffix()),
            r.epe_x1e4,
            r.seconds,
            1e3 * r.seconds / r.steps as f64
        );
    })?;
    println!(
        "\nSynthetic benchmark, {} iterations, backend {}, jacobian {}\n",
        job.iterations, job.backend, job.jacobian
    );
    print!("{}", synthetic::table(&runs));
    args.common.write_json(&runs)
}
