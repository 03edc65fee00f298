//! Time to accuracy: the held-out EPE of a fit against its wall time, for the paper's
//! protocol and faster recipes, in one run. A fast step is not the point; a good fit soon
//! is. The evaluations that draw the curve are timed and subtracted, so a curve's seconds
//! are the fit's own.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::Result;
use crate::backend::BackendKind;
use crate::data::Trajectories;
use crate::data::synthetic::Motion;
use crate::experiments::synthetic::Regularizer;
use crate::field::Variant;
use crate::metrics::{EPE_SCALE, evaluate_epe};
use crate::train::{FitConfig, Hooks, Outcome, Trainer};

/// A contender: a name and the fit config it runs.
#[derive(Clone, Debug)]
pub struct Contender {
    /// Its name in the table (`paper`, `fast`, or a recipe file's stem).
    pub name: String,
    /// What it fits.
    pub config: FitConfig,
}

/// One problem: training tracks to fit and held-out tracks to score.
pub struct Problem {
    /// Its name (a synthetic motion, or a sequence).
    pub name: String,
    /// The synthetic motion, when it is one (for the authors' figures).
    pub motion: Option<Motion>,
    /// The fitted tracks.
    pub train: Trajectories,
    /// The held-out tracks of the EPE.
    pub test: Trajectories,
}

/// What to run.
pub struct TimeJob {
    /// The problems, each fitted by every contender.
    pub problems: Vec<Problem>,
    /// The contenders; the first is the reference of the speed-ups (the paper's protocol).
    pub contenders: Vec<Contender>,
    /// Points per curve (an evaluation every `iterations / curve_points` iterations).
    pub curve_points: usize,
    /// The backend.
    pub backend: BackendKind,
    /// No progress bars.
    pub quiet: bool,
}

/// A point of a curve.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct CurvePoint {
    /// Iterations done.
    pub iteration: usize,
    /// Seconds of fitting so far, the curve's evaluations excluded.
    pub seconds: f64,
    /// The held-out EPE × 10⁴.
    pub epe_x1e4: f64,
}

/// One fit's curve.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Curve {
    /// The problem.
    pub problem: String,
    /// The contender.
    pub contender: String,
    /// The config it ran (what `config.json` would hold).
    pub config: FitConfig,
    /// The curve.
    pub points: Vec<CurvePoint>,
    /// The final held-out EPE × 10⁴.
    pub final_epe_x1e4: f64,
    /// Seconds of fitting, the curve's evaluations excluded.
    pub fit_seconds: f64,
    /// Seconds spent evaluating the curve (not in `fit_seconds`).
    pub eval_seconds: f64,
    /// Iterations run (fewer than the budget when the fit stopped on convergence).
    pub iterations: usize,
}

impl Curve {
    /// The fit seconds at which the EPE first reached `target` (× 10⁴) at the curve's
    /// resolution, or `None`.
    pub fn time_to(&self, target: f64) -> Option<f64> {
        self.points
            .iter()
            .find(|p| p.epe_x1e4 <= target)
            .map(|p| p.seconds)
    }
}

/// How much sooner a contender reached a target than the reference.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(rename_all = "kebab-case")]
pub enum Speedup {
    /// Both reached it: the reference's time over the contender's.
    Ratio(f64),
    /// Only the contender reached it: at least the reference's whole fit over the
    /// contender's time.
    AtLeast(f64),
    /// The contender did not reach it.
    NotReached,
}

impl std::fmt::Display for Speedup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Speedup::Ratio(r) => write!(f, "{r:.1}×"),
            Speedup::AtLeast(r) => write!(f, "> {r:.1}×"),
            Speedup::NotReached => write!(f, "not reached"),
        }
    }
}

/// A target EPE of a problem and who reached it when.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Target {
    /// The problem.
    pub problem: String,
    /// What the target is (`authors`, `authors +10 %`, `paper final`, `paper final +10 %`).
    pub name: String,
    /// The EPE × 10⁴.
    pub epe_x1e4: f64,
    /// Per contender: the fit seconds to reach it, and the speed-up over the reference.
    pub reached: Vec<(String, Option<f64>, Speedup)>,
}

