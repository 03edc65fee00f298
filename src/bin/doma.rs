//! The `doma` command line. Thin: parsing and printing only; the work is in the library.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use doma::backend::BackendKind;
use doma::data::synthetic::Motion;
use doma::experiments::speed;
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
    /// Time the Jacobian step and the training step per backend and Jacobian method.
    Bench(BenchArgs),
}

/// A backend, or every one that can run here.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum BackendArg {
    Flex,
    Ndarray,
    Wgpu,
    All,
}

/// A Jacobian method, or both.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum MethodArg {
    Autodiff,
    Analytic,
    All,
}

#[derive(clap::Args, Debug)]
struct BenchArgs {
    /// The backend to time (`all`: flex, ndarray and wgpu when an adapter exists).
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendArg,
    /// The Jacobian method to time.
    #[arg(long, value_enum, default_value = "all")]
    jacobian: MethodArg,
    /// Point counts of the `jacobian` rows, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1024,16384", value_parser = clap::value_parser!(u64).range(1..))]
    points: Vec<u64>,
    /// Untimed warm-up steps per row.
    #[arg(long, default_value_t = 5)]
    warmup: u64,
    /// Timed steps per row; the median is reported.
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u64).range(1..))]
    steps: u64,
    /// Also write one JSON record per row (kind, backend, method, points, ms, gflops).
    #[arg(long)]
    json: Option<PathBuf>,
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
    /// How the spatial Jacobian is computed: `analytic` (fused, hand-written backward;
    /// the fastest) or `autodiff` (automatic forward mode; the general reference).
    #[arg(long, value_enum, default_value = "analytic")]
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
        check_output_folder(path)?;
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

/// Fails early when `path`'s folder does not exist, before minutes of work.
fn check_output_folder(path: &std::path::Path) -> anyhow::Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
    if let Some(dir) = dir
        && !dir.is_dir()
    {
        anyhow::bail!("{}: the folder does not exist", dir.display());
    }
    Ok(())
}

fn run_bench(args: BenchArgs) -> anyhow::Result<()> {
    if let Some(path) = &args.json {
        check_output_folder(path)?;
    }
    let backends = match args.backend {
        BackendArg::Flex => vec![BackendKind::Flex],
        BackendArg::Ndarray => vec![BackendKind::Ndarray],
        BackendArg::Wgpu => vec![BackendKind::Wgpu],
        BackendArg::All => {
            let mut b = vec![BackendKind::Flex, BackendKind::Ndarray];
            if doma::backend::wgpu_available() {
                b.push(BackendKind::Wgpu);
            } else {
                eprintln!("no wgpu adapter: skipping wgpu");
            }
            b
        }
    };
    let methods = match args.jacobian {
        MethodArg::Autodiff => vec![JacobianKind::Autodiff],
        MethodArg::Analytic => vec![JacobianKind::Analytic],
        MethodArg::All => vec![JacobianKind::Autodiff, JacobianKind::Analytic],
    };
    let job = speed::BenchJob {
        backends,
        methods,
        points: args.points.iter().map(|&p| p as usize).collect(),
        warmup: args.warmup as usize,
        steps: args.steps as usize,
    };
    let rows = speed::run(&job, |r| {
        eprintln!(
            "{:?} {} {} {} points: {:.2} ms",
            r.kind, r.backend, r.method, r.points, r.ms
        )
    })?;
    println!();
    print!("{}", speed::table(&rows));
    if let Some(path) = &args.json {
        speed::write_json(path, &rows)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    doma::backend::tune_allocator();
    let result = match cli.command {
        Command::Synthetic(args) => run_synthetic(args),
        Command::Bench(args) => run_bench(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
