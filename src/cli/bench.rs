//! `doma bench`: the speed table (Jacobian step and training step per backend and method).

use std::path::PathBuf;

use crate::backend::{BackendKind, wgpu_available};
use crate::cli::{ClipArgs, Selection, SequenceArgs, check_output_folder, selection};
use crate::data::sequence::split_indices;
use crate::data::synthetic::{Motion, benchmark_sequence};
use crate::experiments::scaling;
use crate::experiments::speed::{self, BenchJob};
use crate::experiments::synthetic::Regularizer;
use crate::experiments::time_to_accuracy::{self as tta, Contender, Problem, TimeJob, authors_epe};
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::train::{FitConfig, Recipe, WithSchedule};
use crate::{DomaError, Result};

/// The flags of `doma bench`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Time the Jacobian step and the training step per backend and Jacobian method")]
pub struct BenchArgs {
    /// The backends to time (comma-separated: flex, ndarray, wgpu; `all`: flex, ndarray
    /// and wgpu when an adapter exists).
    #[arg(long, default_value = "flex", value_parser = selection::<BackendKind>)]
    pub backend: Selection<BackendKind>,
    /// The Jacobian methods to time (comma-separated: autodiff, analytic; or all).
    #[arg(long, default_value = "all", value_parser = selection::<JacobianKind>)]
    pub jacobian: Selection<JacobianKind>,
    /// Point counts of the `jacobian` rows, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1024,16384", value_parser = clap::value_parser!(u64).range(1..))]
    pub points: Vec<u64>,
    /// Untimed warm-up steps per row.
    #[arg(long, default_value_t = 5)]
    pub warmup: u64,
    /// Timed steps per row; the median is reported.
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u64).range(1..))]
    pub steps: u64,
    /// Also write one JSON record per row (kind, backend, method, points, ms, gflops,
    /// peak_percent); with --compare-torch, one per comparison.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Instead of the table: doma against PyTorch on flex, side by side, alternating
    /// rounds; PYTHON is an interpreter with torch installed (runs benches/torch_step.py).
    #[arg(long, value_name = "PYTHON")]
    pub compare_torch: Option<PathBuf>,
    /// Rounds. The comparison alternates doma and PyTorch this many times (default 3). The
    /// table runs all its rows this many times, so that the methods alternate, and reports
    /// each row's median over the rounds (default 1): on a machine whose speed drifts
    /// (lavapipe, shared hosts), a ratio of rows timed minutes apart is not one run. (The
    /// training-step rows also time the methods' steps in turn within a round.)
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub rounds: Option<u64>,
    /// Instead of the table: the composed training step against the fused one (the
    /// protocol's Affinity-H and L1 steps, and `--recipe fast`'s, also with SOAP's
    /// update), timed in turn on the first --backend, with the paired speed-up.
    #[arg(long, conflicts_with_all = ["compare_torch", "scaling"])]
    pub fused: bool,
    /// Instead of the table: time per training step and peak memory for N ∈ {10³, 10⁴,
    /// 10⁵} training points and T ∈ {20, 100} frames (each cell in a fresh process, on
    /// flex), and checkpoint bytes against T for DOMA and DPF.
    #[arg(long, conflicts_with = "compare_torch")]
    pub scaling: bool,
    /// With --scaling: write scaling_step, scaling_memory and scaling_checkpoint (.png and
    /// .svg) into this folder; with --time-to-accuracy, one time_to_accuracy_PROBLEM per
    /// problem.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// Instead of the table: the held-out EPE against fit time of the paper's protocol and
    /// the recipes, on the synthetic motions (or on --data), with the time each takes to
    /// reach the authors' final EPE and the protocol's own.
    #[command(flatten)]
    pub time: TimeArgs,
    /// One scaling cell, `N,T` or `N,T,K` (K points per step), measured in this process
    /// and printed as JSON; --scaling runs each cell so.
    #[arg(long, hide = true, value_name = "N,T[,K]")]
    pub scaling_cell: Option<String>,
}

impl BenchArgs {
    /// The library job these flags describe (`all` skips wgpu without an adapter).
    pub fn job(&self) -> BenchJob {
        let mut backends = self.backend.items.clone();
        if self.backend.all && !wgpu_available() {
            eprintln!("no wgpu adapter: skipping wgpu");
            backends.retain(|&b| b != BackendKind::Wgpu);
        }
        BenchJob {
            backends,
            methods: self.jacobian.items.clone(),
            points: self.points.iter().map(|&p| p as usize).collect(),
            warmup: self.warmup as usize,
            steps: self.steps as usize,
            rounds: self.rounds.unwrap_or(1) as usize,
        }
    }
}

