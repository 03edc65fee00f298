//! Fitting trajectories (the paper's Sec. 3; docs/reference.md §5): a step on frame `k`
//! minimises the trajectory loss of the training points observed in frame `k`, plus
//! `w_H · L_H` (Eq. 13) and `w_E ·` elasticity when their weights are positive. The parts
//! it is made of: which rows a step reads ([`super::rows`]), where `L_H` is sampled
//! ([`super::samples`]) and the learned canonical positions of tracks unseen in the
//! reference frame ([`super::learned`]).

use std::borrow::Cow;

use burn::tensor::{Device, Gradients, Tensor, TensorData};
use rand_chacha::ChaCha8Rng;

use super::config::{FitConfig, LossConfig};
use super::fused::HostBatch;
use super::learned::LearnedPositions;
use super::objective::Objective;
use super::rows::{StepRows, TrainingRows};
use super::samples::SmoothnessSamples;
use super::schedule::Convergence;
use crate::Result;
use crate::data::Trajectories;
use crate::field::{MotionField, WarpOutput};
use crate::jacobian::JacobianMethod;
use crate::loss;

/// The most tracks that carry `L_T` in a step; a fresh random subset of them beyond it.
pub const TEMPORAL_POINTS: usize = 1024;

/// The trajectory fit of a [`FitConfig`] on training trajectories.
pub struct TrajectoryObjective<'a> {
    /// The fitted tracks: all the training tracks, or those not held back.
    data: Cow<'a, Trajectories>,
    /// All the training tracks, and the rows of the fitted ones when some are held back.
    full: &'a Trajectories,
    fit_rows: Option<Vec<usize>>,
    /// The held-back tracks of [`Convergence`], and the device that evaluates them.
    validation: Option<(Trajectories, Device)>,
    loss: LossConfig,
    method: Box<dyn JacobianMethod>,
    ad: Device,
    /// Every fitted track's canonical position `[N, 3]`.
    x0: Tensor<2>,
    rows: TrainingRows,
    /// `L_H`'s own sample points, when they are not the training points.
    samples: Option<SmoothnessSamples>,
    /// Whether the data term's warp carries the Jacobian (for `L_H` on the training
    /// points, or for elasticity).
    warp_needs_jacobian: bool,
    learned: Option<LearnedPositions>,
    /// The draws of host batches, when the fused step takes the steps.
    host: Option<host::HostDraws>,
}

impl<'a> TrajectoryObjective<'a> {
    /// The objective of `config` on the training trajectories `data`, with tensors on
    /// `device.autodiff()`. Refuses a model that `config.jacobian` does not apply to.
    pub fn new(
        field: &dyn MotionField,
        config: &FitConfig,
        data: &'a Trajectories,
        device: &Device,
    ) -> Result<Self> {
        config.schedule.validate()?;
        config.loss.validate()?;
        config.smoothness_sampling.validate()?;
        crate::field::check_method(field, config.jacobian)?;
        let full = data;
        let (data, fit_rows, validation) = match &config.until_converged {
            None => (Cow::Borrowed(full), None, None),
            Some(c) => {
                c.validate()?;
                let (fit, held) = held_back(full, c, config.seed)?;
                (
                    Cow::Owned(full.select_points(&fit)?),
                    Some(fit),
                    Some((full.select_points(&held)?, device.clone())),
                )
            }
        };
        let ad = device.clone().autodiff();
        let sampling = config.smoothness_sampling.clone();
        let w_h = config.loss.smoothness_weight;
        // L_H gets its own points when they differ from the training points: with a mask,
        // the points observed in the reference frame.
        let separate_h = w_h > 0.0
            && (data.observed().is_some()
                || sampling.jitter > 0.0
                || sampling.max_points.is_some_and(|m| m < data.points()));
        let samples = separate_h.then(|| {
            let canonical = data.canonical();
            let x0 = match data.observed_in_frame(data.reference()) {
                Some(seen) => (0..data.points())
                    .filter(|&i| seen[i])
                    .flat_map(|i| canonical[3 * i..3 * i + 3].iter().copied())
                    .collect(),
                None => canonical.to_vec(),
            };
            SmoothnessSamples::new(x0, sampling, &ad)
        });
        Ok(TrajectoryObjective {
            rows: TrainingRows::new(&data, config.points_per_step, &ad),
            learned: LearnedPositions::new(&data, &ad),
            x0: data.canonical_tensor(&ad),
            warp_needs_jacobian: config.loss.elasticity_weight > 0.0 || (w_h > 0.0 && !separate_h),
            method: config.jacobian.method(),
            loss: config.loss.clone(),
            data,
            full,
            fit_rows,
            validation,
            ad,
            samples,
            host: None,
        })
    }

