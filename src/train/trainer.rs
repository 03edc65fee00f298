//! The fit loop, once: frame order, learning-rate schedule, Adam, progress, the NaN
//! guard, checkpoints, resume, interrupts and observation for learning curves. Every fit
//! in doma (the experiments, `doma fit`, the guided registration) runs through it.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor};
use indicatif::{ProgressBar, ProgressStyle};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::config::{FitConfig, ScheduleConfig};
use super::objective::{Objective, TrajectoryObjective};
use crate::data::Trajectories;
use crate::field::MotionField;
use crate::field::model::Model;
use crate::{DomaError, Result};

/// The record of one iteration.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct IterationRecord {
    /// 0-based iteration.
    pub iteration: usize,
    /// The learning rate used.
    pub learning_rate: f64,
    /// The primary loss (the trajectory L1; the guidance L1 of a registration), averaged
    /// over the iteration's steps.
    pub trajectory_loss: f64,
    /// The whole step loss, averaged over the iteration's steps.
    pub total_loss: f64,
    /// Seconds since the fit started (over all resumed parts).
    pub seconds: f64,
}

/// A fitted field and how the fit went.
#[derive(Debug)]
pub struct Fitted<M> {
    /// The field, moved off the autodiff graph (ready for evaluation).
    pub field: M,
    /// One record per iteration.
    pub history: Vec<IterationRecord>,
    /// Wall time of the loop, seconds (over all resumed parts).
    pub seconds: f64,
    /// Optimiser steps taken (`iterations × T`).
    pub steps: usize,
}

/// How [`Trainer::run_with`] ended.
#[derive(Debug)]
pub enum Outcome<M> {
    /// Every iteration ran.
    Finished(Fitted<M>),
    /// Interrupted after this many iterations (a checkpoint was offered at that point).
    Interrupted {
        /// Iterations done.
        iterations_done: usize,
    },
}

/// A standard normal draw (Box–Muller), so that the samples are the same on every
/// backend for a given seed.
pub fn gaussian(rng: &mut impl Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// The position of a ChaCha8 stream, to resume it exactly.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RngState {
    /// The 32-byte key.
    pub seed: [u8; 32],
    /// The stream number.
    pub stream: u64,
    /// The word position.
    pub word_pos: u128,
}

impl RngState {
    fn of(rng: &ChaCha8Rng) -> Self {
        RngState {
            seed: rng.get_seed(),
            stream: rng.get_stream(),
            word_pos: rng.get_word_pos(),
        }
    }

    fn restore(&self) -> ChaCha8Rng {
        let mut rng = ChaCha8Rng::from_seed(self.seed);
        rng.set_stream(self.stream);
        rng.set_word_pos(self.word_pos);
        rng
    }
}

/// A fit's resumable state ([`Trainer::snapshot`]): with the config and the data, all a
/// resumed fit needs to reach the same weights as an uninterrupted one.
#[derive(Clone, Debug)]
pub struct TrainerSnapshot {
    /// The field's parameters, a burnpack.
    pub model: Vec<u8>,
    /// Adam's state, a burnpack.
    pub optimizer: Vec<u8>,
    /// The random stream.
    pub rng: RngState,
    /// Iterations done.
    pub iterations_done: usize,
    /// Their records.
    pub history: Vec<IterationRecord>,
}

/// What [`Trainer::run_with`] does between iterations besides fitting.
type ObserveFn<'a, M> = Box<dyn FnMut(&IterationRecord, M) -> Result<()> + 'a>;
type CheckpointFn<'a> = Box<dyn FnMut(&TrainerSnapshot) -> Result<()> + 'a>;

/// Hooks of a run: observation, checkpoints and interrupts.
pub struct Hooks<'a, M> {
    observe: Option<(usize, ObserveFn<'a, M>)>,
    checkpoint: Option<(usize, CheckpointFn<'a>)>,
    interrupt: Option<&'a AtomicBool>,
    stop_after: Option<usize>,
}

impl<M> Default for Hooks<'_, M> {
    fn default() -> Self {
        Hooks {
            observe: None,
            checkpoint: None,
            interrupt: None,
            stop_after: None,
        }
    }
}

