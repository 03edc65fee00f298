//! The `doma` command line. Thin: parsing and printing only; the work is in the library.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use doma::backend::BackendKind;
use doma::data::synthetic::Motion;
use doma::experiments::synthetic::{self, Regularizer, SyntheticJob};
use doma::field::Variant;
use doma::jacobian::JacobianKind;

/// DOMA motion fields (CVPR 2024) on Burn: fit SIREN motion fields to point trajectories.
#[derive(Parser, Debug)]
#[command(name = "doma", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Fit the synthetic benchmark (paper Tab. 2) and print the EPE table.
    Synthetic(SyntheticArgs),
}

/// A motion, or all four.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum MotionArg {
    Rotation,
    Scaling,
    Shearing,
    Translation,
    All,
}

/// A variant, or all four.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum VariantArg {
    Trans,
    Se3,
    ScaledSe3,
    Affinity,
    All,
}

#[derive(clap::Args, Debug)]
struct SyntheticArgs {
    /// The synthetic motion to fit.
    #[arg(long, value_enum, default_value = "all")]
    motion: MotionArg,
    /// The DOMA variant (the degrees of freedom of A).
    #[arg(long, value_enum, default_value = "all")]
    variant: VariantArg,
    /// The regulariser: none, the smoothness loss H (Eq. 13) or the elasticity E.
    #[arg(long, value_enum, default_value = "none")]
    reg: Regularizer,
    /// The weight of the smoothness loss with --reg h.
    #[arg(long, default_value_t = 0.1, value_parser = non_negative, allow_negative_numbers = true)]
    h_weight: f64,
    /// The weight of the elasticity loss with --reg e.
    #[arg(long, default_value_t = 0.01, value_parser = non_negative, allow_negative_numbers = true)]
    e_weight: f64,
    /// Iterations (passes over all 20 frames); 1000 is the paper's budget.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..), allow_negative_numbers = true)]
    iters: u64,
    /// The hidden width of the SIREN.
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u64).range(1..))]
    hidden: u64,
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendKind,
    /// How the spatial Jacobian is computed.
    #[arg(long, value_enum, default_value = "autodiff")]
    jacobian: JacobianKind,
    /// Seed of the initial weights and the frame order.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bars.
    #[arg(long)]
    quiet: bool,
    /// Also write one JSON record per run to this file.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// A finite, non-negative float.
fn non_negative(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("`{s}` must be finite and non-negative"))
    }
}

fn run_synthetic(args: SyntheticArgs) -> anyhow::Result<()> {
    let motions = match args.motion {
        MotionArg::All => Motion::ALL.to_vec(),
        MotionArg::Rotation => vec![Motion::Rotation],
        MotionArg::Scaling => vec![Motion::Scaling],
        MotionArg::Shearing => vec![Motion::Shearing],
        MotionArg::Translation => vec![Motion::Translation],
    };
    let variants = match args.variant {
        VariantArg::All => Variant::ALL.to_vec(),
        VariantArg::Trans => vec![Variant::Trans],
        VariantArg::Se3 => vec![Variant::Se3],
        VariantArg::ScaledSe3 => vec![Variant::ScaledSe3],
        VariantArg::Affinity => vec![Variant::Affinity],
    };
    if let Some(path) = &args.json {
        // Fail before hours of fitting, not after.
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
        if let Some(dir) = dir
            && !dir.is_dir()
        {
            anyhow::bail!("{}: the folder does not exist", dir.display());
        }
    }
    let job = SyntheticJob {
        motions,
        variants,
        reg: args.reg,
        h_weight: args.h_weight,
        e_weight: args.e_weight,
        iterations: args.iters as usize,
        hidden: args.hidden as usize,
        backend: args.backend,
        jacobian: args.jacobian,
        seed: args.seed,
        quiet: args.quiet,
    };
    let runs = synthetic::run(&job, |r| {
        eprintln!(
            "{:<11} {:<18} EPE x1e-4 {:>10.2}  ({:.1} s, {:.2} ms/step)",
            r.motion.name(),
            format!("{}{}", r.variant.paper_name(), r.reg.suffix()),
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
    if let Some(path) = &args.json {
        synthetic::write_json(path, &runs)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Synthetic(args) => run_synthetic(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
