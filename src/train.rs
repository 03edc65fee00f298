//! One fit loop for every motion field and every Jacobian method (REFERENCE §5).
//!
//! One *iteration* is one pass over all `T` frames in a fresh random order; each frame
//! is one Adam step on all training points. The step loss is the trajectory L1, plus
//! `w_H · L_H` (Eq. 13) and `w_E ·` elasticity when their weights are positive. The
//! learning rate follows the authors' LambdaLR schedule.

use std::time::Instant;

use burn::config::Config;
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use indicatif::{ProgressBar, ProgressStyle};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::data::Trajectories;
use crate::field::{DomaField, DomaFieldConfig, MotionField, Variant};
use crate::jacobian::{JacobianKind, JacobianMethod};
use crate::loss::{self, SmoothnessNorm};
use crate::{DomaError, Result};

/// Everything that defines a fit; saved as `config.json` next to a checkpoint.
#[derive(Config, Debug)]
pub struct FitConfig {
    /// The motion field (variant and SIREN shape).
    pub field: DomaFieldConfig,
    /// Iterations (passes over all frames); the paper's budget is 1000.
    #[config(default = 1000)]
    pub iterations: usize,
    /// Adam's base learning rate (1e-4 for the DOMA variants).
    #[config(default = 1e-4)]
    pub learning_rate: f64,
    /// Iterations at the full learning rate before the linear decay (the authors' 10).
    #[config(default = 10)]
    pub lr_flat_iterations: usize,
    /// The weight `w_H` of the smoothness loss `L_H` (0 = off; the paper's "-H" uses 0.1).
    #[config(default = 0.0)]
    pub smoothness_weight: f64,
    /// The per-entry penalty of `L_H`.
    #[config(default = "SmoothnessNorm::Squared")]
    pub smoothness_norm: SmoothnessNorm,
    /// At most this many training points (a fresh random subset each step) carry
    /// `L_H`. `None`: the authors' choice for the variant ([`FitConfig::smoothness_sampling`]).
    pub smoothness_points: Option<usize>,
    /// The standard deviation of the Gaussian jitter added to the `L_H` points.
    /// `None`: the authors' choice for the variant.
    pub smoothness_jitter: Option<f64>,
    /// The weight `w_E` of the elasticity loss (0 = off).
    #[config(default = 0.0)]
    pub elasticity_weight: f64,
    /// How the spatial Jacobian is computed.
    #[config(default = "JacobianKind::Autodiff")]
    pub jacobian: JacobianKind,
    /// Seeds the initial weights, the frame order and the `L_H` samples.
    #[config(default = 0)]
    pub seed: u64,
    /// No progress bar.
    #[config(default = false)]
    pub quiet: bool,
}

impl FitConfig {
    /// The `L_H` sample points as `(max points, jitter σ)`. Unless set in the config,
    /// the authors' choice (REFERENCE §4.2): Affinity uses a random subset of at most
    /// 1024 training points jittered by `σ = 0.1`; the other variants use every
    /// training point, unjittered.
    pub fn smoothness_sampling(&self) -> (Option<usize>, f64) {
        let affinity = self.field.variant == Variant::Affinity;
        let points = self
            .smoothness_points
            .or(if affinity { Some(1024) } else { None });
        let jitter = self
            .smoothness_jitter
            .unwrap_or(if affinity { 0.1 } else { 0.0 });
        (points, jitter)
    }

    /// The learning-rate factor during iteration `e` (0-based): 1 for the first
    /// `lr_flat_iterations + 1` iterations, then a linear decay,
    /// `1 − (e − flat) / (iterations − flat + 1)` (the authors' LambdaLR).
    pub fn lr_factor(&self, e: usize) -> f64 {
        let flat = self.lr_flat_iterations;
        if e <= flat {
            1.0
        } else {
            1.0 - (e - flat) as f64 / (self.iterations + 1 - flat) as f64
        }
    }