impl<'a, M> Hooks<'a, M> {
    /// No hooks.
    pub fn new() -> Self {
        Self::default()
    }

    /// Calls `observe(record, field)` after every `every`-th iteration and after the last,
    /// with a validation copy of the field (learning curves); `every = 0` never calls it.
    pub fn observe(
        mut self,
        every: usize,
        observe: impl FnMut(&IterationRecord, M) -> Result<()> + 'a,
    ) -> Self {
        if every > 0 {
            self.observe = Some((every, Box::new(observe)));
        }
        self
    }

    /// Calls `save(snapshot)` after every `every`-th iteration, after the last, and when
    /// interrupted.
    pub fn checkpoint(
        mut self,
        every: usize,
        save: impl FnMut(&TrainerSnapshot) -> Result<()> + 'a,
    ) -> Self {
        self.checkpoint = Some((every.max(1), Box::new(save)));
        self
    }

    /// Stops after the iteration during which `flag` was set (e.g. by Ctrl-C).
    pub fn interrupt(mut self, flag: &'a AtomicBool) -> Self {
        self.interrupt = Some(flag);
        self
    }

    /// Stops after `iterations` iterations in all (tests simulate an interrupt with it).
    pub fn stop_after(mut self, iterations: usize) -> Self {
        self.stop_after = Some(iterations);
        self
    }
}

/// The state of a fit in progress: the field on the autodiff device, its objective,
/// Adam's state, the schedule and the random stream. [`Trainer::step`] is one optimiser
/// step on one frame, [`Trainer::iteration`] one pass over the frames, and
/// [`Trainer::run_with`] the whole loop. Benchmarks drive `step` directly.
pub struct Trainer<M, O> {
    field: Option<M>,
    objective: O,
    schedule: ScheduleConfig,
    optim: burn::optim::ModuleOptimizer,
    rng: ChaCha8Rng,
    history: Vec<IterationRecord>,
    progress: bool,
    /// When this session's first iteration started, and the seconds done before it.
    clock: Option<(Instant, f64)>,
}

impl<'a, M: MotionField + Module> Trainer<M, TrajectoryObjective<'a>> {
    /// Prepares a fit of `field` (whose parameters live on `device.autodiff()`) to the
    /// training trajectories `data` by `config` (`config.model` is not read).
    pub fn new(
        field: M,
        config: &FitConfig,
        data: &'a Trajectories,
        device: &Device,
    ) -> Result<Self> {
        let objective = TrajectoryObjective::new(&field, config, data, device)?;
        let rng = ChaCha8Rng::seed_from_u64(config.seed.wrapping_add(0x00D0_4A5E));
        Ok(Trainer::with_objective(
            field,
            objective,
            &config.optimizer,
            config.schedule.clone(),
            rng,
        ))
    }
}

impl<'a> Trainer<Model, TrajectoryObjective<'a>> {
    /// Prepares a fit of a fresh model of `config.model` (seeded by `config.seed`) to the
    /// training trajectories `data`.
    pub fn from_config(
        config: &FitConfig,
        data: &'a Trajectories,
        device: &Device,
    ) -> Result<Self> {
        config.validate()?;
        let ad = device.clone().autodiff();
        let model = config.model.init(config.seed, data.frame(0), &ad);
        Trainer::new(model, config, data, device)
    }
}

impl<M: MotionField + Module, O: Objective<M>> Trainer<M, O> {
    /// A loop minimising `objective` over `field` with Adam (`optimizer`), on `schedule`,
    /// drawing frame orders (and whatever the objective draws) from `rng`.
    pub fn with_objective(
        field: M,
        objective: O,
        optimizer: &AdamConfig,
        schedule: ScheduleConfig,
        rng: ChaCha8Rng,
    ) -> Self {
        Trainer {
            field: Some(field),
            objective,
            schedule,
            optim: optimizer.init(),
            rng,
            history: Vec::new(),
            progress: false,
            clock: None,
        }
    }

    /// Shows a progress bar while running (off by default).
    pub fn progress(mut self, show: bool) -> Self {
        self.progress = show;
        self
    }

