//! `doma fill`: the gaps of a folder of recordings filled in one command, each written
//! back in its own format (or the one `--format` or the output's extension names), with
//! a line per recording in the lab's terms, a table of its filled gaps beside it, and a
//! summary.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use crate::cli::DeviceArgs;
use crate::run::{
    Completion, FillPolicy, RecordingFill, fill_recording, filled_by, names_and_rate,
    output_kind_for, write_gap_report,
};
use crate::{DomaError, Result};

/// The flags of `doma fill`.
#[derive(clap::Parser, Debug, Clone)]
#[command(
    about = "Fill the gaps of recordings (files or folders of .c3d and .trc) in one go, each written back in its own format"
)]
pub struct FillArgs {
    /// The recordings: files (.c3d, .trc, or any format doma fit reads), folders (their
    /// .c3d and .trc files) or a pattern of file names (`trials/*.c3d`).
    #[arg(required = true, value_name = "INPUT")]
    pub inputs: Vec<PathBuf>,
    /// A folder for the filled recordings (each under its input's name), or, for one
    /// input, the file to write (.c3d, .trc or .npz by its extension).
    #[arg(long)]
    pub out: PathBuf,
    /// The format of the files written into a folder: each input's own by default (a
    /// .c3d stays .c3d, a .trc .trc, any other .npz).
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// Fit a field to each recording first and fill with doma's fill, the validated blend of
    /// every filler the field's included (15–30 s a recording). Without it, the fill needs no
    /// fit: rigid clusters first, then the chain fill (or `--method`), a fraction of a second
    /// a recording; on the native-rate protocol a fit took gaps of 1 s and longer only a few
    /// per cent lower (docs/gap-filling.md).
    #[arg(long, conflicts_with = "no_fit")]
    pub fit: bool,
    /// Fill without a fit (the default; kept for scripts written when a fit was).
    #[arg(long)]
    pub no_fit: bool,
    /// Which gaps are filled, and by what.
    #[command(flatten)]
    pub fill: crate::cli::FillPolicyArgs,
    /// The fit's iterations (default: `doma fit`'s for tracks with gaps).
    #[arg(long = "iters", value_name = "N", value_parser = clap::value_parser!(u64).range(1..), requires = "fit")]
    pub iterations: Option<u64>,
    /// Recordings filled at once.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub jobs: u64,
    /// Flag the gaps whose expected error passes this many millimetres (in the table and
    /// the line of each recording).
    #[arg(long, value_name = "MM", default_value_t = 5.0, value_parser = positive_mm)]
    pub flag_above: f64,
    /// Write over an output that exists (by default it is skipped, with a line saying so).
    #[arg(long)]
    pub overwrite: bool,
    /// Keep each fit's run folder under this folder (one per recording, by its name)
    /// instead of removing it (`--overwrite` replaces a run kept before).
    #[arg(long, value_name = "DIR", requires = "fit")]
    pub keep_runs: Option<PathBuf>,
    /// Fill shard I of N of the recordings (in name order: I, I+N, I+2N, …), for an array
    /// of jobs on Slurm or Kubernetes (default: the scheduler's, as `doma batch`'s).
    #[arg(long, value_parser = crate::batch::Shard::parse, value_name = "I/N")]
    pub shard: Option<crate::batch::Shard>,
    /// Print errors only.
    #[arg(long)]
    pub quiet: bool,
    /// The device.
    #[command(flatten)]
    pub device: DeviceArgs,
}

fn positive_mm(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a positive length in mm")),
    }
}

/// The format of the files `doma fill` writes into a folder.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// C3D: the input file with its gaps written (from a .c3d input).
    C3d,
    /// OpenSim's TRC.
    Trc,
    /// NumPy's .npz: the tracks and their mask.
    Npz,
}

/// One recording to fill: where it is read and where it is written.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// The recording.
    pub input: PathBuf,
    /// The file written.
    pub output: PathBuf,
}

