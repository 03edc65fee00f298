//! `doma bench`: the speed table (Jacobian step and training step per backend and method).

use std::path::PathBuf;

use crate::backend::{BackendKind, wgpu_available};
use crate::cli::{Selection, check_output_folder, selection};
use crate::experiments::scaling;
use crate::experiments::speed::{self, BenchJob};
use crate::jacobian::JacobianKind;
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
    /// Instead of the table: time per training step and peak memory for N ∈ {10³, 10⁴,
    /// 10⁵} training points and T ∈ {20, 100} frames (each cell in a fresh process, on
    /// flex), and checkpoint bytes against T for DOMA and DPF.
    #[arg(long, conflicts_with = "compare_torch")]
    pub scaling: bool,
    /// With --scaling: write scaling_step, scaling_memory and scaling_checkpoint (.png and
    /// .svg) into this folder.
    #[arg(long, requires = "scaling", value_name = "DIR")]
    pub plot: Option<PathBuf>,
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

/// Times every row, then prints the table (or the comparison with PyTorch).
pub fn run(args: &BenchArgs) -> Result<()> {
    if let Some(path) = &args.json {
        check_output_folder(path)?;
    }
    if let Some(cell) = &args.scaling_cell {
        return scaling_cell(cell, args);
    }
    if args.scaling {
        return scaling(args);
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
            crate::checkpoint::save_json(&rows, path)?;
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
        crate::checkpoint::save_json(&rows, path)?;
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
        crate::checkpoint::save_json(&record, path)?;
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
