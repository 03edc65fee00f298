//! The `doma` command line. Thin: parsing and printing only; the work is in the library.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use doma::backend::BackendKind;
use doma::data::synthetic::Motion;
use doma::experiments::meshes;
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
    /// Fit 25 % of an animated mesh's vertices, predict the rest (paper Tab. 1): EPE, CD, CDN.
    NovelPoints(NovelPointsArgs),
    /// Align the frame-0 template to every frame with guidance keypoints (paper Tab. 3).
    MeshAlignment(MeshAlignmentArgs),
    /// DPF vs Trans vs Affinity on 10-frame clips of a fluid simulation (supplement Tab. A8).
    Fluid(FluidArgs),
    /// Trans vs Affinity on a deforming 2-D pixel grid at widths 32/64/128 (supplement Tab. A7).
    Image2d(Image2dArgs),
    /// Fit a motion field to your own data into a run folder (resumable).
    Fit(FitArgs),
    /// Print the metrics of a fitted run, on its held-out points or on new data.
    Eval(EvalArgs),
    /// Warp a canonical mesh through a fitted run and write an OBJ sequence.
    Warp(WarpArgs),
    /// Print a run's variant, parameter count, checkpoint size and data shape.
    Info(InfoArgs),
    /// Write PNG plots of a run (loss, per-frame EPE, 3-view error scatters) to RUN/plots/.
    Plot(PlotArgs),
}

#[derive(clap::Args, Debug)]
struct PlotArgs {
    /// The run folder.
    run: PathBuf,
    /// The frames of the scatter plots (comma-separated; default: the middle and the last).
    #[arg(long, value_delimiter = ',')]
    frames: Option<Vec<usize>>,
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendKind,
}

fn run_plot(args: PlotArgs) -> anyhow::Result<()> {
    let device = args.backend.device()?;
    let run = doma::run::RunDir::new(&args.run);
    for path in doma::run::plot_run(&run, args.frames.as_deref(), &device)? {
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

#[derive(clap::Args, Debug)]
struct FluidArgs {
    /// The particle sequence (default: the crate's data/taichi_mpm3d_fluid.traj).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Frames per clip.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(2..))]
    clip_len: u64,
    /// The first clip's first frame.
    #[arg(long, default_value_t = 10)]
    start: u64,
    /// Frames between clip starts.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..))]
    step: u64,
    /// Explicit clip starts (comma-separated), instead of --start/--step.
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["start", "step"])]
    clips: Option<Vec<usize>>,
    /// Skip clips whose mean particle displacement (normalised units) is below this.
    #[arg(long, default_value_t = 0.02, value_parser = non_negative)]
    min_motion: f64,
    /// The models (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "dpf,trans,affinity"
    )]
    model: Vec<meshes::AlignModel>,
    /// Hidden widths (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "64,128")]
    widths: Vec<usize>,
    /// Iterations per fit (the paper: 5000).
    #[arg(long, default_value_t = 5000, value_parser = clap::value_parser!(u64).range(1..))]
    iters: u64,
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendKind,
    /// Seed of the split and the weights.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bars.
    #[arg(long)]
    quiet: bool,
    /// Also write one JSON record per fit to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Record train and test EPE every this many iterations (a learning curve, in the
    /// JSON records; 0 = none).
    #[arg(long, default_value_t = 0)]
    eval_every: usize,
    /// With --eval-every: write one learning-curve PNG per clip and width here.
    #[arg(long)]
    png_dir: Option<PathBuf>,
    /// Fit nothing: read these record files (written by --json; comma-separated), print
    /// their table, and with --png-dir draw their curves, with --json merge them.
    #[arg(long, value_delimiter = ',')]
    records: Vec<PathBuf>,
}

