//! The fit loop, once: frame order, learning-rate schedule, Adam, progress, the NaN
//! guard, checkpoints, resume, interrupts and observation for learning curves. Every fit
//! in doma (the experiments, `doma fit`, the guided registration) runs through it.

use std::sync::atomic::Ordering;
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::config::FitConfig;
use super::fused::{self, FusedStep, StepKind};
use super::hooks::Hooks;
use super::objective::Objective;
use super::record::{Fitted, IterationRecord, Outcome, StepLoss, read_step_losses};
use super::schedule::{Convergence, ScheduleConfig};
use super::trajectory::TrajectoryObjective;
use crate::data::Trajectories;
use crate::field::MotionField;
use crate::field::model::Model;
use crate::{DomaError, Result};

mod snapshot;

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
    /// The field's device, which decides where steps run (`backend::on_worker`).
    device: Option<Device>,
    /// Frames per Adam step (1: the paper's one frame per step).
    frames_per_step: usize,
    /// Frames per iteration (`None`: all of them, the paper's protocol).
    frames_per_iteration: Option<usize>,
    /// When to stop before the budget, on the objective's held-back tracks.
    convergence: Option<Convergence>,
    /// The whole step as one CPU operation, when the fit takes it ([`StepKind`]); it holds
    /// the parameters during an iteration and writes them into `field` after it.
    fused: Option<FusedStep<f32>>,
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
        let mut trainer = Trainer::with_objective(
            field,
            objective,
            &config.optimizer,
            config.schedule.clone(),
            rng,
        )
        .frames_per_step(config.frames_per_step.unwrap_or(1));
        trainer.frames_per_iteration = config.frames_per_iteration;
        trainer.convergence = config.until_converged.clone();
        // `auto` goes on with the composed step where the fused one does not apply, unless
        // the fit asks for SOAP, which only the fused step computes.
        if let Err(e) = trainer.start_fused(config, device)
            && (config.step == Some(StepKind::Fused) || config.soap.is_some())
        {
            return Err(e);
        }
        Ok(trainer)
    }

    /// Hands the steps to the fused step when `config` asks for it and it applies; else
    /// the reason, and nothing changed.
    fn start_fused(&mut self, config: &FitConfig, device: &Device) -> Result<()> {
        if config.step.unwrap_or(StepKind::Composed) == StepKind::Composed {
            return Ok(());
        }
        fused::check(config, device)?;
        let refuse = |why: String| {
            DomaError::InvalidConfig(format!("the fused step cannot run this fit: {why}"))
        };
        let field = self.field();
        let siren = field
            .siren()
            .ok_or_else(|| refuse("the model is not one SIREN with a head".into()))?;
        let adam = fused::adam_settings(&config.optimizer).map_err(refuse)?;
        let loss = fused::StepLoss {
            penalty: config.loss.penalty(),
            smoothness_weight: config.loss.smoothness_weight,
            smoothness_norm: config.loss.smoothness_norm,
        };
        let mut step = FusedStep::from_siren(siren, field.head(), loss, adam)?
            .with_time_scale(field.time_scale());
        if let Some(soap) = config.soap {
            step = step.with_soap(soap);
        }
        Objective::<M>::use_host_batches(&mut self.objective).map_err(refuse)?;
        self.fused = Some(step);
        Ok(())
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
        let model = config.model.init(config.seed, data.canonical(), &ad);
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
        let device = field.devices().into_iter().next();
        Trainer {
            device,
            field: Some(field),
            objective,
            schedule,
            optim: optimizer.init(),
            rng,
            history: Vec::new(),
            progress: false,
            clock: None,
            frames_per_step: 1,
            frames_per_iteration: None,
            convergence: None,
            fused: None,
        }
    }

    /// Whether the fused step takes this fit's steps ([`StepKind`]).
    pub fn is_fused(&self) -> bool {
        self.fused.is_some()
    }

    /// Writes the fused step's parameters into the field, so that [`Trainer::field`] is
    /// current after steps taken one by one ([`Trainer::step`]); [`Trainer::iteration`]
    /// does it after its steps. Nothing to do for the composed step.
    pub fn sync_field(&mut self) {
        if let Some(fused) = &self.fused
            && let Some(field) = self.field.take()
        {
            self.field = Some(fused.write_back(field));
        }
    }

    /// Takes `frames` frames per Adam step: each step minimises the sum of their losses
    /// (1, the default, is the paper's one frame per step; 0 is taken as 1).
    pub fn frames_per_step(mut self, frames: usize) -> Self {
        self.frames_per_step = frames.max(1);
        self
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
        self.step_frames(&[k], lr)
    }

    /// One Adam step on the sum of the losses of `frames` at learning rate `lr`: the
    /// gradient is the sum of the frames' gradients (one frame adds nothing to its own
    /// loss, so it is the paper's step). Returns the (detached) summed primary and total
    /// loss as a `[2]` tensor.
    pub fn step_frames(&mut self, frames: &[usize], lr: f64) -> Result<Tensor<1>> {
        Ok(match self.step_loss(frames, lr)? {
            StepLoss::Host(values) => {
                let device = self.device.clone().unwrap_or_default();
                Tensor::from_data(TensorData::new(values.to_vec(), [2]), &device)
            }
            StepLoss::Device(losses) => *losses,
        })
    }

    /// [`Trainer::step_frames`], its losses left on the host where the step computed them.
    fn step_loss(&mut self, frames: &[usize], lr: f64) -> Result<StepLoss> {
        match self.device.clone() {
            Some(device) => {
                crate::backend::on_worker(&device, || self.step_frames_here(frames, lr))
            }
            None => self.step_frames_here(frames, lr),
        }
    }

    fn step_frames_here(&mut self, frames: &[usize], lr: f64) -> Result<StepLoss> {
        if let (Some(fused), [k]) = (self.fused.as_mut(), frames) {
            let batch = self
                .objective
                .host_batch(*k, &mut self.rng)
                .ok_or_else(|| {
                    DomaError::InvalidConfig("the objective gives no host batches".into())
                })?;
            let losses = fused.step(&batch.batch(), lr);
            return Ok(StepLoss::Host([losses.data as f32, losses.total as f32]));
        }
        let field = self.field.take().expect("the field is always put back");
        let iteration = self.history.len();
        let mut sums: Option<(Tensor<1>, Tensor<1>)> = None;
        for &k in frames {
            let (primary, total) =
                match self
                    .objective
                    .step_loss(&field, k, iteration, &mut self.rng)
                {
                    Ok(l) => l,
                    Err(e) => {
                        self.field = Some(field);
                        return Err(e);
                    }
                };
            sums = Some(match sums {
                None => (primary, total),
                Some((p, t)) => (p + primary, t + total),
            });
        }
        let Some((primary, total)) = sums else {
            self.field = Some(field);
            return Err(DomaError::InvalidConfig(
                "a step needs at least one frame".into(),
            ));
        };
        let losses = Tensor::cat(vec![primary.detach(), total.clone().detach()], 0);
        let grads = total.backward();
        self.objective.after_backward(&grads, lr);
        let grads = GradientsParams::from_grads(grads, &field);
        self.field = Some(self.optim.step(lr, field, grads));
        Ok(StepLoss::Device(Box::new(losses)))
    }

    /// The frames an iteration visits: all of them, or at most `frames_per_iteration`.
    fn iteration_frames(&self) -> usize {
        let frames = self.objective.frames();
        self.frames_per_iteration.map_or(frames, |n| n.min(frames))
    }

    /// The next iteration: every frame once, in a fresh random order, or the first
    /// `frames_per_iteration` frames of that order (the whole permutation is drawn either
    /// way, so a budget of at least the frame count is the paper's iteration, bit for
    /// bit). Reads the losses
    /// back once, stops with [`DomaError::NonFiniteLoss`] if any step's loss is not
    /// finite, and records the iteration.
    pub fn iteration(&mut self) -> Result<&IterationRecord> {
        let offset = self.history.last().map_or(0.0, |r| r.seconds);
        let (started, offset) = *self.clock.get_or_insert((Instant::now(), offset));
        let iteration = self.history.len();
        let lr = self.learning_rate_at(iteration);
        let mut order: Vec<usize> = (0..self.objective.frames()).collect();
        order.shuffle(&mut self.rng);
        order.truncate(self.iteration_frames());
        self.objective.prepare_iteration(&order, &mut self.rng);
        let mut step_losses = Vec::with_capacity(order.len());
        let mut first_frames = Vec::with_capacity(order.len());
        for frames in order.chunks(self.frames_per_step) {
            step_losses.push(self.step_loss(frames, lr)?);
            first_frames.push(frames[0]);
        }
        self.sync_field();
        let (trajectory_loss, total_loss) =
            read_step_losses(step_losses, &first_frames, order.len(), iteration)?;
        self.history.push(IterationRecord {
            iteration,
            learning_rate: lr,
            trajectory_loss,
            total_loss,
            seconds: offset + started.elapsed().as_secs_f64(),
            validation_epe: None,
        });
        // The validation EPE is part of the fit's cost, so it runs inside its clock.
        if let Some(every) = self.convergence.as_ref().map(|c| c.every)
            && (iteration + 1).is_multiple_of(every)
        {
            let epe = self
                .objective
                .validation_epe(&self.field().clone().valid())?;
            let record = self.history.last_mut().expect("just pushed");
            record.validation_epe = epe;
            record.seconds = offset + started.elapsed().as_secs_f64();
        }
        Ok(self.history.last().expect("just pushed"))
    }

    /// The learning rate of iteration `e`: the schedule's, or during the cool-down after a
    /// plateau ([`Convergence`]), a linear fall from the schedule's rate at the plateau.
    fn learning_rate_at(&self, e: usize) -> f64 {
        match (self.plateau(), &self.convergence) {
            (Some(p), Some(c)) if e >= p => {
                let cooldown = c.cooldown_iterations() as f64;
                let fraction = 1.0 - (e - p + 1) as f64 / (cooldown + 1.0);
                self.schedule.learning_rate_at(p) * fraction.max(0.0)
            }
            _ => self.schedule.learning_rate_at(e),
        }
    }

    /// The iterations done when the validation EPE reached its plateau, if it has.
    fn plateau(&self) -> Option<usize> {
        self.convergence.as_ref()?.plateau(
            self.history
                .iter()
                .filter_map(|r| Some((r.iteration + 1, r.validation_epe?))),
        )
    }

    /// Whether the fit has converged by its [`Convergence`]: its validation EPE reached a
    /// plateau and the cool-down after it is done (never without one).
    pub fn converged(&self) -> bool {
        match (self.plateau(), &self.convergence) {
            (Some(p), Some(c)) => self.history.len() >= p + c.cooldown_iterations(),
            _ => false,
        }
    }

    /// The field being fitted (parameters on the autodiff device).
    pub fn field(&self) -> &M {
        self.field.as_ref().expect("the field is always put back")
    }

    /// The records of the iterations done so far.
    pub fn history(&self) -> &[IterationRecord] {
        &self.history
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
        // Outside a terminal (a log, a pipe) the bar draws nothing: plain lines instead.
        let lines = self.progress && !std::io::IsTerminal::is_terminal(&std::io::stderr());
        while self.history.len() < total && !self.converged() {
            let record = self.iteration()?.clone();
            let converged = self.converged();
            let done = record.iteration + 1;
            bar.set_message(format!(
                "{} {:.2e}  loss {:.2e}",
                self.objective.primary_name(),
                record.trajectory_loss,
                record.total_loss
            ));
            bar.set_position(done as u64);
            if lines && (done % total.div_ceil(10).max(1) == 0 || done == total || converged) {
                eprintln!(
                    "iteration {done}/{total}  {} {:.2e}  loss {:.2e}  {:.1} s",
                    self.objective.primary_name(),
                    record.trajectory_loss,
                    record.total_loss,
                    record.seconds
                );
            }
            if let Some(each) = &mut hooks.each {
                each(&record, total)?;
            }
            if let Some((every, observe)) = &mut hooks.observe
                && (done % *every == 0 || done == total || converged)
            {
                observe(&record, self.field().clone().valid())?;
            }
            let stop = hooks.interrupt.is_some_and(|f| f.load(Ordering::SeqCst))
                || hooks.stop_after == Some(done);
            if let Some((every, save)) = &mut hooks.checkpoint
                && (done % *every == 0 || done == total || stop || converged)
            {
                save(&self.snapshot()?)?;
            }
            if stop && done < total && !converged {
                bar.abandon();
                return Ok(Outcome::Interrupted {
                    iterations_done: done,
                });
            }
        }
        bar.finish_and_clear();
        let field = self.field.take().expect("the field is always put back");
        let frames = self.iteration_frames();
        let canonical = self.objective.learned_canonical()?;
        Ok(Outcome::Finished(Fitted {
            canonical,
            field: field.valid(),
            seconds: self.history.last().map_or(0.0, |r| r.seconds),
            steps: self.history.len() * frames.div_ceil(self.frames_per_step),
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
