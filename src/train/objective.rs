//! What one step of the loop minimises. The loop ([`super::Trainer`]) owns the frame
//! order, the schedule, Adam and the random stream; an [`Objective`] turns the field and
//! a frame into losses.

use std::borrow::Cow;

use burn::tensor::{Device, Gradients, IndexingUpdateOp, Int, Tensor, TensorData};
use rand::Rng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::config::{Convergence, FitConfig, LossConfig, SmoothnessSampling};
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

/// Adam's moment decays and ε for the learned canonical positions: the field's own
/// ([`super::config::default_adam`]).
const ADAM: (f64, f64, f64) = (0.9, 0.999, 1e-8);

/// The canonical positions of the training tracks not observed in the reference frame,
/// learned with the field (docs/design.md §7): `x = x_placed + δ`, one `δ` per track,
/// updated by Adam at the field's learning rate.
struct LearnedPositions {
    /// The tracks' rows `[M]`.
    rows: Tensor<1, Int>,
    /// `δ`, `[M, 3]`, an autodiff leaf.
    delta: Tensor<2>,
    /// Adam's first and second moments (off the graph), and its steps.
    moments: Option<(Tensor<2>, Tensor<2>)>,
    steps: usize,
}

/// Fitting trajectories (Sec. 3; docs/reference.md §5): the trajectory L1 of the training points
/// in frame `k`, plus `w_H · L_H` (Eq. 13) and `w_E ·` elasticity.
pub struct TrajectoryObjective<'a> {
    /// The fitted tracks: all the training tracks, or those not held back.
    data: Cow<'a, Trajectories>,
    /// All the training tracks, and the rows of the fitted ones when some are held back.
    full: &'a Trajectories,
    fit_rows: Option<Vec<usize>>,
    /// The held-back tracks of [`Convergence`], and the device that evaluates them.
    validation: Option<(Trajectories, Device)>,
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
    /// Training points per step when fewer than all (`FitConfig::points_per_step`).
    subset: Option<usize>,
    /// The rows of each step of the current iteration, all steps' end to end, each step's
    /// `(start, len)` in them, and the next step's index.
    prepared_rows: Option<PreparedRows>,
    /// Each frame's observed training rows on the device, where a frame has unobserved
    /// ones (`Some(None)` when it has none observed).
    frame_rows: Vec<Option<Option<Tensor<1, Int>>>>,
    /// Each frame's confidence weights `[N, 1]`, when the data has them.
    frame_weights: Option<Vec<Tensor<2>>>,
    /// The learned canonical positions of tracks unseen in the reference frame.
    learned: Option<LearnedPositions>,
}

/// The rows of an iteration's steps end to end, each step's `(start, len)` in them, and
/// the next step's index.
type PreparedRows = (Tensor<1, Int>, Vec<(usize, usize)>, usize);

/// The training rows of one step.
enum StepRows {
    /// Every training point.
    All,
    /// These rows.
    Rows(Box<Tensor<1, Int>>),
    /// None: the frame has no observed training point.
    Nothing,
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
        let method = config.jacobian.method();
        let ad = device.clone().autodiff();
        let sampling = config.smoothness_sampling.clone();
        let w_h = config.loss.smoothness_weight;
        let masked = data.observed().is_some();
        // L_H gets its own points when they differ from the training points: with a mask,
        // the points observed in the reference frame.
        let separate_h = w_h > 0.0
            && (masked
                || sampling.jitter > 0.0
                || sampling.max_points.is_some_and(|m| m < data.points()));
        let warp_needs_jacobian = config.loss.elasticity_weight > 0.0 || (w_h > 0.0 && !separate_h);
        let canonical = data.canonical();
        let x0_host = match data.observed_in_frame(data.reference()) {
            Some(seen) => (0..data.points())
                .filter(|&i| seen[i])
                .flat_map(|i| canonical[3 * i..3 * i + 3].iter().copied())
                .collect(),
            None => canonical.to_vec(),
        };
        let frame_rows = (0..data.frames())
            .map(|k| {
                let seen = data.observed_in_frame(k)?;
                if seen.iter().all(|&o| o) {
                    return None;
                }
                let rows: Vec<i64> = (0..data.points())
                    .filter(|&i| seen[i])
                    .map(|i| i as i64)
                    .collect();
                let len = rows.len();
                Some(
                    (len > 0)
                        .then(|| Tensor::<1, Int>::from_data(TensorData::new(rows, [len]), &ad)),
                )
            })
            .collect();
        // Tracks unseen in the reference frame start where their neighbours' motion places
        // them, and learn their canonical position with the field.
        let learned = data.observed_in_frame(data.reference()).and_then(|seen| {
            let rows: Vec<i64> = (0..data.points())
                .filter(|&i| !seen[i])
                .map(|i| i as i64)
                .collect();
            let m = rows.len();
            (m > 0).then(|| LearnedPositions {
                rows: Tensor::<1, Int>::from_data(TensorData::new(rows, [m]), &ad),
                delta: Tensor::<2>::zeros([m, 3], &ad).require_grad(),
                moments: None,
                steps: 0,
            })
        });
        let frame_weights = data.weights_in_frame(0).map(|_| {
            (0..data.frames())
                .map(|k| {
                    let w = data.weights_in_frame(k).expect("weights in every frame");
                    Tensor::<2>::from_data(TensorData::new(w.to_vec(), [w.len(), 1]), &ad)
                })
                .collect()
        });
        let x0 = data.canonical_tensor(&ad);
        let subset = config.points_per_step.filter(|&k| k < data.points());
        let targets = (0..data.frames())
            .map(|k| data.frame_tensor(k, &ad))
            .collect();
        Ok(TrajectoryObjective {
            data,
            full,
            fit_rows,
            validation,
            loss: config.loss.clone(),
            sampling,
            method,
            x0_host,
            x0,
            targets,
            ad,
            separate_h,
            warp_needs_jacobian,
            prepared: None,
            subset,
            prepared_rows: None,
            frame_rows,
            frame_weights,
            learned,
        })
    }
}