    /// The data term on frame `k` at time `t` over `rows` (none when the frame observes no
    /// training point): the penalised residual of the warped canonical points against
    /// their positions in frame `k`, and the warp, whose tangents `L_H` and elasticity may
    /// read.
    fn data_term<M: MotionField>(
        &self,
        field: &M,
        k: usize,
        t: f64,
        rows: StepRows,
    ) -> Option<(Tensor<1>, WarpOutput)> {
        let x0 = match &self.learned {
            None => self.x0.clone(),
            Some(l) => l.positions(self.x0.clone()),
        };
        // The frame's positions and weights made for this step, not kept: a tensor per
        // frame held through the fit costs more than the frame's values, and a long
        // recording's fit would hold its data several times over.
        let target = self.data.frame_tensor(k, &self.ad);
        let weights = self
            .data
            .weights_in_frame(k)
            .map(|w| Tensor::<2>::from_data(TensorData::new(w.to_vec(), [w.len(), 1]), &self.ad));
        let (x0, target, weights) = match rows {
            StepRows::All => (x0, target, weights),
            StepRows::Rows(rows) => (
                x0.select(0, (*rows).clone()),
                target.select(0, (*rows).clone()),
                weights.map(|w| w.select(0, *rows)),
            ),
            StepRows::Nothing => return None,
        };
        let method = self.method.as_ref();
        let warped = if self.warp_needs_jacobian {
            field.warp_dual(x0, t, method)
        } else {
            field.warp_values(x0, t, method)
        };
        let penalty = self.loss.penalty();
        let term = loss::trajectory_loss(warped.warped.value.clone(), target, penalty, weights);
        Some((term, warped))
    }

    /// `L_T` at frame `k`, unweighted ([`loss::acceleration`]): at every fitted track's
    /// canonical position (at most [`TEMPORAL_POINTS`] of them, drawn afresh), observed in
    /// frame `k` or not: the fill carries a track's residual across its gap, which is smooth
    /// only where the field's path is smooth on the seen frames too (docs/gap-filling.md).
    /// The three times are centred on `k`, moved inwards at the first and last frames.
    fn temporal_term<M: MotionField>(
        &self,
        field: &M,
        k: usize,
        rng: &mut ChaCha8Rng,
    ) -> Option<Tensor<1>> {
        let frames = self.data.frames();
        if frames < 3 {
            return None;
        }
        let centre = k.clamp(1, frames - 2);
        let delta = self.data.time(centre + 1) - self.data.time(centre);
        let x0 = match &self.learned {
            None => self.x0.clone(),
            Some(l) => l.positions(self.x0.clone()),
        };
        let n = self.data.points();
        let x0 = if n > TEMPORAL_POINTS {
            let rows = super::rows::step_rows(n, TEMPORAL_POINTS, rng);
            let rows = Tensor::<1, burn::tensor::Int>::from_data(
                TensorData::new(rows, [TEMPORAL_POINTS]),
                &self.ad,
            );
            x0.select(0, rows)
        } else {
            x0
        };
        let method = self.method.as_ref();
        let at = |j: usize| {
            field
                .warp_values(x0.clone(), self.data.time(j), method)
                .warped
                .value
        };
        Some(loss::acceleration(
            at(centre - 1),
            at(centre),
            at(centre + 1),
            delta,
        ))
    }

    /// `L_H` (Eq. 13) at time `t`, unweighted: on the step's own samples, or on the
    /// training points of the data term's warp `fitted`.
    fn smoothness_term<M: MotionField>(
        &mut self,
        field: &M,
        t: f64,
        fitted: Option<&WarpOutput>,
        rng: &mut ChaCha8Rng,
    ) -> Option<Tensor<1>> {
        let raw = match self.samples.as_mut() {
            Some(samples) => field.raw_dual(samples.step(rng), t, self.method.as_ref()),
            None => fitted?.raw.clone(),
        };
        let tangent = raw.tangent.expect("raw_dual yields tangents");
        Some(loss::smoothness(tangent, self.loss.smoothness_norm))
    }
}