    /// Refuses values that cannot run.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(DomaError::InvalidConfig(m));
        if self.iterations == 0 {
            return bad("iterations must be at least 1".into());
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return bad(format!(
                "learning rate {} must be positive",
                self.learning_rate
            ));
        }
        for (name, w) in [
            ("smoothness weight", self.smoothness_weight),
            ("elasticity weight", self.elasticity_weight),
        ] {
            if !(w.is_finite() && w >= 0.0) {
                return bad(format!("{name} {w} must be finite and non-negative"));
            }
        }
        if self.field.hidden == 0 {
            return bad("hidden width must be at least 1".into());
        }
        if self.smoothness_points == Some(0) {
            return bad("smoothness points must be at least 1".into());
        }
        if let Some(j) = self.smoothness_jitter
            && !(j.is_finite() && j >= 0.0)
        {
            return bad(format!(
                "smoothness jitter {j} must be finite and non-negative"
            ));
        }
        Ok(())
    }
}

/// The record of one iteration.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct IterationRecord {
    /// 0-based iteration.
    pub iteration: usize,
    /// The learning rate used.
    pub learning_rate: f64,
    /// The trajectory L1, averaged over the iteration's steps.
    pub trajectory_loss: f64,
    /// The whole step loss, averaged over the iteration's steps.
    pub total_loss: f64,
    /// Seconds since the fit started.
    pub seconds: f64,
}

/// A fitted field and how the fit went.
#[derive(Debug)]
pub struct Fitted<M> {
    /// The field, moved off the autodiff graph (ready for evaluation).
    pub field: M,
    /// One record per iteration.
    pub history: Vec<IterationRecord>,
    /// Wall time of the loop, seconds.
    pub seconds: f64,
    /// Optimiser steps taken (`iterations × T`).
    pub steps: usize,
}

/// Fits a DOMA field of `config.field` to the training trajectories `data` on `device`
/// (any backend; autodiff is switched on here).
pub fn fit(config: &FitConfig, data: &Trajectories, device: &Device) -> Result<Fitted<DomaField>> {
    config.validate()?;
    let ad = device.clone().autodiff();
    let field = config.field.init(config.seed, &ad);
    fit_model(field, config, data, device)
}

/// The progress bar of a fit loop (hidden when `quiet`).
pub(crate) fn progress_bar(iterations: usize, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    ProgressBar::new(iterations as u64).with_style(
        ProgressStyle::with_template(
            "{bar:30} {pos}/{len} it  {elapsed_precise}<{eta_precise}  {msg}",
        )
        .expect("a valid template"),
    )
}

