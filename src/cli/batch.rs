//! `doma batch`: fit every sequence of a manifest, or this process's shard of them, into
//! one batch folder; `--collect` tabulates the batch ([`crate::batch`]).

use std::path::PathBuf;

use crate::batch::{ItemOutcome, Manifest, Shard, collect, run_shard};
use crate::cli::WeightSearchArgs;
use crate::{DomaError, Result};

/// The flags of `doma batch`.
#[derive(clap::Parser, Debug, Clone)]
#[command(
    about = "Fit every sequence of a manifest (or one shard of them) into run folders; --collect tabulates them",
    after_help = "The shard defaults to the scheduler's: Slurm's SLURM_ARRAY_TASK_ID with \
SLURM_ARRAY_TASK_COUNT, or Kubernetes' JOB_COMPLETION_INDEX with --shard-count. \
Exit status: 0 when every entry of the shard is done or left to another process, 1 when \
any failed (see DIR/NAME/error.json), 128 + the signal when interrupted."
)]
pub struct BatchArgs {
    /// The manifest (JSON; see the docs of `doma::batch::manifest`), or a folder or a
    /// pattern (`trials/*.c3d`) of recordings, each filled as `doma fill` fills it into
    /// --out (its shard of them).
    #[arg(required_unless_present = "collect")]
    pub manifest: Option<PathBuf>,
    /// The batch folder: one run folder per entry.
    #[arg(long, required_unless_present = "collect", conflicts_with = "collect")]
    pub out: Option<PathBuf>,
    /// Run shard I of N: entries I, I+N, I+2N, … (default: the scheduler's array index,
    /// else all of them).
    #[arg(long, value_parser = Shard::parse, value_name = "I/N")]
    pub shard: Option<Shard>,
    /// The number of shards when the index comes from $JOB_COMPLETION_INDEX (Kubernetes:
    /// the Job's completions) or overrides $SLURM_ARRAY_TASK_COUNT.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..), conflicts_with = "shard")]
    pub shard_count: Option<u64>,
    /// Print this shard's entries and exit, fitting nothing.
    #[arg(long, conflicts_with = "collect")]
    pub list: bool,
    /// Write DIR/summary.csv and DIR/summary.json: every entry's status, metrics,
    /// iterations and seconds, and the errors of the failed ones.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["manifest", "shard", "shard_count"])]
    pub collect: Option<PathBuf>,
    /// How an `h_weight` of `auto` is searched.
    #[command(flatten)]
    pub search: WeightSearchArgs,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
}

impl BatchArgs {
    /// The shard: `--shard`, else the scheduler's environment, else all entries.
    pub fn shard(&self) -> Result<Shard> {
        if let Some(s) = self.shard {
            return Ok(s);
        }
        let count = self.shard_count.map(|n| n as usize);
        match Shard::from_env(|k| std::env::var(k).ok(), count)? {
            Some(s) => Ok(s),
            None if count.is_some() => Err(DomaError::Usage(
                "--shard-count needs $JOB_COMPLETION_INDEX or $SLURM_ARRAY_TASK_ID for the index"
                    .into(),
            )),
            None => Ok(Shard::ALL),
        }
    }
}