#[derive(clap::Args, Debug)]
struct Image2dArgs {
    /// Grid resolution (pixels per side).
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u64).range(2..))]
    resolution: u64,
    /// Frames.
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u64).range(2..))]
    frames: u64,
    /// The motions (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "rotation,scaling,shearing,translation"
    )]
    motion: Vec<doma::experiments::image2d::Motion2d>,
    /// The variants (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "trans,affinity"
    )]
    variant: Vec<Variant>,
    /// Hidden widths (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "32,64,128")]
    widths: Vec<usize>,
    /// Iterations per fit.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    iters: u64,
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendKind,
    /// Seed of the split and the weights.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bars.
    #[arg(long)]
    quiet: bool,
    /// The folder for the PNG pictures of the last frame.
    #[arg(long, default_value = "results/image2d")]
    png_dir: PathBuf,
    /// Also write one JSON record per fit to this file.
    #[arg(long)]
    json: Option<PathBuf>,
}

fn run_image2d(args: Image2dArgs) -> anyhow::Result<()> {
    use doma::experiments::image2d;
    if let Some(path) = &args.json {
        check_output_folder(path)?;
    }
    if args.widths.contains(&0) {
        anyhow::bail!("--widths: a hidden width must be at least 1");
    }
    let job = image2d::Image2dJob {
        resolution: args.resolution as usize,
        frames: args.frames as usize,
        motions: args.motion.clone(),
        variants: args.variant.clone(),
        widths: args.widths.clone(),
        iterations: args.iters as usize,
        backend: args.backend,
        seed: args.seed,
        quiet: args.quiet,
        png_dir: Some(args.png_dir.clone()),
    };
    let records = image2d::run(&job, |r| {
        eprintln!(
            "{} {} {}D: EPE {:.2}e-4 in {:.1} s",
            r.motion.name(),
            r.variant,
            r.hidden,
            r.epe_x1e4,
            r.seconds
        )
    })?;
    print!("{}", image2d::table(&records));
    if let Some(path) = &args.json {
        doma::checkpoint::save_json(&records, path)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

fn run_fluid(args: FluidArgs) -> anyhow::Result<()> {
    use doma::experiments::fluid;
    if let Some(path) = &args.json {
        check_output_folder(path)?;
    }
    if args.widths.contains(&0) {
        anyhow::bail!("--widths: a hidden width must be at least 1");
    }
    if let Some(dir) = &args.png_dir {
        if args.eval_every == 0 && args.records.is_empty() {
            anyhow::bail!("--png-dir draws learning curves: it needs --eval-every N");
        }
        // Fail now, not after hours of fitting.
        std::fs::create_dir_all(dir)
            .map_err(|e| anyhow::anyhow!("--png-dir {}: {e}", dir.display()))?;
    }
    if !args.records.is_empty() {
        let mut records = Vec::new();
        for path in &args.records {
            records.extend(doma::checkpoint::load_json::<Vec<fluid::FluidRecord>>(
                path,
            )?);
        }
        return finish_fluid(&records, &args);
    }
    let job = fluid::FluidJob {
        data: args.data.clone().unwrap_or_else(fluid::default_data),
        clip_len: args.clip_len as usize,
        start: args.start as usize,
        step: args.step as usize,
        clips: args.clips.clone(),
        min_motion: args.min_motion,
        models: args.model.clone(),
        widths: args.widths.clone(),
        iterations: args.iters as usize,
        backend: args.backend,
        seed: args.seed,
        quiet: args.quiet,
        eval_every: args.eval_every,
    };
    let records = fluid::run(
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
    )?;
    finish_fluid(&records, &args)
}

/// Prints the fluid table, draws the curves and writes the records, as asked.
fn finish_fluid(
    records: &[doma::experiments::fluid::FluidRecord],
    args: &FluidArgs,
) -> anyhow::Result<()> {
    use doma::experiments::fluid;
    print!("{}", fluid::table(records));
    if let Some(dir) = &args.png_dir {
        for path in fluid::curve_plots(records, dir)? {
            eprintln!("wrote {}", path.display());
        }
    }
    if let Some(path) = &args.json {
        doma::checkpoint::save_json(&records, path)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

#[derive(clap::Args, Debug)]
struct FitArgs {
    /// The data: .traj, .anime, .npy, .npz, or a folder of OBJ frames with equal vertex counts.
    #[arg(required_unless_present = "resume")]
    data: Option<PathBuf>,
    /// The run folder to create (it must not hold a run yet).
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    out: Option<PathBuf>,
    /// Continue the interrupted run in this folder from its last checkpoint.
    #[arg(long, conflicts_with_all = ["data", "config", "variant", "iters", "test_fraction", "mesh", "frames", "stride", "jacobian", "h_weight", "seed", "checkpoint_every"])]
    resume: Option<PathBuf>,
    /// A fit config (JSON, the `fit` part of a run's config.json); flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// The DOMA variant.
    #[arg(long, value_enum)]
    variant: Option<Variant>,
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendKind,
    /// How the spatial Jacobian is computed.
    #[arg(long, value_enum)]
    jacobian: Option<JacobianKind>,
    /// Iterations (passes over all frames).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    iters: Option<u64>,
    /// The fraction of points held out for the report.
    #[arg(long, value_parser = fraction)]
    test_fraction: Option<f64>,
    /// The weight of the smoothness loss L_H (0 = off).
    #[arg(long, value_parser = non_negative, allow_negative_numbers = true)]
    h_weight: Option<f64>,
    /// An OBJ whose vertices are the points in order (for the faces).
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// A clip of the frames, `A..B` (B excluded) or `A..=B`.
    #[arg(long, value_parser = doma::data::parse_frame_range)]
    frames: Option<std::ops::Range<usize>>,
    /// Keep every N-th frame of the clip.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    stride: Option<u64>,
    /// Iterations between checkpoints.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    checkpoint_every: Option<u64>,
    /// Seed of the weights, the split and the frame order.
    #[arg(long)]
    seed: Option<u64>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

#[derive(clap::Args, Debug)]
struct EvalArgs {
    /// The run folder.
    run: PathBuf,
    /// Evaluate on every point of this data instead of the run's held-out points.
    data: Option<PathBuf>,
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendKind,
}

#[derive(clap::Args, Debug)]
struct WarpArgs {
    /// The run folder.
    run: PathBuf,
    /// The canonical mesh, in the data's units (default: the run data's first frame, with
    /// the faces of its mesh).
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// The folder to write frame_0000.obj, … into.
    #[arg(long)]
    out: PathBuf,
    /// Which frames, `A..B` or `A..=B` (default: all of the run's frames).
    #[arg(long, value_parser = doma::data::parse_frame_range)]
    frames: Option<std::ops::Range<usize>>,
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendKind,
}

#[derive(clap::Args, Debug)]
struct InfoArgs {
    /// The run folder.
    run: PathBuf,
}

/// A fraction strictly between 0 and 1.
fn fraction(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("`{s}` is not a number"))?;
    if v > 0.0 && v < 1.0 {
        Ok(v)
    } else {
        Err(format!("`{s}` must be strictly between 0 and 1"))
    }
}

/// Set by SIGINT; the fit loop polls it after every iteration.
static INTERRUPTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

extern "C" fn on_sigint(_: libc::c_int) {
    INTERRUPTED.store(true, std::sync::atomic::Ordering::SeqCst);
}

fn run_fit(args: FitArgs) -> anyhow::Result<()> {
    use doma::run::{FitOutcome, RunConfig, RunDir, fit_run};
    // Ctrl-C finishes the iteration, saves a checkpoint and exits cleanly.
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, on_sigint as *const () as libc::sighandler_t);
    }
    let (run, config) = match &args.resume {
        Some(dir) => {
            let run = RunDir::new(dir);
            // A folder that is not a run fails here, before anything else.
            run.load_config()?;
            (run, None)
        }
        None => {
            let data = args
                .data
                .clone()
                .expect("clap requires DATA without --resume");
            let data = std::fs::canonicalize(&data)
                .map_err(|e| anyhow::anyhow!("{}: {e}", data.display()))?;
            let mut fit = match &args.config {
                Some(path) => doma::checkpoint::load_json::<doma::train::FitConfig>(path)?,
                None => doma::train::FitConfig::new(doma::field::DomaFieldConfig::new(
                    Variant::Affinity,
                ))
                .with_jacobian(JacobianKind::Analytic),
            };
            if let Some(v) = args.variant {
                fit.field.variant = v;
            }
            if let Some(j) = args.jacobian {
                fit.jacobian = j;
            }
            if let Some(i) = args.iters {
                fit.iterations = i as usize;
            }
            if let Some(w) = args.h_weight {
                fit.smoothness_weight = w;
            }
            if let Some(s) = args.seed {
                fit.seed = s;
            }
            fit.quiet = args.quiet;
            let mut config = RunConfig::new(data, fit);
            config.mesh = match &args.mesh {
                Some(m) => Some(
                    std::fs::canonicalize(m)
                        .map_err(|e| anyhow::anyhow!("{}: {e}", m.display()))?,
                ),
                None => None,
            };
            config.frames = args.frames.clone().map(|r| [r.start, r.end]);
            config.stride = args.stride.map_or(1, |s| s as usize);
            config.backend = args.backend;
            if let Some(t) = args.test_fraction {
                config.test_fraction = t;
            }
            if let Some(k) = args.checkpoint_every {
                config.checkpoint_every = k as usize;
            }
            let out = args
                .out
                .clone()
                .expect("clap requires --out without --resume");
            (RunDir::new(out), Some(config))
        }
    };
    let backend = match &config {
        Some(c) => c.backend,
        None => run.load_config()?.backend,
    };
    let device = backend.device()?;
    match fit_run(&run, config, &device, &INTERRUPTED, None)? {
        FitOutcome::Finished(report) => {
            println!("{}", serde_json::to_string_pretty(&report)?);
            eprintln!("wrote {}", run.dir.display());
            Ok(())
        }
        FitOutcome::Interrupted { iterations_done } => {
            eprintln!(
                "interrupted after {iterations_done} iterations; the checkpoint is saved. Continue with: doma fit --resume {}",
                run.dir.display()
            );
            std::process::exit(130);
        }
    }
}

fn run_eval(args: EvalArgs) -> anyhow::Result<()> {
    let device = args.backend.device()?;
    let run = doma::run::RunDir::new(&args.run);
    let report = doma::run::eval_run(&run, args.data.as_deref(), &device)?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

fn run_warp(args: WarpArgs) -> anyhow::Result<()> {
    let device = args.backend.device()?;
    let run = doma::run::RunDir::new(&args.run);
    let paths = doma::run::warp_run(
        &run,
        args.mesh.as_deref(),
        &args.out,
        args.frames.clone(),
        &device,
    )?;
    eprintln!("wrote {} frames to {}", paths.len(), args.out.display());
    Ok(())
}

fn run_info(args: InfoArgs) -> anyhow::Result<()> {
    let info = doma::run::info(&doma::run::RunDir::new(&args.run))?;
    println!("{}", serde_json::to_string_pretty(&info)?);
    Ok(())
}

/// Where the sequence comes from (shared by the mesh experiments).
#[derive(clap::Args, Debug)]
struct SequenceArgs {
    /// The sequence: .traj, .anime, .npy or .npz (default: the crate's data/cdp_male_wave.traj).
    #[arg(long)]
    data: Option<PathBuf>,
    /// An OBJ whose vertices are the points in order, for the faces (default: NAME.obj next
    /// to a .traj, or the .anime's own faces).
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// A clip of the frames, `A..B` (B excluded) or `A..=B`.
    #[arg(long, value_parser = doma::data::parse_frame_range)]
    frames: Option<std::ops::Range<usize>>,
    /// Keep every N-th frame of the clip.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    stride: Option<u64>,
}

impl SequenceArgs {
    fn load(&self, default_stride: usize) -> anyhow::Result<meshes::Sequence> {
        let data = self.data.clone().unwrap_or_else(meshes::default_data);
        let stride = self.stride.map_or(default_stride, |s| s as usize);
        let mut seq =
            meshes::load_sequence(&data, self.mesh.as_deref(), self.frames.clone(), stride)?;
        if let Some(r) = &self.frames {
            seq.name = format!("{}[{}..{}]", seq.name, r.start, r.end);
        }
        if stride > 1 {
            seq.name = format!("{}/{stride}", seq.name);
        }
        Ok(seq)
    }
}

#[derive(clap::Args, Debug)]
struct NovelPointsArgs {
    #[command(flatten)]
    sequence: SequenceArgs,
    /// The DOMA variants (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "trans,se3,scaled-se3,affinity"
    )]
    variant: Vec<Variant>,
    /// Baselines to run too (comma-separated): mlp, mlp-pe6, dct-nerf, bone-cloud.
    #[arg(long, value_enum, value_delimiter = ',')]
    baselines: Vec<doma::field::baselines::Baseline>,
    /// Iterations per fit (the paper: 1000).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    iters: u64,
    /// Surface samples per mesh and frame for CD/CDN (the paper: 1000000).
    #[arg(long, default_value_t = 100_000, value_parser = clap::value_parser!(u64).range(1..))]
    samples: u64,
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendKind,
    /// Seed of the split, the weights and the samples.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bars.
    #[arg(long)]
    quiet: bool,
    /// Also write one JSON record per run to this file.
    #[arg(long)]
    json: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
struct MeshAlignmentArgs {
    #[command(flatten)]
    sequence: SequenceArgs,
    /// The models (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "dpf,trans,affinity"
    )]
    model: Vec<meshes::AlignModel>,
    /// The regularisers (comma-separated): none, a (AIAP), h (smoothness), ah (both).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "none,a,h,ah")]
    reg: Vec<meshes::AlignReg>,
    /// Iterations per fit (the authors: 2000).
    #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u64).range(1..))]
    iters: u64,
    /// Guidance keypoints: this many vertices, a fixed seeded subset.
    #[arg(long, default_value_t = 930, value_parser = clap::value_parser!(u64).range(1..))]
    keypoints: u64,
    /// Template surface samples (the authors: 10000).
    #[arg(long, default_value_t = 10_000, value_parser = clap::value_parser!(u64).range(2..))]
    canonical_samples: u64,
    /// Target surface samples per step (the authors: 10000).
    #[arg(long, default_value_t = 10_000, value_parser = clap::value_parser!(u64).range(1..))]
    target_samples: u64,
    /// Surface samples per mesh and frame for CD/CDN.
    #[arg(long, default_value_t = 40_000, value_parser = clap::value_parser!(u64).range(1..))]
    samples: u64,
    /// The SIREN's hidden width.
    #[arg(long, default_value_t = 128, value_parser = clap::value_parser!(u64).range(1..))]
    hidden: u64,
    /// Hidden sine layers after the first (the authors' registration: 3).
    #[arg(long, default_value_t = 3)]
    n_hidden: u64,
    /// How `L_H`'s Jacobian is computed; `analytic` also fuses the sine layers of every
    /// SIREN-based model's warp (DOMA and DPF).
    #[arg(long, value_enum, default_value = "autodiff")]
    jacobian: JacobianKind,
    /// The compute backend.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendKind,
    /// Seed of the keypoints, the samples, the weights and the frame order.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bars.
    #[arg(long)]
    quiet: bool,
    /// Also write one JSON record per run to this file.
    #[arg(long)]
    json: Option<PathBuf>,
}