/// Everything a run measured.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TimeRecord {
    /// The curves, problem by problem, contender by contender.
    pub curves: Vec<Curve>,
    /// The targets and their times.
    pub targets: Vec<Target>,
}

impl TimeRecord {
    /// The problems, in the order they were fitted.
    pub fn problems(&self) -> Vec<&str> {
        let mut problems: Vec<&str> = Vec::new();
        for c in &self.curves {
            if !problems.contains(&c.problem.as_str()) {
                problems.push(&c.problem);
            }
        }
        problems
    }
}

/// The final EPE (× 10⁴) of the authors' code on the synthetic benchmark's points (seed
/// 0), for the variants measured there (docs/results.md).
pub fn authors_epe(variant: Variant, reg: Regularizer, motion: Motion) -> Option<f64> {
    let row = match (variant, reg) {
        (Variant::Affinity, Regularizer::H) => [10.52, 3.34, 3.92, 77.46],
        (Variant::Affinity, Regularizer::None) => [1099.0, 84.0, 161.0, 2302.0],
        (Variant::Trans, Regularizer::None) => [2068.0, 220.0, 640.0, 2368.0],
        _ => return None,
    };
    let i = Motion::ALL.iter().position(|m| *m == motion)?;
    Some(row[i])
}

/// Fits every problem with every contender, in turn, calling `on_curve` after each fit.
/// `authors` gives a problem's authors' EPE, when known.
pub fn run(
    job: &TimeJob,
    authors: impl Fn(&Problem) -> Option<f64>,
    mut on_curve: impl FnMut(&Curve),
) -> Result<TimeRecord> {
    let device = job.backend.device()?;
    let mut curves = Vec::new();
    let mut targets = Vec::new();
    for problem in &job.problems {
        let first = curves.len();
        for contender in &job.contenders {
            let curve = fit_curve(problem, contender, job, &device)?;
            on_curve(&curve);
            curves.push(curve);
        }
        targets.extend(problem_targets(
            &problem.name,
            &curves[first..],
            authors(problem),
        ));
    }
    Ok(TimeRecord { curves, targets })
}

/// One fit, its held-out EPE measured every `iterations / curve_points` iterations.
fn fit_curve(
    problem: &Problem,
    contender: &Contender,
    job: &TimeJob,
    device: &burn::tensor::Device,
) -> Result<Curve> {
    let config = &contender.config;
    let every = (config.schedule.iterations / job.curve_points.max(1)).max(1);
    let mut points = Vec::new();
    let mut eval_seconds = 0.0;
    let trainer = Trainer::from_config(config, &problem.train, device)?.progress(!job.quiet);
    let hooks = Hooks::new().observe(every, |record, field| {
        // The record's clock ran through the earlier evaluations: take them out.
        let seconds = record.seconds - eval_seconds;
        let started = Instant::now();
        let epe = evaluate_epe(&field, &problem.test, device)? * EPE_SCALE;
        eval_seconds += started.elapsed().as_secs_f64();
        points.push(CurvePoint {
            iteration: record.iteration + 1,
            seconds,
            epe_x1e4: epe,
        });
        Ok(())
    });
    let Outcome::Finished(fitted) = trainer.run_with(hooks)? else {
        unreachable!("no interrupt was set");
    };
    let last = points
        .last()
        .cloned()
        .expect("the last iteration is observed");
    Ok(Curve {
        problem: problem.name.clone(),
        contender: contender.name.clone(),
        config: config.clone(),
        final_epe_x1e4: last.epe_x1e4,
        fit_seconds: last.seconds,
        eval_seconds,
        iterations: fitted.history.len(),
        points,
    })
}