/// The flags of `doma bench --time-to-accuracy`.
#[derive(clap::Args, Debug, Clone)]
pub struct TimeArgs {
    /// Time to accuracy instead of the step table.
    #[arg(long, conflicts_with_all = ["compare_torch", "scaling", "scaling_cell"])]
    pub time_to_accuracy: bool,
    /// The synthetic motions (comma-separated, or all); ignored with --data.
    #[arg(long, default_value = "all", value_parser = selection::<Motion>)]
    pub motion: Selection<Motion>,
    /// The DOMA variant.
    #[arg(long, value_enum, default_value = "affinity")]
    pub variant: Variant,
    /// The regulariser: none, H (`L_H`, weight 0.1) or E (elasticity, weight 0.01).
    #[arg(long, value_enum, default_value = "h")]
    pub reg: Regularizer,
    /// The named recipes to run (comma-separated: paper, fast, soap; or all). The first one
    /// run is the reference of the speed-ups; `paper` always runs first.
    #[arg(long, default_value = "all", value_parser = selection::<Recipe>)]
    pub recipe: Selection<Recipe>,
    /// A recipe as a JSON file of fit-config fields laid over the paper's (for example
    /// `{"schedule": {"iterations": 200, "learning_rate": 3e-4}}`), named by its file stem;
    /// repeatable.
    #[arg(long, value_name = "FILE")]
    pub recipe_file: Vec<PathBuf>,
    /// The paper protocol's budget in iterations (1000 on the synthetic benchmark).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    pub paper_iters: u64,
    /// Evaluations per curve (one every budget / N iterations, and after the last).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    pub curve_points: u64,
    /// A sequence to fit instead of the synthetic motions: a seeded --train-fraction of
    /// its points is fitted, the rest scores the curve (novel points, as in Tab. 1).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// The clip of --data.
    #[command(flatten)]
    pub clip: ClipArgs,
    /// With --data: the fraction of the points fitted.
    #[arg(long, default_value_t = 0.25)]
    pub train_fraction: f64,
    /// The seed of the weights, the frame order and the split of --data.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

impl TimeArgs {
    /// The contenders: `paper` first (the paper's protocol at --paper-iters), then the
    /// other named recipes, then the recipe files.
    pub fn contenders(&self) -> Result<Vec<Contender>> {
        // The weights of docs/results.md's "-H" and "-E" rows.
        let (w_h, w_e) = self.reg.weights(0.1, 0.01);
        let paper = FitConfig::doma(DomaFieldConfig::new(self.variant))
            .with_iterations(self.paper_iters as usize)
            .with_smoothness_weight(w_h)
            .with_elasticity_weight(w_e)
            .with_jacobian(JacobianKind::Analytic)
            .with_seed(self.seed);
        let mut recipes = vec![Recipe::Paper];
        recipes.extend(self.recipe.items.iter().filter(|&&r| r != Recipe::Paper));
        let mut out: Vec<Contender> = recipes
            .into_iter()
            .map(|r| Contender {
                name: r.to_string(),
                config: r.apply(paper.clone()),
            })
            .collect();
        for path in &self.recipe_file {
            let name = path
                .file_stem()
                .map_or("file".into(), |s| s.to_string_lossy().into_owned());
            out.push(Contender {
                name,
                config: paper.overlaid(path)?,
            });
        }
        Ok(out)
    }