    /// One Adam step on frame `k` at learning rate `lr`. Returns the (detached) primary
    /// and total loss as a `[2]` tensor; reading it is left to the caller, so that a step
    /// does not force a device sync.
    pub fn step(&mut self, k: usize, lr: f64) -> Result<Tensor<1>> {
        let field = self.field.take().expect("the field is always put back");
        let iteration = self.history.len();
        let losses = self
            .objective
            .step_loss(&field, k, iteration, &mut self.rng);
        let (primary, total) = match losses {
            Ok(l) => l,
            Err(e) => {
                self.field = Some(field);
                return Err(e);
            }
        };
        let losses = Tensor::cat(vec![primary.detach(), total.clone().detach()], 0);
        let grads = GradientsParams::from_grads(total.backward(), &field);
        self.field = Some(self.optim.step(lr, field, grads));
        Ok(losses)
    }

    /// The next iteration: every frame once, in a fresh random order. Reads the losses
    /// back once, stops with [`DomaError::NonFiniteLoss`] if any step's loss is not
    /// finite, and records the iteration.
    pub fn iteration(&mut self) -> Result<&IterationRecord> {
        let offset = self.history.last().map_or(0.0, |r| r.seconds);
        let (started, offset) = *self.clock.get_or_insert((Instant::now(), offset));
        let iteration = self.history.len();
        let lr = self.schedule.learning_rate_at(iteration);
        let mut order: Vec<usize> = (0..self.objective.frames()).collect();
        order.shuffle(&mut self.rng);
        let mut step_losses = Vec::with_capacity(order.len());
        for &k in &order {
            step_losses.push(self.step(k, lr)?);
        }
        let (trajectory_loss, total_loss) = read_step_losses(step_losses, &order, iteration)?;
        self.history.push(IterationRecord {
            iteration,
            learning_rate: lr,
            trajectory_loss,
            total_loss,
            seconds: offset + started.elapsed().as_secs_f64(),
        });
        Ok(self.history.last().expect("just pushed"))
    }

    /// The field being fitted (parameters on the autodiff device).
    pub fn field(&self) -> &M {
        self.field.as_ref().expect("the field is always put back")
    }

    /// The records of the iterations done so far.
    pub fn history(&self) -> &[IterationRecord] {
        &self.history
    }

    /// Everything a resumed fit needs besides the config and the data: the field's
    /// parameters, Adam's state, the random stream's position and the history.
    pub fn snapshot(&self) -> Result<TrainerSnapshot> {
        let optimizer = self
            .optim
            .into_bytes()
            .map_err(|e| DomaError::Device(format!("cannot serialise Adam's state: {e}")))?
            .to_vec();
        Ok(TrainerSnapshot {
            model: crate::checkpoint::encode_checkpoint(
                self.field().clone(),
                crate::checkpoint::Precision::F32,
            )?,
            optimizer,
            rng: RngState::of(&self.rng),
            iterations_done: self.history.len(),
            history: self.history.clone(),
        })
    }

    /// Puts a [`Trainer::snapshot`] back: the field's parameters (with their ids, which
    /// key Adam's state), Adam's state, the random stream and the history.
    pub fn restore(&mut self, snapshot: &TrainerSnapshot) -> Result<()> {
        if snapshot.history.len() != snapshot.iterations_done {
            return Err(DomaError::InvalidData(format!(
                "the checkpoint says {} iterations but holds {} records",
                snapshot.iterations_done,
                snapshot.history.len()
            )));
        }
        let field = self.field.take().expect("the field is always put back");
        let loaded = crate::checkpoint::decode_checkpoint(field.clone(), &snapshot.model);
        self.field = Some(match loaded {
            Ok(f) => f,
            Err(e) => {
                self.field = Some(field);
                return Err(e);
            }
        });
        let optim = std::mem::replace(&mut self.optim, AdamConfig::new().init());
        self.optim = optim
            .from_bytes(burn::tensor::Bytes::from_bytes_vec(
                snapshot.optimizer.clone(),
            ))
            .map_err(|e| {
                DomaError::InvalidData(format!("the saved Adam state is unreadable: {e}"))
            })?;
        self.rng = snapshot.rng.restore();
        self.history = snapshot.history.clone();
        self.clock = None;
        Ok(())
    }

