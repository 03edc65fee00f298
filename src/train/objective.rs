//! What one step of the loop minimises. The loop ([`super::Trainer`]) owns the frame
//! order, the schedule, Adam and the random stream; an [`Objective`] turns the field and
//! a frame into losses. The two objectives are the trajectory fit
//! ([`super::TrajectoryObjective`], the paper's Sec. 3) and the guided registration of
//! Eq. 14 ([`crate::register`]).

use burn::tensor::{Gradients, Tensor};
use rand_chacha::ChaCha8Rng;

use crate::Result;

/// The losses of one optimiser step.
pub trait Objective<M>: Send {
    /// What the primary loss is called on the progress bar.
    fn primary_name(&self) -> &'static str {
        "L1"
    }

    /// Steps per iteration: the frames.
    fn frames(&self) -> usize;

    /// Called by [`super::Trainer::iteration`] before its steps, with the frame order it
    /// will take: an objective may draw what its steps need here, in the order the steps
    /// would draw it (so the random stream is unchanged), and move it to the device in one
    /// transfer. The default draws nothing.
    fn prepare_iteration(&mut self, _order: &[usize], _rng: &mut ChaCha8Rng) {}

    /// The losses of one step on frame `k` during iteration `iteration` (0-based), each
    /// `[1]`: the primary loss (reported) and the total (minimised). `rng` is the loop's
    /// stream, for whatever the step draws.
    fn step_loss(
        &mut self,
        field: &M,
        k: usize,
        iteration: usize,
        rng: &mut ChaCha8Rng,
    ) -> Result<(Tensor<1>, Tensor<1>)>;

    /// Switches the objective to host batches for the fused step (the whole step as one
    /// CPU op, [`super::StepKind::Fused`]): from now on [`Objective::prepare_iteration`]
    /// keeps its draws on the host and [`Objective::host_batch`] gives each step's inputs.
    /// The reason when the objective has no such form (the default).
    fn use_host_batches(&mut self) -> std::result::Result<(), String> {
        Err("this objective is not a trajectory fit".into())
    }

    /// Goes back to device batches (a resumed fit whose Adam state is Burn's).
    fn stop_host_batches(&mut self) {}

    /// The fused step's inputs on frame `k`, drawn from `rng` as [`Objective::step_loss`]
    /// would draw them; `None` unless [`Objective::use_host_batches`] succeeded.
    fn host_batch(&mut self, _k: usize, _rng: &mut ChaCha8Rng) -> Option<super::fused::HostBatch> {
        None
    }

    /// Called after each step's backward pass with its gradients and learning rate: an
    /// objective with parameters of its own updates them here. The default has none.
    fn after_backward(&mut self, _grads: &Gradients, _lr: f64) {}

    /// The objective's own learned state, for a checkpoint (empty when it has none).
    fn state(&self) -> Result<Vec<f32>> {
        Ok(Vec::new())
    }

    /// Puts an [`Objective::state`] back.
    fn restore_state(&mut self, state: &[f32]) -> Result<()> {
        if state.is_empty() {
            Ok(())
        } else {
            Err(crate::DomaError::InvalidData(format!(
                "the checkpoint holds {} values of an objective that learns none",
                state.len()
            )))
        }
    }

    /// The canonical positions `[N, 3]` of its data, where it learned some of them.
    fn learned_canonical(&self) -> Result<Option<Vec<f32>>> {
        Ok(None)
    }

    /// The EPE of `field` (a validation copy) on the tracks the objective holds back from
    /// the fit, when it holds some back ([`super::Convergence`]); the default holds none.
    fn validation_epe(&self, _field: &M) -> Result<Option<f64>> {
        Ok(None)
    }
}