    /// The problems: the synthetic motions, or the seeded split of --data.
    pub fn problems(&self) -> Result<Vec<Problem>> {
        match &self.data {
            None => self
                .motion
                .items
                .iter()
                .map(|&m| {
                    let seq = benchmark_sequence(m, 0)?;
                    Ok(Problem {
                        name: m.to_string(),
                        motion: Some(m),
                        train: seq.train,
                        test: seq.test,
                    })
                })
                .collect(),
            Some(data) => {
                let seq = SequenceArgs {
                    data: Some(data.clone()),
                    clip: self.clip.clone(),
                }
                .load(1)?;
                let all = &seq.trajectories;
                let (train, test) = split_indices(all.points(), self.train_fraction, self.seed)?;
                Ok(vec![Problem {
                    name: seq.name.clone(),
                    motion: None,
                    train: all.select_points(&train)?,
                    test: all.select_points(&test)?,
                }])
            }
        }
    }
}

/// Runs the time-to-accuracy comparison, prints its table, and writes the JSON and plots.
fn time_to_accuracy(args: &BenchArgs) -> Result<()> {
    let time = &args.time;
    if let Some(dir) = &args.plot {
        check_output_folder(&dir.join("time_to_accuracy.png"))?;
    }
    let backend = *args.backend.items.first().unwrap_or(&BackendKind::Flex);
    let job = TimeJob {
        problems: time.problems()?,
        contenders: time.contenders()?,
        curve_points: time.curve_points as usize,
        backend,
        quiet: true,
    };
    let (variant, reg) = (time.variant, time.reg);
    let authors = |p: &Problem| p.motion.and_then(|m| authors_epe(variant, reg, m));
    let record = tta::run(&job, authors, |c| {
        eprintln!(
            "{:<12} {:<14} EPE x1e-4 {:>10.2} after {:>5} iterations, {:.1} s of fitting (+{:.1} s of curve)",
            c.problem, c.contender, c.final_epe_x1e4, c.iterations, c.fit_seconds, c.eval_seconds
        )
    })?;
    println!(
        "\nTime to accuracy: {}{}, backend {backend}; seconds of fitting, evaluation excluded",
        variant.paper_name(),
        reg.suffix()
    );
    print!("{}", tta::table(&record));
    if let Some(path) = &args.json {
        crate::io::save_json(&record, path)?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(dir) = &args.plot {
        let by_name = |name: &str| {
            job.problems
                .iter()
                .find(|p| p.name == name)
                .and_then(&authors)
        };
        for (name, figure) in tta::plots(&record, by_name) {
            let path = dir.join(name);
            figure.save_png_and_svg(&path)?;
            eprintln!("wrote {}", path.with_extension("png").display());
        }
    }
    Ok(())
}

/// Times every row, then prints the table (or the comparison with PyTorch).
pub fn run(args: &BenchArgs) -> Result<()> {
    if let Some(path) = &args.json {
        check_output_folder(path)?;
    }
    if args.time.time_to_accuracy {
        return time_to_accuracy(args);
    }
    if args.plot.is_some() && !args.scaling {
        return Err(DomaError::Usage(
            "--plot goes with --scaling or --time-to-accuracy".into(),
        ));
    }
    if let Some(cell) = &args.scaling_cell {
        return scaling_cell(cell, args);
    }
    if args.scaling {
        return scaling(args);
    }
    if args.fused {
        let backend = args
            .backend
            .items
            .first()
            .copied()
            .unwrap_or(BackendKind::Flex);
        let rows = speed::fused_rows(backend, args.warmup as usize, args.steps as usize)?;
        print!("{}", speed::fused_table(&rows));
        if let Some(path) = &args.json {
            crate::io::save_json(&rows, path)?;
            eprintln!("wrote {}", path.display());
        }
        return Ok(());
    }
    if let Some(python) = &args.compare_torch {
        let rows = speed::compare_torch(
            python,
            args.rounds.unwrap_or(3) as usize,
            args.warmup as usize,
            args.steps as usize,
            |line| eprintln!("{line}"),
        )?;
        println!();
        print!("{}", speed::comparison_table(&rows));
        if let Some(path) = &args.json {
            crate::io::save_json(&rows, path)?;
            eprintln!("wrote {}", path.display());
        }
        return Ok(());
    }
    let rows = speed::run(&args.job(), |r| {
        let method = r.method.map_or("-".into(), |m| m.to_string());
        eprintln!(
            "{:?} {} {method} {} points: {:.2} ms ({:.0} % of the GEMM peak)",
            r.kind, r.backend, r.points, r.ms, r.peak_percent
        )
    })?;
    println!();
    print!("{}", speed::table(&rows));
    if let Some(path) = &args.json {
        crate::io::save_json(&rows, path)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

fn scaling_cell(spec: &str, args: &BenchArgs) -> Result<()> {
    let (n, t, k) = scaling::parse_cell(spec)?;
    let cell = scaling::measure_cell(
        n,
        t,
        k,
        args.warmup as usize,
        args.steps as usize,
        &burn::tensor::Device::flex(),
    )?;
    let text = serde_json::to_string(&cell).map_err(|e| DomaError::InvalidData(e.to_string()))?;
    println!("{text}");
    Ok(())
}

/// Runs every cell in a child process (its own peak memory), then the checkpoint sizes.
fn scaling(args: &BenchArgs) -> Result<()> {
    if let Some(dir) = &args.plot {
        check_output_folder(&dir.join("scaling_step.png"))?;
    }
    let exe = std::env::current_exe().map_err(|e| DomaError::io("the doma binary", e))?;
    let cells = scaling::run_cells(&exe, args.warmup as usize, args.steps as usize, |cell| {
        eprintln!(
            "N {} T {} per step {}: {:.2} ms, peak {} MiB",
            cell.points,
            cell.frames,
            cell.points_per_step.map_or("all".into(), |k| k.to_string()),
            cell.step_ms,
            cell.peak_mib.map_or("-".into(), |m| format!("{m:.0}"))
        )
    })?;
    let sizes = scaling::checkpoint_sizes(&scaling::CHECKPOINT_FRAMES)?;
    println!();
    print!("{}", scaling::scaling_table(&cells, &sizes));
    if let Some(path) = &args.json {
        let record = serde_json::json!({ "cells": cells, "checkpoints": sizes });
        crate::io::save_json(&record, path)?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(dir) = &args.plot {
        for (name, canvas) in scaling::scaling_plots(&cells, &sizes) {
            let path = dir.join(name);
            canvas.save_png_and_svg(&path)?;
            eprintln!("wrote {}", path.display());
        }
    }
    Ok(())
}
