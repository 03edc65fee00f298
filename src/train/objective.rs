//! What one step of the loop minimises. The loop ([`super::Trainer`]) owns the frame
//! order, the schedule, Adam and the random stream; an [`Objective`] turns the field and
//! a frame into losses.

use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::config::{FitConfig, LossConfig, SmoothnessSampling};
use super::record::gaussian;
use crate::Result;
use crate::data::Trajectories;
use crate::field::MotionField;
use crate::jacobian::JacobianMethod;
use crate::loss;

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
}

/// Fitting trajectories (Sec. 3; REFERENCE §5): the trajectory L1 of the training points
/// in frame `k`, plus `w_H · L_H` (Eq. 13) and `w_E ·` elasticity.
pub struct TrajectoryObjective<'a> {
    data: &'a Trajectories,
    loss: LossConfig,
    sampling: SmoothnessSampling,
    method: Box<dyn JacobianMethod>,
    ad: Device,
    x0_host: Vec<f32>,
    x0: Tensor<2>,
    targets: Vec<Tensor<2>>,
    separate_h: bool,
    warp_needs_jacobian: bool,
    /// The `L_H` samples of the current iteration, drawn at its start and uploaded at once
    /// (`[steps · n, 3]`), with `n` and the next step's index into them.
    prepared: Option<(Tensor<2>, usize, usize)>,
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
        let method = config.jacobian.method();
        let ad = device.clone().autodiff();
        let sampling = config.smoothness_sampling.clone();
        let w_h = config.loss.smoothness_weight;
        // L_H gets its own points when they differ from the training points.
        let separate_h = w_h > 0.0
            && (sampling.jitter > 0.0 || sampling.max_points.is_some_and(|m| m < data.points()));
        let warp_needs_jacobian = config.loss.elasticity_weight > 0.0 || (w_h > 0.0 && !separate_h);
        Ok(TrajectoryObjective {
            data,
            loss: config.loss.clone(),
            sampling,
            method,
            x0_host: data.frame(0).to_vec(),
            x0: data.frame_tensor(0, &ad),
            targets: (0..data.frames())
                .map(|k| data.frame_tensor(k, &ad))
                .collect(),
            ad,
            separate_h,
            warp_needs_jacobian,
            prepared: None,
        })
    }
}

impl<M: MotionField> Objective<M> for TrajectoryObjective<'_> {
    fn frames(&self) -> usize {
        self.data.frames()
    }

    /// Draws every step's `L_H` samples now, in step order, and uploads them in one
    /// transfer, so that no step moves data to the device.
    fn prepare_iteration(&mut self, order: &[usize], rng: &mut ChaCha8Rng) {
        self.prepared = None;
        if !(self.separate_h && self.loss.smoothness_weight > 0.0) || order.is_empty() {
            return;
        }
        let mut all = Vec::new();
        let mut n = 0;
        for _ in order {
            let (pts, rows) = smoothness_samples(&self.x0_host, &self.sampling, rng);
            all.extend(pts);
            n = rows;
        }
        let rows = order.len() * n;
        let pts = Tensor::<2>::from_data(TensorData::new(all, [rows, 3]), &self.ad);
        self.prepared = Some((pts, n, 0));
    }

    fn step_loss(
        &mut self,
        field: &M,
        k: usize,
        _iteration: usize,
        rng: &mut ChaCha8Rng,
    ) -> Result<(Tensor<1>, Tensor<1>)> {
        let method = self.method.as_ref();
        let t = self.data.time(k);
        let out = if self.warp_needs_jacobian {
            field.warp_dual(self.x0.clone(), t, method)
        } else {
            field.warp_values(self.x0.clone(), t, method)
        };
        let l1 = loss::trajectory_l1(out.warped.value, self.targets[k].clone());
        let mut total = l1.clone();
        let w = &self.loss;
        if w.smoothness_weight > 0.0 {
            let raw = if self.separate_h {
                let pts = match self.prepared.as_mut() {
                    Some((all, n, next)) if (*next + 1) * *n <= all.dims()[0] => {
                        *next += 1;
                        all.clone().narrow(0, (*next - 1) * *n, *n)
                    }
                    // A step outside `Trainer::iteration` (benchmarks): drawn here.
                    _ => {
                        let (pts, n) = smoothness_samples(&self.x0_host, &self.sampling, rng);
                        Tensor::<2>::from_data(TensorData::new(pts, [n, 3]), &self.ad)
                    }
                };
                field.raw_dual(pts, t, method)
            } else {
                out.raw
            };
            let tangent = raw.tangent.expect("raw_dual yields tangents");
            total = total
                + loss::smoothness(tangent, w.smoothness_norm).mul_scalar(w.smoothness_weight);
        }
        if w.elasticity_weight > 0.0 {
            let tangent = out.warped.tangent.expect("warp_dual yields tangents");
            total = total + loss::elasticity(tangent).mul_scalar(w.elasticity_weight);
        }
        Ok((l1, total))
    }
}

/// Draws the `L_H` sample points: a random subset of at most `max_points` rows of `x0`
/// (`[N, 3]`, host), jittered by Gaussian noise.
fn smoothness_samples(
    x0: &[f32],
    sampling: &SmoothnessSampling,
    rng: &mut impl Rng,
) -> (Vec<f32>, usize) {
    let n = x0.len() / 3;
    let mut rows: Vec<usize> = (0..n).collect();
    let take = sampling.max_points.map_or(n, |m| m.min(n));
    if take < n {
        rows.shuffle(rng);
        rows.truncate(take);
    }
    let sigma = sampling.jitter;
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