/// The recordings of `inputs` (a folder's `.c3d` and `.trc` files, sorted by name) and the
/// file each is written to: `out` itself for one input file whose `out` names a format,
/// else `out/NAME` with the extension `format` (or the input's own) gives.
pub fn jobs(inputs: &[PathBuf], out: &Path, format: Option<Format>) -> Result<Vec<Job>> {
    let mut files = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(input)
                .map_err(|e| DomaError::io(input, e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && matches!(ext(p).as_str(), "c3d" | "trc"))
                .collect();
            if found.is_empty() {
                return Err(DomaError::Usage(format!(
                    "{}: a folder without .c3d or .trc files",
                    input.display()
                )));
            }
            found.sort();
            files.extend(found);
        } else if input.exists() {
            files.push(input.clone());
        } else if let Some(found) = glob(input)? {
            files.extend(found);
        } else {
            return Err(DomaError::io(
                input,
                std::io::Error::from(std::io::ErrorKind::NotFound),
            ));
        }
    }
    let one_file = files.len() == 1 && inputs.len() == 1 && !inputs[0].is_dir();
    // One input and an `--out` with an extension names the file to write (refused later
    // unless the extension is a format's).
    if one_file && out.extension().is_some() && !out.is_dir() {
        if format.is_some() {
            return Err(DomaError::Usage(
                "--format names the files written into a folder; --out names this one's".into(),
            ));
        }
        return Ok(vec![Job {
            input: files.remove(0),
            output: out.to_path_buf(),
        }]);
    }
    let mut seen = std::collections::HashSet::new();
    let mut jobs = Vec::with_capacity(files.len());
    for input in files {
        let own = match ext(&input).as_str() {
            "c3d" => "c3d",
            "trc" => "trc",
            _ => "npz",
        };
        let extension = match format {
            Some(Format::C3d) => "c3d",
            Some(Format::Trc) => "trc",
            Some(Format::Npz) => "npz",
            None => own,
        };
        let stem = input.file_stem().unwrap_or_default();
        let output = out.join(stem).with_extension(extension);
        if !seen.insert(output.clone()) {
            return Err(DomaError::Usage(format!(
                "two inputs would be written to {}: give them apart",
                output.display()
            )));
        }
        jobs.push(Job { input, output });
    }
    Ok(jobs)
}

/// The files that `pattern`'s last component matches in its folder (`*` any run of
/// characters, `?` one), sorted; `None` where it has no wildcard. A pattern matching
/// nothing is refused, naming it.
fn glob(pattern: &Path) -> Result<Option<Vec<PathBuf>>> {
    let Some(name) = pattern.file_name().and_then(|n| n.to_str()) else {
        return Ok(None);
    };
    if !name.contains(['*', '?']) {
        return Ok(None);
    }
    let dir = match pattern.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut found: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map_err(|e| DomaError::io(&dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| matches(name, n))
        })
        .collect();
    if found.is_empty() {
        return Err(DomaError::Usage(format!(
            "{}: no file matches",
            pattern.display()
        )));
    }
    found.sort();
    Ok(Some(found))
}

/// Whether `name` matches `pattern` (`*` any run of characters, `?` one).
fn matches(pattern: &str, name: &str) -> bool {
    let (p, n): (Vec<char>, Vec<char>) = (pattern.chars().collect(), name.chars().collect());
    // The classic two-pointer match with the last star's place to fall back to.
    let (mut i, mut j, mut star, mut from) = (0, 0, None, 0);
    while j < n.len() {
        if i < p.len() && (p[i] == '?' || p[i] == n[j]) {
            i += 1;
            j += 1;
        } else if i < p.len() && p[i] == '*' {
            star = Some(i);
            from = j;
            i += 1;
        } else if let Some(s) = star {
            i = s + 1;
            from += 1;
            j = from;
        } else {
            return false;
        }
    }
    p[i..].iter().all(|&c| c == '*')
}

