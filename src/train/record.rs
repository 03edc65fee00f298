//! What a fit leaves: the per-iteration records, the fitted field, and the resumable
//! state of the loop (its random stream included).

use burn::tensor::Tensor;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

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
    /// The EPE on the held-back tracks after this iteration, when the fit stops on
    /// convergence ([`super::Convergence`]) and measured it here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validation_epe: Option<f64>,
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
    /// The canonical positions `[N, 3]` of the training data where the fit learned some
    /// (tracks unseen in the reference frame, docs/design.md §7); `None`: the data's own.
    pub canonical: Option<Vec<f32>>,
}

/// How [`super::Trainer::run_with`] ended.
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
    pub(super) fn of(rng: &ChaCha8Rng) -> Self {
        RngState {
            seed: rng.get_seed(),
            stream: rng.get_stream(),
            word_pos: rng.get_word_pos(),
        }
    }

    pub(super) fn restore(&self) -> ChaCha8Rng {
        let mut rng = ChaCha8Rng::from_seed(self.seed);
        rng.set_stream(self.stream);
        rng.set_word_pos(self.word_pos);
        rng
    }
}

/// A fit's resumable state ([`super::Trainer::snapshot`]): with the config and the data, all a
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
    /// The objective's own learned state ([`super::Objective::state`]; empty if none).
    pub objective: Vec<f32>,
}

impl<M> Outcome<M> {
    /// The fitted field of a run without interrupts.
    pub(super) fn expect_finished(self) -> Fitted<M> {
        match self {
            Outcome::Finished(f) => f,
            Outcome::Interrupted { .. } => unreachable!("a run without hooks is not interrupted"),
        }
    }
}

/// A step's summed primary and total loss: on the host already (the fused step computes
/// them there), or a `[2]` tensor still on the device.
pub(super) enum StepLoss {
    /// The two losses, as the `f32` a tensor would hold.
    Host([f32; 2]),
    /// The `[2]` tensor, read back with the iteration's others (boxed: a tensor is large
    /// beside two floats).
    Device(Box<Tensor<1>>),
}

/// Reads an iteration's step losses back (one device sync for those on the device; those
/// on the host never become tensors, whose autodiff bookkeeping cost tens of megabytes an
/// iteration), each (primary loss, total) in the order `order` of frames; stops with
/// [`DomaError::NonFiniteLoss`] naming the iteration and frame if any is not finite, else
/// returns the two means.
pub(super) fn read_step_losses(
    step_losses: Vec<StepLoss>,
    first_frames: &[usize],
    frames: usize,
    iteration: usize,
) -> Result<(f64, f64)> {
    let mut on_device = Vec::new();
    for l in &step_losses {
        if let StepLoss::Device(t) = l {
            on_device.push((**t).clone());
        }
    }
    let read = if on_device.is_empty() {
        Vec::new()
    } else {
        crate::readback::to_vec::<f64, 2, _>(Tensor::stack::<2>(on_device, 0))?
    };
    let mut read = read.chunks_exact(2);
    let mut losses = Vec::with_capacity(2 * step_losses.len());
    for l in &step_losses {
        match l {
            StepLoss::Host(pair) => losses.extend(pair.map(f64::from)),
            StepLoss::Device(_) => losses.extend(read.next().into_iter().flatten().copied()),
        }
    }
    if let Some(i) = losses.iter().position(|v| !v.is_finite()) {
        return Err(DomaError::NonFiniteLoss {
            iteration,
            frame: first_frames[i / 2],
            value: losses[i],
        });
    }
    // Per frame: a step's losses are the sums over its frames.
    let mean = |c: usize| losses.iter().skip(c).step_by(2).sum::<f64>() / frames as f64;
    Ok((mean(0), mean(1)))
}
