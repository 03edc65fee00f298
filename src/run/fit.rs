//! `doma fit`: a new or resumed fit into a run folder.

use std::sync::atomic::AtomicBool;

use burn::tensor::Device;

use super::{NewFit, Report, RunConfig, RunDir, RunLock, evaluate, gap_report};
use crate::checkpoint::Precision;
use crate::data::sequence::Sequence;
use crate::field::model::Model;
use crate::io::save_json;
use crate::io::write_atomic;
use crate::train::{Fitted, Hooks, Outcome, Progress, Trainer};
use crate::{DomaError, Result};

/// How a fit ended.
// Returned once per fit: boxing the report would cost every caller a deref for nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq)]
pub enum FitOutcome {
    /// All iterations ran; `model.bpk` and `report.json` are written.
    Finished(Report),
    /// Interrupted (e.g. Ctrl-C) after this many iterations; a checkpoint holds them.
    Interrupted {
        /// Iterations done and saved.
        iterations_done: usize,
    },
}

/// Fits `new` into `run` (a new or empty folder), or resumes the fit saved there when
/// `new` is `None`. A new fit's data is the sequence it carries (read once, by
/// [`NewFit::load`] or [`super::RunSpec::prepare`]); a resumed fit reads its data once. `interrupt` is polled after every iteration: when set, the fit saves
/// a checkpoint and returns [`FitOutcome::Interrupted`]. `stop_after` (for tests)
/// interrupts after that many iterations. `progress` (a bool, or [`Progress`]) shows it.
pub fn fit_run<'a>(
    run: &RunDir,
    new: Option<NewFit>,
    device: &Device,
    interrupt: &'a AtomicBool,
    stop_after: Option<usize>,
    progress: impl Into<Progress<'a>>,
) -> Result<FitOutcome> {
    fit_holding(
        run,
        new,
        None,
        device,
        interrupt,
        stop_after,
        progress.into(),
    )
}

/// [`fit_run`] of a new fit into a folder whose lock the caller took first
/// ([`RunLock::acquire`]), so that nothing it wrote there before the fit (its data, as the
/// Python package writes it) could be replaced or read by another writer meanwhile.
pub fn fit_run_locked<'a>(
    run: &RunDir,
    new: NewFit,
    lock: RunLock,
    device: &Device,
    interrupt: &'a AtomicBool,
    stop_after: Option<usize>,
    progress: impl Into<Progress<'a>>,
) -> Result<FitOutcome> {
    fit_holding(
        run,
        Some(new),
        Some(lock),
        device,
        interrupt,
        stop_after,
        progress.into(),
    )
}

/// The run's own fit, then the others of a run that combines several
/// ([`RunConfig::fits`]), each into its folder ([`RunDir::member`]), in turn: a resumed run
/// goes on with the first unfinished one.
fn fit_holding<'a>(
    run: &RunDir,
    new: Option<NewFit>,
    held: Option<RunLock>,
    device: &Device,
    interrupt: &'a AtomicBool,
    stop_after: Option<usize>,
    mut progress: Progress<'a>,
) -> Result<FitOutcome> {
    let mut one = |dir: &RunDir, new: Option<NewFit>, held: Option<RunLock>| {
        fit_one(
            dir,
            new,
            held,
            device,
            interrupt,
            stop_after,
            progress.by_ref(),
        )
    };
    let resumed = match &new {
        Some(_) => None,
        None => Some(run.load_config()?),
    };
    // A resumed run whose own fit is done goes on with the others, under its lock.
    let (report, _lock, config) = match resumed {
        Some(config) if config.fits > 1 && run.model().is_file() => (
            crate::io::load_json::<Report>(&run.report())?,
            Some(RunLock::acquire(&run.dir)?),
            config,
        ),
        _ => match one(run, new, held)? {
            // The config as the run's own fit saved it.
            (FitOutcome::Finished(report), lock) => (report, lock, run.load_config()?),
            (interrupted, _) => return Ok(interrupted),
        },
    };
    for k in 2..=config.fits {
        let member = run.member(k);
        if member.model().is_file() {
            continue;
        }
        let new = if member.config().is_file() {
            None
        } else {
            std::fs::create_dir_all(run.dir.join("fits"))
                .map_err(|e| DomaError::io(run.dir.join("fits"), e))?;
            Some(NewFit::load(config.member(k))?)
        };
        let (outcome, _) = one(&member, new, None)?;
        if let FitOutcome::Interrupted { .. } = outcome {
            return Ok(outcome);
        }
    }
    Ok(FitOutcome::Finished(report))
}