/// Reads an iteration's step losses back (one device sync), each a `[2]` tensor
/// (primary loss, total) in the order `order` of frames; stops with
/// [`DomaError::NonFiniteLoss`] naming the iteration and frame if any is not finite, else
/// returns the two means.
pub(crate) fn read_step_losses(
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

/// Draws the `L_H` sample points: a random subset of at most `max` rows of `x0`
/// (`[N, 3]`, host), jittered by Gaussian noise of standard deviation `sigma`.
fn smoothness_samples(
    x0: &[f32],
    max: Option<usize>,
    sigma: f64,
    rng: &mut impl Rng,
) -> (Vec<f32>, usize) {
    let n = x0.len() / 3;
    let mut rows: Vec<usize> = (0..n).collect();
    let take = max.map_or(n, |m| m.min(n));
    if take < n {
        rows.shuffle(rng);
        rows.truncate(take);
    }
    let mut out = Vec::with_capacity(take * 3);
    for &i in &rows {
        for c in 0..3 {
            let noise = if sigma > 0.0 {
                sigma * gaussian(rng)
            } else {
                0.0
            };
            out.push((x0[3 * i + c] as f64 + noise) as f32);
        }
    }
    (out, take)
}

/// A standard normal draw (Box–Muller), so that the samples are the same on every
/// backend for a given seed.
pub(crate) fn gaussian(rng: &mut impl Rng) -> f64 {
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

/// A fit's resumable state ([`Trainer::snapshot`]).
#[derive(Clone, Debug)]
pub struct TrainerSnapshot {
    /// The field's parameters, a burnpack.
    pub model: Vec<u8>,
    /// Adam's state, a burnpack.
    pub optimizer: Vec<u8>,
    /// The random stream.
    pub rng: RngState,
}

/// The state of a fit in progress: the field on the autodiff device, Adam's state, the
/// data on the device and the random stream. [`Trainer::step`] is one optimiser step on
/// one frame; [`Trainer::run`] is the whole loop. Benchmarks drive `step` directly.
pub struct Trainer<'a, M> {
    field: Option<M>,
    config: &'a FitConfig,
    data: &'a Trajectories,
    method: Box<dyn JacobianMethod>,
    optim: burn::optim::ModuleOptimizer,
    rng: ChaCha8Rng,
    ad: Device,
    x0_host: Vec<f32>,
    x0: Tensor<2>,
    targets: Vec<Tensor<2>>,
    separate_h: bool,
    warp_needs_jacobian: bool,
}

impl<'a, M: MotionField + Module> Trainer<'a, M> {
    /// Prepares a fit of `field` (whose parameters live on `device.autodiff()`) to the
    /// training trajectories `data`.
    pub fn new(
        field: M,
        config: &'a FitConfig,
        data: &'a Trajectories,
        device: &Device,
    ) -> Result<Self> {
        config.validate()?;
        let ad = device.clone().autodiff();
        let (h_points, h_jitter) = config.smoothness_sampling();
        let w_h = config.smoothness_weight;
        // L_H gets its own points when they differ from the training points.
        let separate_h =
            w_h > 0.0 && (h_jitter > 0.0 || h_points.is_some_and(|m| m < data.points()));
        let warp_needs_jacobian = config.elasticity_weight > 0.0 || (w_h > 0.0 && !separate_h);
        Ok(Trainer {
            field: Some(field),
            config,
            data,
            method: config.jacobian.method(),
            optim: AdamConfig::new().with_epsilon(1e-8).init(),
            rng: ChaCha8Rng::seed_from_u64(config.seed.wrapping_add(0x00D0_4A5E)),
            x0_host: data.frame(0).to_vec(),
            x0: data.frame_tensor(0, &ad),
            targets: (0..data.frames())
                .map(|k| data.frame_tensor(k, &ad))
                .collect(),
            ad,
            separate_h,
            warp_needs_jacobian,
        })
    }

    /// One Adam step on frame `k` at learning rate `lr`. Returns the (detached)
    /// trajectory loss and total loss as a `[2]` tensor; reading it is left to the
    /// caller, so that a step does not force a device sync.
    pub fn step(&mut self, k: usize, lr: f64) -> Tensor<1> {
        let field = self.field.take().expect("the field is always put back");
        let config = self.config;
        let method = self.method.as_ref();
        let t = self.data.time(k);
        let out = if self.warp_needs_jacobian {
            field.warp_dual(self.x0.clone(), t, Some(method))
        } else {
            field.warp_values(self.x0.clone(), t, method)
        };
        let l1 = loss::trajectory_l1(out.warped.value, self.targets[k].clone());
        let mut total = l1.clone();
        if config.smoothness_weight > 0.0 {
            let raw = if self.separate_h {
                let (h_points, h_jitter) = config.smoothness_sampling();
                let (pts, n) = smoothness_samples(&self.x0_host, h_points, h_jitter, &mut self.rng);
                let pts = Tensor::<2>::from_data(TensorData::new(pts, [n, 3]), &self.ad);
                field.raw_dual(pts, t, Some(method))
            } else {
                out.raw
            };
            let tangent = raw.tangent.expect("a Jacobian method yields tangents");
            total = total
                + loss::smoothness(tangent, config.smoothness_norm)
                    .mul_scalar(config.smoothness_weight);
        }
        if config.elasticity_weight > 0.0 {
            let tangent = out
                .warped
                .tangent
                .expect("a Jacobian method yields tangents");
            total = total + loss::elasticity(tangent).mul_scalar(config.elasticity_weight);
        }
        let losses = Tensor::cat(vec![l1.detach(), total.clone().detach()], 0);
        let grads = GradientsParams::from_grads(total.backward(), &field);
        self.field = Some(self.optim.step(lr, field, grads));
        losses
    }

    /// One iteration: every frame once, in a fresh random order. Reads the losses back
    /// once, and stops with [`DomaError::NonFiniteLoss`] if any step's loss is not finite.
    pub fn iteration(&mut self, iteration: usize) -> Result<(f64, f64)> {
        let frames = self.data.frames();
        let lr = self.config.learning_rate * self.config.lr_factor(iteration);
        let mut order: Vec<usize> = (0..frames).collect();
        order.shuffle(&mut self.rng);
        let step_losses: Vec<Tensor<1>> = order.iter().map(|&k| self.step(k, lr)).collect();
        read_step_losses(step_losses, &order, iteration)
    }

    /// The field being fitted (parameters on the autodiff device).
    pub fn field(&self) -> &M {
        self.field.as_ref().expect("the field is always put back")
    }

    /// Everything a resumed fit needs besides the config and the data: the field's
    /// parameters, Adam's state and the random stream's position.
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
        })
    }

    /// Puts a [`Trainer::snapshot`] back: the field's parameters (with their ids, which
    /// key Adam's state), Adam's state and the random stream.
    pub fn restore(&mut self, snapshot: &TrainerSnapshot) -> Result<()> {
        let field = self.field.take().expect("the field is always put back");
        let record = burn::store::ModuleRecord::from_bytes(burn::tensor::Bytes::from_bytes_vec(
            snapshot.model.clone(),
        ))
        .and_then(|r| field.try_load_record(r))
        .map_err(|e| DomaError::InvalidData(format!("the saved model does not fit: {e}")))?;
        self.field = Some(record);
        let optim = std::mem::replace(&mut self.optim, AdamConfig::new().init());
        self.optim = optim
            .from_bytes(burn::tensor::Bytes::from_bytes_vec(
                snapshot.optimizer.clone(),
            ))
            .map_err(|e| {
                DomaError::InvalidData(format!("the saved Adam state is unreadable: {e}"))
            })?;
        self.rng = snapshot.rng.restore();
        Ok(())
    }

    /// The whole fit: `config.iterations` iterations, with a progress bar unless quiet.
    pub fn run(self) -> Result<Fitted<M>> {
        self.run_observed(0, |_, _| Ok(()))
    }

    /// [`Trainer::run`], calling `observe(record, field)` after every `every`-th iteration
    /// (and after the last) with that iteration's record and a validation copy of the
    /// field; `every = 0` never calls it. Learning curves (test error against iterations)
    /// are built on this.
    pub fn run_observed(
        mut self,
        every: usize,
        mut observe: impl FnMut(&IterationRecord, M) -> Result<()>,
    ) -> Result<Fitted<M>> {
        let config = self.config;
        let bar = progress_bar(config.iterations, config.quiet);
        let start = Instant::now();
        let mut history = Vec::with_capacity(config.iterations);
        for iteration in 0..config.iterations {
            let (trajectory_loss, total_loss) = self.iteration(iteration)?;
            let record = IterationRecord {
                iteration,
                learning_rate: config.learning_rate * config.lr_factor(iteration),
                trajectory_loss,
                total_loss,
                seconds: start.elapsed().as_secs_f64(),
            };
            bar.set_message(format!("L1 {trajectory_loss:.2e}  loss {total_loss:.2e}"));
            bar.inc(1);
            if every > 0 && ((iteration + 1) % every == 0 || iteration + 1 == config.iterations) {
                observe(&record, self.field().clone().valid())?;
            }
            history.push(record);
        }
        bar.finish_and_clear();
        let field = self.field.take().expect("the field is always put back");
        Ok(Fitted {
            field: field.valid(),
            history,
            seconds: start.elapsed().as_secs_f64(),
            steps: config.iterations * self.data.frames(),
        })
    }
}

/// The fit loop for any motion field whose parameters live on `device.autodiff()`.
/// The returned field is a validation snapshot (no autodiff graph).
pub fn fit_model<M: MotionField + Module>(
    field: M,
    config: &FitConfig,
    data: &Trajectories,
    device: &Device,
) -> Result<Fitted<M>> {
    Trainer::new(field, config, data, device)?.run()
}