impl<M: MotionField> Objective<M> for TrajectoryObjective<'_> {
    fn frames(&self) -> usize {
        self.data.frames()
    }

    fn after_backward(&mut self, grads: &Gradients, lr: f64) {
        self.learn_positions(grads, lr);
    }

    /// `δ`, then Adam's two moments (zeros before the first step), then the step count.
    fn state(&self) -> Result<Vec<f32>> {
        let Some(l) = &self.learned else {
            return Ok(Vec::new());
        };
        let mut out: Vec<f32> = crate::readback::to_vec(l.delta.clone().inner())?;
        let n = out.len();
        match &l.moments {
            Some((m, v)) => {
                out.extend(crate::readback::to_vec::<f32, 2, _>(m.clone())?);
                out.extend(crate::readback::to_vec::<f32, 2, _>(v.clone())?);
            }
            None => out.extend(std::iter::repeat_n(0.0, 2 * n)),
        }
        out.push(l.steps as f32);
        Ok(out)
    }

    fn restore_state(&mut self, state: &[f32]) -> Result<()> {
        let Some(l) = self.learned.as_mut() else {
            return if state.is_empty() {
                Ok(())
            } else {
                Err(crate::DomaError::InvalidData(format!(
                    "the checkpoint holds {} learned values; this fit learns none",
                    state.len()
                )))
            };
        };
        let m = l.rows.dims()[0];
        if state.len() != 9 * m + 1 {
            return Err(crate::DomaError::InvalidData(format!(
                "the checkpoint holds {} values for the learned positions of {m} tracks",
                state.len()
            )));
        }
        let part = |i: usize| {
            Tensor::<2>::from_data(
                TensorData::new(state[3 * m * i..3 * m * (i + 1)].to_vec(), [m, 3]),
                &self.ad,
            )
            .inner()
        };
        l.steps = state[9 * m] as usize;
        l.delta = part(0).autodiff().require_grad();
        l.moments = (l.steps > 0).then(|| (part(1), part(2)));
        Ok(())
    }

    fn learned_canonical(&self) -> Result<Option<Vec<f32>>> {
        let Some(l) = &self.learned else {
            return Ok(None);
        };
        let delta: Vec<f32> = crate::readback::to_vec(l.delta.clone().inner())?;
        let rows: Vec<i64> = crate::readback::to_vec(l.rows.clone())?;
        // Rows of the fitted tracks, as rows of all the training tracks.
        let row = |r: usize| self.fit_rows.as_ref().map_or(r, |f| f[r]);
        let mut x = self.full.canonical().to_vec();
        for (j, &r) in rows.iter().enumerate() {
            let i = row(r as usize);
            for c in 0..3 {
                x[3 * i + c] += delta[3 * j + c];
            }
        }
        Ok(Some(x))
    }

    fn validation_epe(&self, field: &M) -> Result<Option<f64>> {
        match &self.validation {
            Some((tracks, device)) => crate::metrics::evaluate_epe(field, tracks, device).map(Some),
            None => Ok(None),
        }
    }

    /// Draws every step's `L_H` samples now, in step order, and uploads them in one
    /// transfer, so that no step moves data to the device.
    fn prepare_iteration(&mut self, order: &[usize], rng: &mut ChaCha8Rng) {
        self.prepared = None;
        self.prepared_rows = None;
        let h = self.separate_h && self.loss.smoothness_weight > 0.0;
        if !(h || self.subset.is_some()) || order.is_empty() {
            return;
        }
        let (mut all, mut rows_all, mut spans) = (Vec::new(), Vec::new(), Vec::new());
        let mut n = 0;
        // Per step: its training rows, then its L_H samples, as `step_loss` draws them.
        for &k in order {
            if let Some(take) = self.subset {
                let start = rows_all.len();
                rows_all.extend(self.draw_rows(k, take, rng));
                spans.push((start, rows_all.len() - start));
            }
            if h {
                let (pts, rows) = smoothness_samples(&self.x0_host, &self.sampling, rng);
                all.extend(pts);
                n = rows;
            }
        }
        if h {
            let rows = order.len() * n;
            let pts = Tensor::<2>::from_data(TensorData::new(all, [rows, 3]), &self.ad);
            self.prepared = Some((pts, n, 0));
        }
        if self.subset.is_some() {
            let len = rows_all.len();
            let rows = Tensor::<1, Int>::from_data(TensorData::new(rows_all, [len]), &self.ad);
            self.prepared_rows = Some((rows, spans, 0));
        }
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
        let rows = match self.subset {
            None => match &self.frame_rows[k] {
                None => StepRows::All,
                Some(Some(rows)) => StepRows::Rows(Box::new(rows.clone())),
                Some(None) => StepRows::Nothing,
            },
            Some(n) => {
                let prepared = match self.prepared_rows.as_mut() {
                    Some((all, spans, next)) if *next < spans.len() => {
                        *next += 1;
                        let (start, len) = spans[*next - 1];
                        (len > 0).then(|| all.clone().narrow(0, start, len))
                    }
                    // A step outside `Trainer::iteration` (benchmarks): drawn here.
                    _ => {
                        let rows = self.draw_rows(k, n, rng);
                        let len = rows.len();
                        (len > 0).then(|| {
                            Tensor::<1, Int>::from_data(TensorData::new(rows, [len]), &self.ad)
                        })
                    }
                };
                prepared.map_or(StepRows::Nothing, |r| StepRows::Rows(Box::new(r)))
            }
        };
        let mut total: Option<Tensor<1>> = None;
        let mut l1 = None;
        let mut out = None;
        let weights = self.frame_weights.as_ref().map(|w| w[k].clone());
        let x0_all = match &self.learned {
            None => self.x0.clone(),
            Some(l) => {
                let offsets = Tensor::<2>::zeros(self.x0.dims(), &self.ad).select_assign(
                    0,
                    l.rows.clone(),
                    l.delta.clone(),
                    IndexingUpdateOp::Add,
                );
                self.x0.clone() + offsets
            }
        };
        if let Some((x0, target, weights)) = match rows {
            StepRows::All => Some((x0_all, self.targets[k].clone(), weights)),
            StepRows::Rows(rows) => Some((
                x0_all.select(0, (*rows).clone()),
                self.targets[k].clone().select(0, (*rows).clone()),
                weights.map(|w| w.select(0, *rows)),
            )),
            StepRows::Nothing => None,
        } {
            let warped = if self.warp_needs_jacobian {
                field.warp_dual(x0, t, method)
            } else {
                field.warp_values(x0, t, method)
            };
            let data_term = loss::trajectory_loss(
                warped.warped.value.clone(),
                target,
                self.loss.penalty(),
                weights,
            );
            total = Some(data_term.clone());
            l1 = Some(data_term);
            out = Some(warped);
        }
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
                Some(field.raw_dual(pts, t, method))
            } else {
                out.as_ref().map(|o| o.raw.clone())
            };
            if let Some(raw) = raw {
                let tangent = raw.tangent.expect("raw_dual yields tangents");
                let h =
                    loss::smoothness(tangent, w.smoothness_norm).mul_scalar(w.smoothness_weight);
                total = Some(match total {
                    Some(t) => t + h,
                    None => h,
                });
            }
        }
        if w.elasticity_weight > 0.0
            && let Some(out) = &out
        {
            let tangent = out
                .warped
                .tangent
                .clone()
                .expect("warp_dual yields tangents");
            let e = loss::elasticity(tangent).mul_scalar(w.elasticity_weight);
            total = total.map(|t| t + e);
        }
        // A frame with no observed training point and no regulariser contributes nothing.
        let zero = || Tensor::<1>::zeros([1], &self.ad);
        Ok((l1.unwrap_or_else(zero), total.unwrap_or_else(zero)))
    }
}