/// The targets of one problem (its curves, the reference first): the authors' EPE and the
/// reference's final EPE, each as it is and 10 % above.
fn problem_targets(problem: &str, curves: &[Curve], authors: Option<f64>) -> Vec<Target> {
    let Some(reference) = curves.first() else {
        return Vec::new();
    };
    let mut wanted = Vec::new();
    if let Some(a) = authors {
        wanted.push(("authors".to_string(), a));
        wanted.push(("authors +10 %".to_string(), 1.1 * a));
    }
    let own = reference.final_epe_x1e4;
    wanted.push((format!("{} final", reference.contender), own));
    wanted.push((format!("{} final +10 %", reference.contender), 1.1 * own));
    wanted
        .into_iter()
        .map(|(name, epe)| {
            let base = reference.time_to(epe);
            let reached = curves
                .iter()
                .map(|c| {
                    let t = c.time_to(epe);
                    let speedup = match (base, t) {
                        (_, None) => Speedup::NotReached,
                        (Some(b), Some(t)) => Speedup::Ratio(b / t.max(1e-9)),
                        (None, Some(t)) => Speedup::AtLeast(reference.fit_seconds / t.max(1e-9)),
                    };
                    (c.contender.clone(), t, speedup)
                })
                .collect();
            Target {
                problem: problem.to_string(),
                name,
                epe_x1e4: epe,
                reached,
            }
        })
        .collect()
}

/// The table: per problem, each contender's final EPE, fit seconds and iterations, then
/// each target with every contender's time and speed-up over the reference.
pub fn table(record: &TimeRecord) -> String {
    let mut out = String::new();
    for p in record.problems() {
        out += &format!("\n{p}\n");
        out += &format!(
            "  {:<16} {:>12} {:>10} {:>6}\n",
            "contender", "final EPE", "fit s", "iters"
        );
        for c in record.curves.iter().filter(|c| c.problem == p) {
            out += &format!(
                "  {:<16} {:>12.2} {:>10.1} {:>6}\n",
                c.contender, c.final_epe_x1e4, c.fit_seconds, c.iterations
            );
        }
        for t in record.targets.iter().filter(|t| t.problem == p) {
            out += &format!("  to {} ({:.2}):", t.name, t.epe_x1e4);
            for (name, seconds, speedup) in &t.reached {
                let at = seconds.map_or("-".to_string(), |s| format!("{s:.1} s"));
                out += &format!("  {name} {at} ({speedup})");
            }
            out += "\n";
        }
    }
    out
}

/// One figure per problem: held-out EPE against fit seconds, log–log, a curve per
/// contender and a flat line at the authors' EPE where known.
pub fn plots(
    record: &TimeRecord,
    authors: impl Fn(&str) -> Option<f64>,
) -> Vec<(String, crate::plot::Figure)> {
    use crate::plot::{Series, line_plot};
    const COLOURS: [[u8; 3]; 6] = [
        [31, 119, 180],
        [214, 39, 40],
        [44, 160, 44],
        [148, 103, 189],
        [255, 127, 14],
        [23, 190, 207],
    ];
    record
        .problems()
        .into_iter()
        .map(|p| {
            let curves: Vec<&Curve> = record.curves.iter().filter(|c| c.problem == p).collect();
            let mut series: Vec<Series> = curves
                .iter()
                .enumerate()
                .map(|(i, c)| Series {
                    name: &c.contender,
                    color: COLOURS[i % COLOURS.len()],
                    points: c.points.iter().map(|q| (q.seconds, q.epe_x1e4)).collect(),
                })
                .collect();
            if let Some(a) = authors(p) {
                let end = curves.iter().map(|c| c.fit_seconds).fold(0.0, f64::max);
                let start = curves
                    .iter()
                    .filter_map(|c| c.points.first().map(|q| q.seconds))
                    .fold(f64::INFINITY, f64::min);
                series.push(Series {
                    name: "authors' final EPE",
                    color: [120, 120, 120],
                    points: vec![(start, a), (end, a)],
                });
            }
            let figure = line_plot(
                &format!("Held-out EPE against fit time: {p}"),
                "fit seconds (evaluation excluded)",
                "EPE ×1e-4",
                &series,
                true,
            )
            .log_x();
            (format!("time_to_accuracy_{}", file_stem(p)), figure)
        })
        .collect()
}

/// A problem's name as a file-name part: letters, digits, `-` and `_` kept, the rest `_`.
fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}
