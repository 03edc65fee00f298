//! Many fits, one per sequence of a dataset (`doma batch`): a [`Manifest`] lists them,
//! a [`Shard`] picks this process's part, and every sequence becomes the same run folder
//! that `doma fit` makes, under one batch folder:
//!
//! | file | what |
//! |---|---|
//! | `DIR/batch-manifest.json` | the manifest's entries, resolved (for `--collect`) |
//! | `DIR/NAME/…` | the run folder of entry `NAME` ([`crate::run`]) |
//! | `DIR/NAME/error.json` | why its last attempt failed ([`Failure`]); gone once it succeeds |
//! | `DIR/summary.csv`, `DIR/summary.json` | the table of `--collect` ([`SummaryRow`]) |
//!
//! A shard skips finished runs, resumes interrupted ones from their checkpoint, leaves a
//! run that another process holds (its lock) to that process, and records a failure and
//! goes on to the next entry. Rerunning a shard after a crash or a kill therefore
//! finishes exactly what is left.

pub mod manifest;
pub mod shard;

pub use manifest::{BatchItem, Manifest};
pub use shard::Shard;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use serde::{Deserialize, Serialize};

use crate::io::{load_json, save_json};
use crate::run::{FitOutcome, Report, RunDir, RunSpec, fit_run};
use crate::train::IterationRecord;
use crate::train::select::WeightSearch;
use crate::{DomaError, Result};

/// The file under the batch folder that keeps the manifest's resolved entries.
pub const MANIFEST_COPY: &str = "batch-manifest.json";

/// The batch folder's own files, which no entry may be named.
pub const RESERVED: [&str; 3] = [MANIFEST_COPY, "summary.json", "summary.csv"];
/// A run folder's record of its last failure.
pub const ERROR_FILE: &str = "error.json";

/// What became of one entry in a shard.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "status")]
pub enum ItemOutcome {
    /// Finished before (its `report.json` exists): skipped.
    Done,
    /// Fitted from the start now.
    Fitted {
        /// EPE × 10⁴ on the held-out points.
        epe_x1e4: f64,
        /// Seconds of fitting.
        seconds: f64,
    },
    /// An interrupted fit, continued from its checkpoint and finished now.
    Resumed {
        /// EPE × 10⁴ on the held-out points.
        epe_x1e4: f64,
        /// Seconds of fitting, over all its parts.
        seconds: f64,
    },
    /// Another process holds the run's lock: left to it.
    Busy {
        /// Who: "process 1234".
        holder: String,
    },
    /// Failed; the error is also in the run's `error.json`.
    Failed {
        /// The error, as the CLI prints it.
        error: String,
    },
}

/// One entry of a [`ShardReport`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ItemReport {
    /// The entry's name.
    pub name: String,
    /// What became of it.
    #[serde(flatten)]
    pub outcome: ItemOutcome,
}

/// What one shard did (printed as JSON by `doma batch`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShardReport {
    /// The shard, `I/N`.
    pub shard: String,
    /// Its entries, in order, up to where it stopped.
    pub items: Vec<ItemReport>,
    /// Whether a signal stopped it (the current fit's checkpoint is saved).
    pub interrupted: bool,
}

impl ShardReport {
    /// Whether any entry failed.
    pub fn any_failed(&self) -> bool {
        self.items
            .iter()
            .any(|i| matches!(i.outcome, ItemOutcome::Failed { .. }))
    }
}

/// A run folder's `error.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    /// The error.
    pub error: String,
    /// When, in seconds since the Unix epoch.
    pub unix_seconds: u64,
}

/// Runs `shard`'s entries of `manifest` into the batch folder `out` (made if missing).
/// `interrupt` is polled by every fit: when set, the fit checkpoints and the shard stops.
/// `on_item` hears each entry's outcome as it happens. Weight searches (`h_weight: auto`)
/// use `search`.
pub fn run_shard(
    manifest: &Manifest,
    out: &Path,
    shard: Shard,
    search: &WeightSearch,
    interrupt: &AtomicBool,
    progress: bool,
    mut on_item: impl FnMut(&ItemReport),
) -> Result<ShardReport> {
    std::fs::create_dir_all(out).map_err(|e| DomaError::io(out, e))?;
    save_json(manifest, &out.join(MANIFEST_COPY))?;
    let mut report = ShardReport {
        shard: shard.to_string(),
        items: Vec::new(),
        interrupted: false,
    };
    for (i, item) in manifest.items.iter().enumerate() {
        if !shard.owns(i) {
            continue;
        }
        if interrupt.load(Ordering::SeqCst) {
            report.interrupted = true;
            break;
        }
        let run = RunDir::new(out.join(&item.name));
        let Some(outcome) = run_item(&run, &item.spec, search, interrupt, progress)? else {
            report.interrupted = true;
            break;
        };
        let entry = ItemReport {
            name: item.name.clone(),
            outcome,
        };
        on_item(&entry);
        report.items.push(entry);
    }
    Ok(report)
}