    /// The whole fit: every remaining iteration of the schedule.
    pub fn run(self) -> Result<Fitted<M>> {
        self.run_with(Hooks::new()).map(Outcome::expect_finished)
    }

    /// [`Trainer::run`], calling `observe(record, field)` after every `every`-th iteration
    /// (and after the last) with that iteration's record and a validation copy of the
    /// field; `every = 0` never calls it. Learning curves are built on this.
    pub fn run_observed(
        self,
        every: usize,
        observe: impl FnMut(&IterationRecord, M) -> Result<()>,
    ) -> Result<Fitted<M>> {
        self.run_with(Hooks::new().observe(every, observe))
            .map(Outcome::expect_finished)
    }

    /// The loop: the remaining iterations of the schedule (all of them, or those after a
    /// [`Trainer::restore`]), with `hooks` between iterations.
    pub fn run_with(mut self, mut hooks: Hooks<'_, M>) -> Result<Outcome<M>> {
        let total = self.schedule.iterations;
        let bar = self.progress_bar();
        while self.history.len() < total {
            let record = self.iteration()?.clone();
            let done = record.iteration + 1;
            bar.set_message(format!(
                "{} {:.2e}  loss {:.2e}",
                self.objective.primary_name(),
                record.trajectory_loss,
                record.total_loss
            ));
            bar.set_position(done as u64);
            if let Some((every, observe)) = &mut hooks.observe
                && (done % *every == 0 || done == total)
            {
                observe(&record, self.field().clone().valid())?;
            }
            let stop = hooks.interrupt.is_some_and(|f| f.load(Ordering::SeqCst))
                || hooks.stop_after == Some(done);
            if let Some((every, save)) = &mut hooks.checkpoint
                && (done % *every == 0 || done == total || stop)
            {
                save(&self.snapshot()?)?;
            }
            if stop && done < total {
                bar.abandon();
                return Ok(Outcome::Interrupted {
                    iterations_done: done,
                });
            }
        }
        bar.finish_and_clear();
        let field = self.field.take().expect("the field is always put back");
        let frames = self.objective.frames();
        Ok(Outcome::Finished(Fitted {
            field: field.valid(),
            seconds: self.history.last().map_or(0.0, |r| r.seconds),
            steps: self.history.len() * frames,
            history: self.history,
        }))
    }

    fn progress_bar(&self) -> ProgressBar {
        if !self.progress {
            return ProgressBar::hidden();
        }
        ProgressBar::new(self.schedule.iterations as u64)
            .with_style(
                ProgressStyle::with_template(
                    "{bar:30} {pos}/{len} it  {elapsed_precise}<{eta_precise}  {msg}",
                )
                .expect("a valid template"),
            )
            .with_position(self.history.len() as u64)
    }
}

impl<M> Outcome<M> {
    /// The fitted field of a run without interrupts.
    fn expect_finished(self) -> Fitted<M> {
        match self {
            Outcome::Finished(f) => f,
            Outcome::Interrupted { .. } => unreachable!("a run without hooks is not interrupted"),
        }
    }
}

/// Reads an iteration's step losses back (one device sync), each a `[2]` tensor
/// (primary loss, total) in the order `order` of frames; stops with
/// [`DomaError::NonFiniteLoss`] naming the iteration and frame if any is not finite, else
/// returns the two means.
fn read_step_losses(
    step_losses: Vec<Tensor<1>>,
    order: &[usize],
    iteration: usize,
) -> Result<(f64, f64)> {
    let losses = Tensor::stack::<2>(step_losses, 0)
        .try_into_vec_as::<f64>()
        .map_err(|e| DomaError::Device(format!("{e:?}")))?;
    if let Some(i) = losses.iter().position(|v| !v.is_finite()) {
        return Err(DomaError::NonFiniteLoss {
            iteration,
            frame: order[i / 2],
            value: losses[i],
        });
    }
    let mean = |c: usize| losses.iter().skip(c).step_by(2).sum::<f64>() / order.len() as f64;
    Ok((mean(0), mean(1)))
}