/// Runs the shard (exit status 1 if any entry failed), or collects.
pub fn run(args: &BatchArgs) -> Result<()> {
    if let Some(dir) = &args.collect {
        return collect_and_print(dir);
    }
    let (Some(path), Some(out)) = (&args.manifest, &args.out) else {
        return Err(DomaError::Usage(
            "give MANIFEST and --out, or --collect DIR".into(),
        ));
    };
    // A folder or a pattern of recordings is `doma fill`'s job over them, sharded.
    if path.is_dir() || path.to_str().is_some_and(|p| p.contains(['*', '?'])) {
        return crate::cli::fill::run(&crate::cli::fill::FillArgs {
            inputs: vec![path.clone()],
            out: out.clone(),
            format: None,
            fit: false,
            no_fit: false,
            fill: Default::default(),
            iterations: None,
            jobs: 1,
            flag_above: 5.0,
            overwrite: false,
            keep_runs: None,
            shard: Some(args.shard()?),
            quiet: args.quiet,
            device: crate::cli::DeviceArgs {
                backend: crate::backend::BackendKind::Flex,
            },
        });
    }
    let manifest = Manifest::load(path)?;
    let shard = args.shard()?;
    let search = args.search.search()?;
    if args.list {
        for (i, item) in manifest.items.iter().enumerate() {
            if shard.owns(i) {
                println!("{}", item.name);
            }
        }
        return Ok(());
    }
    // The batch folder's own files must not replace the manifest or an entry's data.
    let mut inputs: Vec<&std::path::Path> = vec![path.as_path()];
    inputs.extend(manifest.items.iter().filter_map(|i| i.spec.data.as_deref()));
    for name in [crate::batch::MANIFEST_COPY, "summary.json", "summary.csv"] {
        crate::io::check_output(&out.join(name), None, &inputs)?;
    }
    let interrupt = crate::cli::interrupt::install();
    let mine = (0..manifest.items.len()).filter(|&i| shard.owns(i)).count();
    eprintln!(
        "shard {shard}: {mine} of {} sequences",
        manifest.items.len()
    );
    let report = run_shard(
        &manifest,
        out,
        shard,
        &search,
        interrupt,
        !args.quiet,
        |item| {
            let what = match &item.outcome {
                ItemOutcome::Done => "done before, skipped".to_string(),
                ItemOutcome::Fitted { epe_x1e4, seconds } => {
                    format!("fitted: EPE {epe_x1e4:.2}e-4 in {seconds:.1} s")
                }
                ItemOutcome::Resumed { epe_x1e4, seconds } => {
                    format!("resumed and finished: EPE {epe_x1e4:.2}e-4 in {seconds:.1} s")
                }
                ItemOutcome::Busy { holder } => format!("left to {holder}, which holds it"),
                ItemOutcome::Failed { error } => format!("FAILED: {error}"),
            };
            eprintln!("{}: {what}", item.name);
        },
    )?;
    let text =
        serde_json::to_string_pretty(&report).map_err(|e| DomaError::InvalidData(e.to_string()))?;
    println!("{text}");
    if report.interrupted {
        eprintln!(
            "interrupted; the current fit's checkpoint is saved. Rerun the same command to finish the shard."
        );
        crate::cli::interrupt::exit();
    }
    if report.any_failed() {
        return Err(DomaError::InvalidData(format!(
            "shard {shard}: {} of its sequences failed (their errors are in {}/NAME/error.json)",
            report
                .items
                .iter()
                .filter(|i| matches!(i.outcome, ItemOutcome::Failed { .. }))
                .count(),
            out.display()
        )));
    }
    Ok(())
}

fn collect_and_print(dir: &std::path::Path) -> Result<()> {
    let rows = collect(dir)?;
    println!(
        "{:<24} {:<10} {:<14} {:>10} {:>6} {:>9}  error",
        "name", "status", "model", "EPE x1e4", "iters", "seconds"
    );
    let opt = |v: Option<String>| v.unwrap_or_else(|| "-".into());
    for r in &rows {
        let status = serde_json::to_value(r.status)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default();
        println!(
            "{:<24} {:<10} {:<14} {:>10} {:>6} {:>9}  {}",
            r.name,
            status,
            opt(r.model.clone()),
            opt(r.epe_x1e4.map(|e| format!("{e:.2}"))),
            opt(r.iterations.map(|i| i.to_string())),
            opt(r.seconds.map(|s| format!("{s:.1}"))),
            r.error.clone().unwrap_or_default(),
        );
    }
    let failed = rows
        .iter()
        .filter(|r| r.status == crate::batch::RunStatus::Failed)
        .count();
    let done = rows
        .iter()
        .filter(|r| r.status == crate::batch::RunStatus::Done)
        .count();
    eprintln!(
        "{done} of {} done, {failed} failed; wrote {}/summary.csv and summary.json",
        rows.len(),
        dir.display()
    );
    Ok(())
}