/// One entry: skip, resume or fit; a failure is recorded and returned as an outcome.
/// `Ok(None)`: interrupted. `Err`: the failure could not even be recorded.
fn run_item(
    run: &RunDir,
    spec: &RunSpec,
    search: &WeightSearch,
    interrupt: &AtomicBool,
    progress: bool,
) -> Result<Option<ItemOutcome>> {
    if run.report().is_file() {
        return Ok(Some(ItemOutcome::Done));
    }
    let resumed = run.config().is_file();
    let attempt = if resumed {
        resume(run, interrupt, progress)
    } else {
        fit_new(run, spec, search, interrupt, progress)
    };
    let error = match attempt {
        Ok(FitOutcome::Finished(r)) => {
            let _ = std::fs::remove_file(run.dir.join(ERROR_FILE));
            let (epe_x1e4, seconds) = (r.epe_x1e4, r.seconds);
            return Ok(Some(if resumed {
                ItemOutcome::Resumed { epe_x1e4, seconds }
            } else {
                ItemOutcome::Fitted { epe_x1e4, seconds }
            }));
        }
        Ok(FitOutcome::Interrupted { .. }) => return Ok(None),
        Err(DomaError::Busy { holder, .. }) => return Ok(Some(ItemOutcome::Busy { holder })),
        Err(e) => e.to_string(),
    };
    let unix_seconds = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let failure = Failure {
        error: error.clone(),
        unix_seconds,
    };
    // A failure is reported even when its folder cannot hold `error.json` (a file of the
    // run's name, say), and the shard goes on.
    let recorded = std::fs::create_dir_all(&run.dir)
        .map_err(|e| DomaError::io(&run.dir, e))
        .and_then(|()| save_json(&failure, &run.dir.join(ERROR_FILE)));
    let error = match recorded {
        Ok(()) => error,
        Err(e) => format!("{error} (and the failure could not be recorded: {e})"),
    };
    Ok(Some(ItemOutcome::Failed { error }))
}

fn fit_new(
    run: &RunDir,
    spec: &RunSpec,
    search: &WeightSearch,
    interrupt: &AtomicBool,
    progress: bool,
) -> Result<FitOutcome> {
    let new = spec.prepare(search, |_| {})?;
    let device = new.config.backend.device()?;
    match fit_run(run, Some(new), &device, interrupt, None, progress) {
        // Another shard started it between our look and our lock: continue it.
        Err(DomaError::RunExists(_)) => resume(run, interrupt, progress),
        other => other,
    }
}

fn resume(run: &RunDir, interrupt: &AtomicBool, progress: bool) -> Result<FitOutcome> {
    let device = run.load_config()?.backend.device()?;
    fit_run(run, None, &device, interrupt, None, progress)
}

/// The status of an entry in `--collect`'s table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RunStatus {
    /// `report.json` is written.
    Done,
    /// The last attempt failed (`error.json`).
    Failed,
    /// Started, not finished: interrupted, killed, or running now.
    Unfinished,
    /// Not started.
    #[default]
    Pending,
}

/// One row of `--collect`'s table.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SummaryRow {
    /// The entry's name (its run folder).
    pub name: String,
    /// Where it stands.
    pub status: RunStatus,
    /// The model's paper name.
    pub model: Option<String>,
    /// The data file.
    pub data: Option<PathBuf>,
    /// EPE × 10⁴ on the held-out points (done runs).
    pub epe_x1e4: Option<f64>,
    /// Iterations done.
    pub iterations: Option<usize>,
    /// Seconds of fitting.
    pub seconds: Option<f64>,
    /// Frames of the fitted clip (done runs).
    pub frames: Option<usize>,
    /// Held-out points evaluated (done runs).
    pub points: Option<usize>,
    /// Trainable parameters (done runs).
    pub params: Option<usize>,
    /// `model.bpk` bytes (done runs).
    pub checkpoint_bytes: Option<u64>,
    /// Why it failed (failed runs).
    pub error: Option<String>,
}