impl<M: MotionField> Objective<M> for TrajectoryObjective<'_> {
    fn frames(&self) -> usize {
        self.data.frames()
    }

    /// The loss of frame `k`: data term + `w_H · L_H` + `w_E · elasticity`.
    fn step_loss(
        &mut self,
        field: &M,
        k: usize,
        _iteration: usize,
        rng: &mut ChaCha8Rng,
    ) -> Result<(Tensor<1>, Tensor<1>)> {
        let t = self.data.time(k);
        let rows = self.rows.step(&self.data, k, rng);
        let fitted = self.data_term(field, k, t, rows);
        let mut total = fitted.as_ref().map(|(term, _)| term.clone());
        let warp = fitted.as_ref().map(|(_, warp)| warp);
        let LossConfig {
            smoothness_weight: w_h,
            elasticity_weight: w_e,
            ..
        } = self.loss;
        if w_h > 0.0
            && let Some(h) = self.smoothness_term(field, t, warp, rng)
        {
            let h = h.mul_scalar(w_h);
            total = Some(match total {
                Some(d) => d + h,
                None => h,
            });
        }
        let w_t = self.loss.temporal_weight();
        if w_t > 0.0
            && let Some(l) = self.temporal_term(field, k, rng)
        {
            let l = l.mul_scalar(w_t);
            total = Some(match total {
                Some(d) => d + l,
                None => l,
            });
        }
        if w_e > 0.0
            && let Some(warp) = warp
        {
            let tangent = warp
                .warped
                .tangent
                .clone()
                .expect("warp_dual yields tangents");
            let e = loss::elasticity(tangent).mul_scalar(w_e);
            total = total.map(|d| d + e);
        }
        // A frame with no observed training point and no regulariser adds nothing: a zero
        // that is a tracked leaf, so that the step's backward pass runs and moves no
        // parameter (Adam skips a parameter without a gradient).
        let zero = || Tensor::<1>::zeros([1], &self.ad);
        let data = fitted.map_or_else(zero, |(term, _)| term);
        Ok((data, total.unwrap_or_else(|| zero().require_grad())))
    }

    /// Draws every step's rows and `L_H` samples now, in step order (each step's rows, then
    /// its samples, as `step_loss` would draw them), and uploads them in one transfer each,
    /// so that no step moves data to the device.
    fn prepare_iteration(&mut self, order: &[usize], rng: &mut ChaCha8Rng) {
        let draws = self.draw_iteration(order, rng);
        if self.host.is_some() {
            // The fused step reads them on the host.
            self.host = Some(draws);
            return;
        }
        self.rows.clear();
        if let Some(s) = self.samples.as_mut() {
            s.clear();
        }
        if let (Some(s), Some((points, per_step))) = (self.samples.as_mut(), draws.samples) {
            s.prepare(points, order.len(), per_step);
        }
        if let Some((rows, spans)) = draws.rows {
            self.rows.prepare(rows, spans);
        }
    }

    fn use_host_batches(&mut self) -> std::result::Result<(), String> {
        match self.host_refusal() {
            Some(why) => Err(why.into()),
            None => {
                self.host = Some(host::HostDraws::default());
                Ok(())
            }
        }
    }

    fn stop_host_batches(&mut self) {
        self.host = None;
    }

    fn host_batch(&mut self, k: usize, rng: &mut ChaCha8Rng) -> Option<HostBatch> {
        self.host
            .is_some()
            .then(|| TrajectoryObjective::host_batch(self, k, rng))
    }

    fn after_backward(&mut self, grads: &Gradients, lr: f64) {
        if let Some(l) = self.learned.as_mut() {
            l.update(grads, lr);
        }
    }

    fn state(&self) -> Result<Vec<f32>> {
        self.learned
            .as_ref()
            .map_or_else(|| Ok(Vec::new()), LearnedPositions::state)
    }

    fn restore_state(&mut self, state: &[f32]) -> Result<()> {
        match self.learned.as_mut() {
            Some(l) => l.restore(state),
            None if state.is_empty() => Ok(()),
            None => Err(crate::DomaError::InvalidData(format!(
                "the checkpoint holds {} learned values; this fit learns none",
                state.len()
            ))),
        }
    }

    fn learned_canonical(&self) -> Result<Option<Vec<f32>>> {
        let Some(l) = &self.learned else {
            return Ok(None);
        };
        // Rows of the fitted tracks, as rows of all the training tracks.
        let row = |r: usize| self.fit_rows.as_ref().map_or(r, |f| f[r]);
        l.canonical(self.full.canonical(), row).map(Some)
    }

    fn validation_epe(&self, field: &M) -> Result<Option<f64>> {
        match &self.validation {
            Some((tracks, device)) => crate::metrics::evaluate_epe(field, tracks, device).map(Some),
            None => Ok(None),
        }
    }
}

/// The seeded split of the training tracks for [`Convergence`]: the rows fitted and the
/// rows held back, both in increasing order. The held-back rows are drawn among the tracks
/// seen in the reference frame, whose canonical positions are observed, not learned.
fn held_back(data: &Trajectories, c: &Convergence, seed: u64) -> Result<(Vec<usize>, Vec<usize>)> {
    let eligible: Vec<usize> = match data.observed_in_frame(data.reference()) {
        Some(seen) => (0..data.points()).filter(|&i| seen[i]).collect(),
        None => (0..data.points()).collect(),
    };
    // Its own stream: neither the train/test split's nor the weight search's.
    let (_, held) = crate::data::sequence::split_indices(
        eligible.len(),
        1.0 - c.validation_fraction,
        seed ^ 0xC04E_26ED,
    )
    .map_err(|_| {
        crate::DomaError::InvalidConfig(format!(
            "holding back {} of {} tracks seen in the reference frame leaves no track to \
             validate on or none to fit",
            c.validation_fraction,
            eligible.len()
        ))
    })?;
    let mut held: Vec<usize> = held.into_iter().map(|j| eligible[j]).collect();
    held.sort_unstable();
    let mut is_held = vec![false; data.points()];
    for &i in &held {
        is_held[i] = true;
    }
    let fit = (0..data.points()).filter(|&i| !is_held[i]).collect();
    Ok((fit, held))
}

mod host;
#[cfg(test)]
mod tests;