impl TrajectoryObjective<'_> {
    /// Adam's update of the learned positions from this step's gradient, on the device.
    fn learn_positions(&mut self, grads: &Gradients, lr: f64) {
        let Some(l) = self.learned.as_mut() else {
            return;
        };
        let Some(g) = l.delta.grad(grads) else {
            return;
        };
        let (b1, b2, eps) = ADAM;
        let (m, v) = match l.moments.take() {
            Some((m, v)) => (m, v),
            None => (g.zeros_like(), g.zeros_like()),
        };
        let m = m.mul_scalar(b1) + g.clone().mul_scalar(1.0 - b1);
        let v = v.mul_scalar(b2) + g.square().mul_scalar(1.0 - b2);
        l.steps += 1;
        let t = l.steps as i32;
        let step = m
            .clone()
            .div_scalar(1.0 - b1.powi(t))
            .div(
                v.clone()
                    .div_scalar(1.0 - b2.powi(t))
                    .sqrt()
                    .add_scalar(eps),
            )
            .mul_scalar(lr);
        l.delta = (l.delta.clone().inner() - step).autodiff().require_grad();
        l.moments = Some((m, v));
    }

    /// A step's training rows on frame `k`: `take` distinct rows of all the training points
    /// when the frame observes all of them, else of its observed ones (fewer when it has
    /// fewer).
    fn draw_rows(&self, k: usize, take: usize, rng: &mut ChaCha8Rng) -> Vec<i64> {
        match (&self.frame_rows[k], self.data.observed_in_frame(k)) {
            (Some(_), Some(seen)) => {
                let rows: Vec<usize> = (0..seen.len()).filter(|&i| seen[i]).collect();
                step_rows(rows.len(), take.min(rows.len()), rng)
                    .into_iter()
                    .map(|r| rows[r as usize] as i64)
                    .collect()
            }
            _ => step_rows(self.data.points(), take, rng),
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

/// A step's training rows: `k` distinct rows of `n`, drawn uniformly.
fn step_rows(n: usize, k: usize, rng: &mut impl Rng) -> Vec<i64> {
    rand::seq::index::sample(rng, n, k)
        .into_iter()
        .map(|i| i as i64)
        .collect()
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

#[cfg(test)]
mod tests {
    use burn::module::Module;
    use rand::SeedableRng;

    use super::*;
    use crate::field::{DomaFieldConfig, Variant};
    use crate::jacobian::JacobianKind;
    use crate::siren::WithSirenShape;

    /// 40 points moving on their own paths over 3 frames.
    fn data() -> Trajectories {
        let (t, n) = (3, 40);
        let pos = (0..t * n * 3)
            .map(|i| ((i * 7919 % 113) as f32 / 113.0) - 0.5)
            .collect();
        Trajectories::new(t, n, pos).unwrap()
    }

    #[test]
    fn points_per_step_takes_distinct_rows_and_the_l1_over_them_alone() {
        let data = data();
        let device = Device::flex();
        let config = FitConfig::doma(DomaFieldConfig::new(Variant::Trans).with_hidden(16))
            .with_jacobian(JacobianKind::Autodiff)
            .with_points_per_step(Some(7));
        let field = config
            .model
            .init(0, data.frame(0), &device.clone().autodiff());
        let mut objective = TrajectoryObjective::new(&field, &config, &data, &device).unwrap();
        let order = [2, 0, 1];
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        Objective::<crate::field::model::Model>::prepare_iteration(
            &mut objective,
            &order,
            &mut rng,
        );
        // The rows a step would draw for itself from the same stream: the same rows.
        let mut replay = ChaCha8Rng::seed_from_u64(5);
        let drawn: Vec<Vec<i64>> = order
            .iter()
            .map(|_| step_rows(40, 7, &mut replay))
            .collect();
        let (rows, _, _) = objective.prepared_rows.clone().unwrap();
        let rows: Vec<i64> = crate::readback::to_vec(rows).unwrap();
        assert_eq!(rows, drawn.concat());
        for step in &drawn {
            let distinct: std::collections::BTreeSet<_> = step.iter().collect();
            assert_eq!(distinct.len(), 7);
            assert!(step.iter().all(|&r| (0..40).contains(&r)));
        }
        // Each step's L1 is the mean |y − ŷ| over its 7 rows' 21 coordinates, computed here
        // on the host from the field's prediction of every point.
        let inference = field.clone().valid();
        for (s, &k) in order.iter().enumerate() {
            let (l1, _) = objective.step_loss(&field, k, 0, &mut rng).unwrap();
            let l1 = crate::readback::to_vec::<f64, 1, _>(l1).unwrap()[0];
            let all: Vec<f32> = crate::readback::to_vec(
                inference.warp(data.frame_tensor(0, &device), data.time(k)),
            )
            .unwrap();
            let target = data.frame(k);
            let expected = drawn[s]
                .iter()
                .flat_map(|&r| (0..3).map(move |c| 3 * r as usize + c))
                .map(|i| (all[i] - target[i]).abs() as f64)
                .sum::<f64>()
                / 21.0;
            assert!(
                (l1 - expected).abs() < 1e-6 * expected.max(1.0),
                "{l1} vs {expected}"
            );
        }
    }

    #[test]
    fn a_masked_frame_s_l1_is_over_its_observed_rows_and_an_empty_frame_s_is_zero() {
        let full = data();
        let mut observed = vec![true; 3 * 40];
        // Frame 1 observes the even rows only; frame 2 observes none.
        for i in 0..40 {
            observed[40 + i] = i % 2 == 0;
            observed[80 + i] = false;
        }
        let masked = crate::data::tracks::Tracks::new(3, 40, full.positions().to_vec(), observed)
            .unwrap()
            .into_trajectories(Some(0))
            .unwrap();
        let device = Device::flex();
        let config = FitConfig::doma(DomaFieldConfig::new(Variant::Trans).with_hidden(16))
            .with_jacobian(JacobianKind::Autodiff);
        let field = config
            .model
            .init(0, masked.canonical(), &device.clone().autodiff());
        let mut objective = TrajectoryObjective::new(&field, &config, &masked, &device).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let inference = field.clone().valid();
        let all: Vec<f32> = crate::readback::to_vec(
            inference.warp(masked.canonical_tensor(&device), masked.time(1)),
        )
        .unwrap();
        let target = full.frame(1);
        let expected = (0..40)
            .step_by(2)
            .flat_map(|r| (0..3).map(move |c| 3 * r + c))
            .map(|i| (all[i] - target[i]).abs() as f64)
            .sum::<f64>()
            / 60.0;
        let (l1, _) = objective.step_loss(&field, 1, 0, &mut rng).unwrap();
        let l1 = crate::readback::to_vec::<f64, 1, _>(l1).unwrap()[0];
        assert!(
            (l1 - expected).abs() < 1e-6 * expected.max(1.0),
            "{l1} vs {expected}"
        );
        let (l1, total) = objective.step_loss(&field, 2, 0, &mut rng).unwrap();
        let read = |t| crate::readback::to_vec::<f64, 1, _>(t).unwrap()[0];
        assert_eq!((read(l1), read(total)), (0.0, 0.0));
    }

    /// What `Trainer::step_frames` minimises: the sum of the frames' losses, whose
    /// gradient is the sum of theirs.
    #[test]
    fn the_gradient_of_a_batch_of_frames_is_the_sum_of_theirs() {
        let data = data();
        let device = Device::flex();
        let ad = device.clone().autodiff();
        let config = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity).with_hidden(16))
            .with_jacobian(JacobianKind::Analytic);
        let field = DomaFieldConfig::new(Variant::Affinity)
            .with_hidden(16)
            .init(1, &ad);
        let mut objective = TrajectoryObjective::new(&field, &config, &data, &device).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut loss = |k: usize| objective.step_loss(&field, k, 0, &mut rng).unwrap().1;
        let grad = |total: Tensor<1>| -> Vec<f64> {
            let grads = total.backward();
            let layer = &field.siren.sine[0];
            crate::readback::to_vec(layer.weight.val().grad(&grads).expect("a gradient")).unwrap()
        };
        let (g0, g2) = (grad(loss(0)), grad(loss(2)));
        let batch = grad(loss(0) + loss(2));
        for ((a, b), s) in g0.iter().zip(&g2).zip(&batch) {
            assert!(
                (a + b - s).abs() <= 1e-6 * (1.0 + s.abs()),
                "{a} + {b} vs {s}"
            );
        }
    }
}