/// The table of every entry of the batch in `out`, written to `out/summary.csv` and
/// `out/summary.json` (each atomically). The entries are those of the batch's manifest
/// copy; without one, the run folders found in `out`.
pub fn collect(out: &Path) -> Result<Vec<SummaryRow>> {
    if !out.is_dir() {
        return Err(DomaError::io(
            out,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such batch folder"),
        ));
    }
    let copy = out.join(MANIFEST_COPY);
    let names: Vec<String> = if copy.is_file() {
        let manifest: Manifest = load_json(&copy)?;
        let names: Vec<String> = manifest.items.into_iter().map(|i| i.name).collect();
        // Only folders inside the batch folder are read: a name is a plain folder name.
        for name in &names {
            manifest::check_name(name).map_err(|reason| DomaError::Malformed {
                path: copy.clone(),
                reason,
            })?;
        }
        names
    } else {
        let mut names = Vec::new();
        for entry in std::fs::read_dir(out).map_err(|e| DomaError::io(out, e))? {
            let path = entry.map_err(|e| DomaError::io(out, e))?.path();
            if path.join("config.json").is_file() || path.join(ERROR_FILE).is_file() {
                names.extend(path.file_name().map(|n| n.to_string_lossy().into_owned()));
            }
        }
        names.sort();
        names
    };
    let rows = names
        .into_iter()
        .map(|name| summary_row(&RunDir::new(out.join(&name)), name))
        .collect::<Result<Vec<_>>>()?;
    let json = serde_json::to_vec_pretty(&rows)
        .map_err(|e| DomaError::InvalidData(format!("cannot serialise the summary: {e}")))?;
    crate::io::write_atomic_all(&[
        (&out.join("summary.json"), &json),
        (&out.join("summary.csv"), to_csv(&rows).as_bytes()),
    ])?;
    Ok(rows)
}

fn summary_row(run: &RunDir, name: String) -> Result<SummaryRow> {
    let mut row = SummaryRow {
        name,
        ..SummaryRow::default()
    };
    if run.config().is_file() {
        let config = run.load_config()?;
        row.model = Some(config.fit.model.paper_name().to_string());
        row.data = Some(config.data);
        row.status = RunStatus::Unfinished;
        if run.history().is_file() {
            let history: Vec<IterationRecord> = load_json(&run.history())?;
            row.iterations = Some(history.len());
            row.seconds = history.last().map(|r| r.seconds);
        }
    }
    if run.report().is_file() {
        let r: Report = load_json(&run.report())?;
        row.status = RunStatus::Done;
        row.epe_x1e4 = Some(r.epe_x1e4);
        row.iterations = Some(r.iterations);
        row.seconds = Some(r.seconds);
        row.frames = Some(r.frames);
        row.points = Some(r.points);
        row.params = Some(r.params);
        row.checkpoint_bytes = Some(r.checkpoint_bytes);
    } else if run.dir.join(ERROR_FILE).is_file() {
        let f: Failure = load_json(&run.dir.join(ERROR_FILE))?;
        row.status = RunStatus::Failed;
        row.error = Some(f.error);
    }
    Ok(row)
}

/// The rows as CSV (RFC 4180: fields with a comma, a quote or a line break are quoted).
pub fn to_csv(rows: &[SummaryRow]) -> String {
    fn field(s: &str) -> String {
        if s.contains([',', '"', '\n', '\r']) {
            format!("\"{}\"", s.replace('"', "\"\""))
        } else {
            s.to_string()
        }
    }
    fn opt<T: ToString>(v: &Option<T>) -> String {
        v.as_ref().map_or(String::new(), T::to_string)
    }
    let mut out = String::from(
        "name,status,model,data,epe_x1e4,iterations,seconds,frames,points,params,checkpoint_bytes,error\n",
    );
    for r in rows {
        let status = serde_json::to_value(r.status)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default();
        let cells = [
            r.name.clone(),
            status,
            opt(&r.model),
            r.data
                .as_ref()
                .map_or(String::new(), |p| p.display().to_string()),
            opt(&r.epe_x1e4),
            opt(&r.iterations),
            opt(&r.seconds),
            opt(&r.frames),
            opt(&r.points),
            opt(&r.params),
            opt(&r.checkpoint_bytes),
            opt(&r.error),
        ];
        let line: Vec<String> = cells.iter().map(|c| field(c)).collect();
        out.push_str(&line.join(","));
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_quotes_what_needs_it() {
        let row = SummaryRow {
            name: "a".into(),
            status: RunStatus::Failed,
            data: Some("/d/x,y.traj".into()),
            epe_x1e4: Some(1.5),
            error: Some("bad \"file\"\nline".into()),
            ..SummaryRow::default()
        };
        let csv = to_csv(&[row]);
        let line = csv.lines().nth(1).unwrap();
        assert_eq!(
            line,
            "a,failed,,\"/d/x,y.traj\",1.5,,,,,,,\"bad \"\"file\"\""
        );
    }
}