pub(crate) fn ext(path: &Path) -> String {
    path.extension()
        .map_or(String::new(), |e| e.to_string_lossy().to_ascii_lowercase())
}

/// What happened to one recording.
enum Outcome {
    /// The completion, the seconds it took, the gaps flagged, and the largest expected
    /// error with its units.
    Filled(Box<Completion>, f64, usize, Option<(f64, String)>),
    Skipped,
    Failed(DomaError),
}

/// Fills every recording; an error in one is reported and the others still run, and the
/// command then fails naming how many.
pub fn run(args: &FillArgs) -> Result<()> {
    let mut jobs = jobs(&args.inputs, &args.out, args.format)?;
    let shard = match args.shard {
        Some(s) => s,
        None => crate::batch::Shard::from_env(|k| std::env::var(k).ok(), None)?
            .unwrap_or(crate::batch::Shard::ALL),
    };
    if shard.count > 1 {
        jobs = jobs
            .into_iter()
            .enumerate()
            .filter(|(k, _)| k % shard.count == shard.index)
            .map(|(_, j)| j)
            .collect();
    }
    // Every output's format checked before anything is written.
    for job in &jobs {
        output_kind_for(&job.input, &job.output)?;
    }
    if jobs.first().is_none_or(|j| j.output != args.out) {
        std::fs::create_dir_all(&args.out).map_err(|e| DomaError::io(&args.out, e))?;
    }
    if let Some(dir) = &args.keep_runs {
        std::fs::create_dir_all(dir).map_err(|e| DomaError::io(dir, e))?;
    }
    let device = args.device.backend.device()?;
    let interrupt = crate::cli::interrupt::install();
    let policy = args.fill.policy();
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::new(jobs.len() as u64);
        bar.set_style(
            ProgressStyle::with_template("{bar:30} {pos}/{len} recordings, {elapsed} (ETA {eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar
    };
    let next = AtomicUsize::new(0);
    let outcomes: Mutex<Vec<Option<Outcome>>> = Mutex::new((0..jobs.len()).map(|_| None).collect());
    let started = Instant::now();
    let workers = (args.jobs as usize).min(jobs.len()).max(1);
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(job) = jobs.get(k) else { break };
                    let outcome = fill_one(job, args, policy, &device, interrupt);
                    let line = describe(job, &outcome, args.fill.max_gap.is_some());
                    // Through the bar, which prints nothing itself where stderr is no
                    // terminal.
                    if !args.quiet || matches!(outcome, Outcome::Failed(_)) {
                        bar.suspend(|| eprintln!("{line}"));
                    }
                    bar.inc(1);
                    if let Ok(mut all) = outcomes.lock() {
                        all[k] = Some(outcome);
                    }
                }
            });
        }
    });
    bar.finish_and_clear();
    let outcomes = outcomes.into_inner().unwrap_or_default();
    let (mut filled, mut skipped, mut failed, mut gaps) = (0, 0, 0, 0);
    for outcome in outcomes.iter().flatten() {
        match outcome {
            Outcome::Filled(c, _, _, _) => {
                filled += 1;
                gaps += c.gaps.len();
            }
            Outcome::Skipped => skipped += 1,
            Outcome::Failed(_) => failed += 1,
        }
    }
    if !args.quiet {
        eprintln!(
            "{filled} recordings filled ({gaps} gaps), {skipped} skipped, {failed} failed, in \
             {:.1} s",
            started.elapsed().as_secs_f64()
        );
    }
    if failed > 0 {
        return Err(DomaError::Usage(format!(
            "{failed} of {} recordings failed (each said why above)",
            jobs.len()
        )));
    }
    Ok(())
}