fn finish_mesh_runs(
    records: &[meshes::MeshRecord],
    json: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    print!("{}", meshes::table(records));
    if let Some(path) = json {
        meshes::write_json(path, records)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

fn run_novel_points(args: NovelPointsArgs) -> anyhow::Result<()> {
    if let Some(path) = &args.json {
        check_output_folder(path)?;
    }
    let job = meshes::NovelPointsJob {
        sequence: args.sequence.load(1)?,
        variants: args.variant,
        baselines: args.baselines,
        iterations: args.iters as usize,
        train_fraction: 0.25,
        samples: args.samples as usize,
        backend: args.backend,
        jacobian: JacobianKind::Analytic,
        seed: args.seed,
        quiet: args.quiet,
    };
    eprintln!(
        "novel_points on {}: {} frames, {} vertices, {} iterations, backend {}",
        job.sequence.name,
        job.sequence.trajectories.frames(),
        job.sequence.trajectories.points(),
        job.iterations,
        job.backend
    );
    let records = meshes::novel_points(&job, |r| {
        eprintln!(
            "{} EPE {:.2}e-4 in {:.1} s",
            r.variant,
            r.epe_x1e4.unwrap_or(f64::NAN),
            r.seconds
        )
    })?;
    finish_mesh_runs(&records, args.json.as_deref())
}

fn run_mesh_alignment(args: MeshAlignmentArgs) -> anyhow::Result<()> {
    if let Some(path) = &args.json {
        check_output_folder(path)?;
    }
    let config = doma::register::RegistrationConfig::new()
        .with_iterations(args.iters as usize)
        .with_canonical_samples(args.canonical_samples as usize)
        .with_target_samples(args.target_samples as usize)
        .with_jacobian(args.jacobian)
        .with_seed(args.seed)
        .with_quiet(args.quiet);
    let job = meshes::MeshAlignmentJob {
        sequence: args.sequence.load(2)?,
        keypoints: args.keypoints as usize,
        models: args.model,
        regs: args.reg,
        config,
        aiap_weight: 1.0,
        h_weight: 0.001,
        hidden: args.hidden as usize,
        n_hidden: args.n_hidden as usize,
        samples: args.samples as usize,
        backend: args.backend,
    };
    eprintln!(
        "mesh_alignment on {}: {} frames, {} vertices, {} iterations, backend {}",
        job.sequence.name,
        job.sequence.trajectories.frames(),
        job.sequence.trajectories.points(),
        args.iters,
        job.backend
    );
    let records = meshes::mesh_alignment(&job, |r| {
        eprintln!(
            "{}-{} CD {:.3}e-4 in {:.1} s",
            r.variant,
            r.reg,
            r.cd_x1e4.unwrap_or(f64::NAN),
            r.seconds
        )
    })?;
    finish_mesh_runs(&records, args.json.as_deref())
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
    // Die quietly on a closed pipe (`doma eval RUN | head`), as Unix tools do, rather than
    // panic in `println!`.
    // SAFETY: restoring the default disposition of a signal; no other thread exists yet.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Burn materialises a loaded optimizer state on its default device, which is wgpu when
    // compiled in; pin it to the CPU so that resuming a CPU fit never needs a GPU adapter
    // (the state moves to the fit's device at the next step).
    if std::env::var_os("BURN_DEVICE").is_none() {
        // SAFETY: no other thread exists yet.
        unsafe { std::env::set_var("BURN_DEVICE", "flex") };
    }
    let result = match cli.command {
        Command::Synthetic(args) => run_synthetic(args),
        Command::Bench(args) => run_bench(args),
        Command::NovelPoints(args) => run_novel_points(args),
        Command::MeshAlignment(args) => run_mesh_alignment(args),
        Command::Fluid(args) => run_fluid(args),
        Command::Image2d(args) => run_image2d(args),
        Command::Fit(args) => run_fit(args),
        Command::Eval(args) => run_eval(args),
        Command::Warp(args) => run_warp(args),
        Command::Info(args) => run_info(args),
        Command::Plot(args) => run_plot(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