/// One fit into `run`: new (`new`), or resumed from its checkpoint; with the lock that it
/// held, to hold while the run's other fits go on.
fn fit_one<'a>(
    run: &RunDir,
    new: Option<NewFit>,
    held: Option<RunLock>,
    device: &Device,
    interrupt: &'a AtomicBool,
    stop_after: Option<usize>,
    progress: Progress<'a>,
) -> Result<(FitOutcome, Option<RunLock>)> {
    let resume = new.is_none();
    let (NewFit { config, sequence }, resumed) = match new {
        Some(NewFit { config, sequence }) => (
            NewFit {
                config: config.recording(&sequence),
                sequence,
            },
            None,
        ),
        None => {
            let config = run.load_config()?;
            let lock = RunLock::acquire(&run.dir)?;
            (NewFit::load(config)?, Some(lock))
        }
    };
    let (train, _) = config.split(&sequence.trajectories)?;
    let ad = device.clone().autodiff();
    let fit = &config.fit;
    let field = fit.model.init(fit.seed, train.canonical(), &ad);
    let mut trainer =
        Trainer::new(field, fit, &train, device)?.progress(matches!(progress, Progress::Shown));
    // A new fit's folder is made only now, once the trainer took the data: a refusal
    // until here leaves nothing behind.
    let lock = match resumed {
        Some(lock) => lock,
        None => start(run, &config, held)?,
    };
    if resume && run.resume().is_file() {
        let snapshot = run.read_resume()?;
        trainer
            .restore(&snapshot)
            .map_err(|e| DomaError::Malformed {
                path: run.resume(),
                reason: e.to_string(),
            })?;
    }
    let mut hooks = Hooks::new()
        .checkpoint(config.checkpoint_every, |snapshot| {
            run.write_resume(snapshot)?;
            save_json(&snapshot.history, &run.history())
        })
        .interrupt(interrupt);
    if let Some(n) = stop_after {
        hooks = hooks.stop_after(n);
    }
    if let Progress::Each(each) = progress {
        hooks = hooks.each(each);
    }
    let outcome = match trainer.run_with(hooks)? {
        Outcome::Finished(fitted) => {
            drop(train);
            FitOutcome::Finished(finish(run, &config, sequence, &fitted, device)?)
        }
        Outcome::Interrupted { iterations_done } => FitOutcome::Interrupted { iterations_done },
    };
    Ok((outcome, Some(lock)))
}

/// Claims the run folder of a new fit ([`super::Claim`]: made, locked, refused if it holds
/// a run) unless its lock is `held`, and writes its config. The data were read and checked
/// before ([`NewFit`]), so that bad data leaves nothing behind.
fn start(run: &RunDir, config: &RunConfig, held: Option<RunLock>) -> Result<RunLock> {
    // The lock first: a folder being fitted is refused naming the process that fits it,
    // rather than as a run to resume (which that process would refuse too).
    let lock = match held {
        Some(lock) => lock,
        None => {
            let (claim, lock) = super::Claim::take(&run.dir)?;
            claim.keep();
            lock
        }
    };
    if run.config().exists() {
        return Err(DomaError::RunExists(run.dir.clone()));
    }
    save_json(config, &run.config())?;
    Ok(lock)
}

/// Writes `model.bpk`, `canonical.npy` when the fit learned canonical positions, and
/// `report.json` (the EPE on the held-out points).
fn finish(
    run: &RunDir,
    config: &RunConfig,
    sequence: Sequence,
    fitted: &Fitted<Model>,
    device: &Device,
) -> Result<Report> {
    let encoded = fitted.field.encode(Precision::F32)?;
    // The learned canonical positions of the training tracks go into every track's.
    let learned = match &fitted.canonical {
        Some(learned) => {
            let (train, _) = config.split_indices(sequence.trajectories.points())?;
            let mut all = sequence.trajectories.canonical().to_vec();
            for (r, &i) in train.iter().enumerate() {
                all[3 * i..3 * i + 3].copy_from_slice(&learned[3 * r..3 * r + 3]);
            }
            crate::data::npy::write_npy(run.canonical(), &[all.len() / 3, 3], &all)?;
            Some(all)
        }
        None => None,
    };
    // The gap report fills the held-out entries from the data's own canonical positions
    // (`placed`) and measures the field at the learned ones: only it needs both, and so a
    // second copy of the trajectories.
    let (placed, sequence) = match learned {
        Some(all) if sequence.held_out.is_some() => {
            // Field by field: `..sequence.clone()` would copy the trajectories twice.
            let with = Sequence {
                name: sequence.name.clone(),
                trajectories: sequence.trajectories.clone().with_canonical(all)?,
                faces: sequence.faces.clone(),
                center: sequence.center,
                scale: sequence.scale,
                held_out: sequence.held_out.clone(),
                blind: sequence.blind.clone(),
                kept: sequence.kept.clone(),
                model_outputs_left_out: sequence.model_outputs_left_out,
                notes: sequence.notes.clone(),
                units: sequence.units.clone(),
            };
            (Some(sequence), with)
        }
        Some(all) => {
            let mut sequence = sequence;
            sequence.trajectories = sequence.trajectories.with_canonical(all)?;
            (None, sequence)
        }
        None => (None, sequence),
    };
    let placed = placed.as_ref().unwrap_or(&sequence);
    let sequence = &sequence;
    let (test, what) = config.measured(&sequence.trajectories)?;
    write_atomic(&run.model(), &encoded)?;
    let report = Report {
        checkpoint_bytes: encoded.len() as u64,
        iterations: fitted.history.len(),
        seconds: fitted.seconds,
        held_out_observations: gap_report(&fitted.field, config, placed, sequence, device)?,
        ..evaluate(&fitted.field, &test, what, device)?
    }
    .in_units(sequence.units.clone(), sequence.scale);
    save_json(&report, &run.report())?;
    Ok(report)
}