/// Fills one recording, or skips it where its output exists and `--overwrite` is not set.
fn fill_one(
    job: &Job,
    args: &FillArgs,
    policy: FillPolicy,
    device: &burn::tensor::Device,
    interrupt: &std::sync::atomic::AtomicBool,
) -> Outcome {
    if job.output.exists() && !args.overwrite {
        return Outcome::Skipped;
    }
    let started = Instant::now();
    let how = RecordingFill {
        fit: args.fit,
        policy,
        spec: crate::run::RunSpec {
            iterations: args.iterations.map(|i| i as usize),
            ..Default::default()
        },
        keep_run: args
            .keep_runs
            .as_ref()
            .map(|dir| dir.join(job.input.file_stem().unwrap_or_default())),
    };
    // A run kept by an earlier fill of this recording is replaced where the output is.
    if let Some(run) = how
        .keep_run
        .as_ref()
        .filter(|r| args.overwrite && r.join("config.json").is_file())
        && let Err(e) = std::fs::remove_dir_all(run)
    {
        return Outcome::Failed(DomaError::io(run, e));
    }
    let done = fill_recording(&job.input, &job.output, &how, device, interrupt).and_then(|c| {
        let table = write_gap_report(&job.input, &job.output, &c, args.flag_above)?;
        let flagged = table.rows.iter().filter(|r| r.flagged).count();
        let worst = table
            .rows
            .iter()
            .filter_map(|r| r.expected_error)
            .max_by(f64::total_cmp)
            .map(|e| (e, table.units.clone().unwrap_or_default()));
        Ok((c, flagged, worst))
    });
    match done {
        Ok((c, flagged, worst)) => {
            Outcome::Filled(Box::new(c), started.elapsed().as_secs_f64(), flagged, worst)
        }
        Err(e) => Outcome::Failed(e),
    }
}

/// The line printed for one recording.
fn describe(job: &Job, outcome: &Outcome, max_gap: bool) -> String {
    let name = job.input.display();
    match outcome {
        Outcome::Skipped => format!(
            "{name}: skipped, {} exists (--overwrite writes over it)",
            job.output.display()
        ),
        Outcome::Failed(e) => format!("{name}: failed: {e}"),
        Outcome::Filled(c, seconds, flagged, worst) => {
            let longest = c
                .gaps
                .iter()
                .map(|g| g.frames[1] - g.frames[0] + 1)
                .max()
                .unwrap_or(0);
            let rate = names_and_rate(&job.input).ok().and_then(|(_, r)| r);
            let longest = match rate {
                Some(r) => format!("{:.2} s", longest as f64 / r),
                None => format!("{longest} frames"),
            };
            let mut line = format!(
                "{name}: {} markers, {} gaps filled (longest {longest}, by {})",
                c.tracks,
                c.gaps.len(),
                filled_by(c)
            );
            if let Some((e, units)) = worst {
                line.push_str(&format!(", expected error up to {e:.1} {units}"));
            }
            if *flagged > 0 {
                line.push_str(&format!(", {flagged} flagged (over --flag-above)"));
            }
            if max_gap || c.left_long > 0 {
                line.push_str(&format!(
                    ", {} gaps longer than --max-gap left",
                    c.left_long
                ));
            }
            if c.unfilled > 0 && !max_gap {
                line.push_str(&format!(
                    ", {} entries left (past a marker's ends, or of a marker never seen)",
                    c.unfilled
                ));
            }
            line.push_str(&format!(" -> {} ({seconds:.1} s)", job.output.display()));
            line
        }
    }
}

#[cfg(test)]
mod tests {
    use super::matches;

    #[test]
    fn patterns_match_as_a_shell_does() {
        assert!(matches("*.c3d", "trial01.c3d"));
        assert!(matches("trial??.c3d", "trial01.c3d"));
        assert!(matches("*", "x"));
        assert!(matches("a*b*c", "aXXbYYc"));
        assert!(!matches("*.c3d", "trial01.trc"));
        assert!(!matches("trial?.c3d", "trial01.c3d"));
        assert!(!matches("a*b*c", "aXXbYY"));
    }
}
