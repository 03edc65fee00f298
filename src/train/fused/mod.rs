//! The whole training step of a trajectory fit as one operation on raw CPU buffers
//! (docs/design.md §2.4): the SIREN forward with its spatial Jacobian (Eq. 1, 6), the
//! head `(A, u)` and the warp `y = A x + u` (Eq. 4, 10–12), the trajectory loss, `L_H`
//! (Eq. 13), their backward pass and Adam's update, with no autodiff graph and no tensor
//! dispatch in between.
//!
//! The composed step builds each of these from Burn's operations around the fused SIREN
//! op, some sixty small operations a step; on the CPU their dispatch costs as much as the
//! network itself. This step calls the same network code (`jacobian::analytic::cpu`) and
//! does the rest in loops over the step's few hundred rows.
//!
//! Burn stays the owner of the parameters: [`FusedStep::from_siren`] reads them, the
//! trainer writes them back after each iteration ([`FusedStep::write_back`]), and every
//! other path (evaluation, checkpoints, autodiff, wgpu, the baselines) is unchanged.
//! Where the step does not apply (another model, a GPU, a loss term it does not
//! compute), [`StepKind::Fused`] is refused with the reason ([`check`]).
//!
//! | file | what it holds |
//! |---|---|
//! | `head.rs` | the four heads and their backward on rows |
//! | `loss.rs` | the trajectory penalty and `L_H` on rows, with their gradients |
//! | `params.rs` | the parameters read from and written back into Burn's module |
//! | `adam.rs` | Adam's update as Burn computes it |
//! | `optimizer.rs` | the update a step applies (Adam or SOAP), and its checkpoint's kind |
//! | `soap/` | SOAP's update (Adam in Shampoo's eigenbasis), the fused step's alternative |
//! | `tests.rs` | against Burn's autodiff step, and finite differences in f64 |

mod adam;
mod head;
mod loss;
mod optimizer;
mod params;
mod soap;
#[cfg(test)]
mod tests;

pub use adam::{AdamSettings, AdamState};
pub use optimizer::{Optimizer, OptimizerKind, is_fused_state};
pub use soap::{SoapConfig, SoapState};

use burn::optim::AdamConfig;
use burn::tensor::Device;

use super::config::FitConfig;
use crate::field::Variant;
use crate::jacobian::JacobianKind;
use crate::jacobian::analytic::OpSpec;
use crate::jacobian::analytic::cpu::{Net, Real, serial};
use crate::loss::{DataPenalty, SmoothnessNorm};
use crate::siren::Siren;
use crate::{DomaError, Result};
use loss::{data_term, smoothness};
use params::read_params;

pub use crate::train::step::StepKind;

/// The float operations the step needs beyond the network's ([`Real`]).
pub(crate) trait Float: Real + std::ops::Div<Output = Self> + PartialOrd {
    fn sqrt(self) -> Self;
    fn exp(self) -> Self;
    fn ln_1p(self) -> Self;
    fn abs(self) -> Self;
    fn recip(self) -> Self;
    fn max(self, other: Self) -> Self;
    fn to_f64(self) -> f64;
}

macro_rules! float_impl {
    ($t:ty) => {
        impl Float for $t {
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            fn exp(self) -> Self {
                <$t>::exp(self)
            }
            fn ln_1p(self) -> Self {
                <$t>::ln_1p(self)
            }
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            fn recip(self) -> Self {
                <$t>::recip(self)
            }
            fn max(self, other: Self) -> Self {
                <$t>::max(self, other)
            }
            fn to_f64(self) -> f64 {
                self as f64
            }
        }
    };
}
float_impl!(f32);
float_impl!(f64);

/// Why the fused step cannot run a fit of `config` on `device`, if it cannot.
pub fn check(config: &FitConfig, device: &Device) -> Result<()> {
    let refuse = |why: &str| {
        Err(DomaError::InvalidConfig(format!(
            "the fused step cannot run this fit: {why}; use --step composed"
        )))
    };
    if !matches!(config.model, crate::field::model::ModelConfig::Doma(_)) {
        return refuse(&format!(
            "it computes DOMA fields only, not {}",
            config.model.paper_name()
        ));
    }
    if config.jacobian != JacobianKind::Analytic {
        return refuse("it uses the analytic Jacobian, and the fit asks for autodiff");
    }
    if !crate::backend::runs_on_cpu(device) {
        return refuse("it runs on the CPU backends (flex, ndarray) only");
    }
    let loss = &config.loss;
    if loss.elasticity_weight > 0.0 {
        return refuse("it does not compute the elasticity loss");
    }
    if loss.temporal_weight() > 0.0 {
        return refuse("it does not compute the temporal loss L_T");
    }
    if config.frames_per_step.is_some_and(|f| f > 1) {
        return refuse("it takes one frame per step");
    }
    adam_settings(&config.optimizer)
        .map(|_| ())
        .or_else(|e| refuse(&e))
}

/// Adam's `β₁, β₂, ε`, or why the fused update cannot reproduce `config`.
pub fn adam_settings(config: &AdamConfig) -> std::result::Result<AdamSettings, String> {
    // Burn's config keeps its fields private; its serialised form names them.
    let value = serde_json::to_value(config).map_err(|e| e.to_string())?;
    let get = |k: &str| value.get(k).filter(|v| !v.is_null());
    if get("weight_decay").is_some() || get("grad_clipping").is_some() {
        return Err("Adam with weight decay or gradient clipping is not fused".into());
    }
    if get("amsgrad").and_then(|v| v.as_bool()) == Some(true) {
        return Err("AMSGrad is not fused".into());
    }
    let f = |k: &str| {
        get(k)
            .and_then(|v| v.as_f64())
            .map(|v| v as f32)
            .ok_or_else(|| format!("Adam's config has no `{k}`"))
    };
    Ok(AdamSettings {
        beta_1: f("beta_1")?,
        beta_2: f("beta_2")?,
        epsilon: f("epsilon")?,
    })
}

/// What one step reads, on the host: the frame's time, the training rows' canonical
/// positions and targets, their confidence weights, and `L_H`'s own sample points.
#[derive(Clone, Copy, Debug)]
pub struct StepBatch<'a, E> {
    /// The frame's normalised time.
    pub time: f64,
    /// The training rows' canonical positions, `[n, 3]` (`n` may be 0).
    pub x0: &'a [E],
    /// Their positions in the frame, `[n, 3]`.
    pub target: &'a [E],
    /// Their weights, `[n]`, when the data has confidences.
    pub weights: Option<&'a [E]>,
    /// `L_H`'s sample points `[p, 3]`; `None` evaluates `L_H` on the training rows.
    pub samples: Option<&'a [E]>,
}

/// The losses of a step: the data term (reported) and the total (minimised).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepLosses {
    /// The trajectory loss.
    pub data: f64,
    /// The trajectory loss plus `w_H · L_H`.
    pub total: f64,
}

/// The loss terms the step computes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepLoss {
    /// The per-coordinate penalty of the trajectory loss.
    pub penalty: DataPenalty,
    /// `w_H`; 0 leaves `L_H` out.
    pub smoothness_weight: f64,
    /// How `L_H` treats each Jacobian entry.
    pub smoothness_norm: SmoothnessNorm,
}

/// A DOMA field's SIREN, its head and the optimiser's state on flat host buffers, and
/// the step.
#[derive(Clone, Debug)]
pub struct FusedStep<E> {
    variant: Variant,
    /// The factor on the frame's time that the SIREN reads ([`crate::field::MotionField::time_scale`]).
    time_scale: f64,
    /// The network's op without tangents, and with them.
    specs: [OpSpec; 2],
    loss: StepLoss,
    /// `[W_0, b_0, …, W_o, b_o]`, the layout of the analytic op.
    params: Vec<E>,
    optimizer: Optimizer<E>,
}

impl<E: Float + Send + Sync> FusedStep<E> {
    /// The step over `siren`'s current parameters (read back from the device), with
    /// `variant`'s head, `loss`'s terms and a fresh Adam.
    pub fn from_siren(
        siren: &Siren,
        variant: Variant,
        loss: StepLoss,
        adam: AdamSettings,
    ) -> Result<Self> {
        let params = read_params(siren)?;
        let len = params.len();
        Ok(FusedStep {
            variant,
            time_scale: 1.0,
            specs: [OpSpec::of(siren, false), OpSpec::of(siren, true)],
            loss,
            params,
            optimizer: Optimizer::Adam(AdamState::new(adam, len)),
        })
    }

    /// The same step for a field that reads its time scaled by `scale`
    /// ([`crate::field::MotionField::time_scale`]).
    pub fn with_time_scale(self, scale: f64) -> Self {
        FusedStep {
            time_scale: scale,
            ..self
        }
    }

    /// The flat parameters `[W_0, b_0, …, W_o, b_o]`.
    #[cfg(test)]
    pub fn params(&self) -> &[E] {
        &self.params
    }

    /// Replaces the flat parameters (same length).
    #[cfg(test)]
    pub fn set_params(&mut self, params: &[E]) {
        self.params.copy_from_slice(params);
    }

    /// Reads the parameters again from `siren` (after a checkpoint put them back).
    pub fn reload(&mut self, siren: &Siren) -> Result<()> {
        self.params = read_params(siren)?;
        Ok(())
    }

    fn spec(&self, dual: bool) -> &OpSpec {
        &self.specs[usize::from(dual)]
    }

    /// The step's losses and the gradient of the total with respect to the flat
    /// parameters; no gradient when the step has no term (a frame without a training row
    /// and without `L_H`), so that Adam moves nothing, as Burn's optimiser skips a
    /// parameter without a gradient.
    pub fn gradients(&self, batch: &StepBatch<'_, E>) -> (StepLosses, Option<Vec<E>>) {
        // The two network calls are independent until their gradients are summed: each
        // runs on its own thread, so that the second thread has work for the whole step
        // instead of being woken for each parallel region. When their sizes are close
        // (the fast recipe's 256 rows and 64 samples: 256 stacked rows each), each runs
        // whole on its thread; otherwise the smaller one's thread helps the larger.
        let rows = (batch.x0.len() / 3) * if self.rows_dual(batch) { 4 } else { 1 };
        let samples = if self.loss.smoothness_weight > 0.0 {
            batch.samples.map_or(0, |s| 4 * (s.len() / 3))
        } else {
            0
        };
        let balanced = rows.min(samples) > 0 && rows.max(samples) <= 2 * rows.min(samples);
        let (rows, samples) = rayon::join(
            || serial_if(balanced, || self.rows_term(batch)),
            || serial_if(balanced, || self.samples_term(batch)),
        );
        let mut losses = StepLosses {
            data: 0.0,
            total: 0.0,
        };
        let mut grad: Option<Vec<E>> = None;
        if let Some((data, total, g)) = rows {
            losses = StepLosses { data, total };
            grad = Some(g);
        }
        if let Some((h, g)) = samples {
            losses.total += h;
            grad = Some(match grad {
                None => g,
                Some(mut acc) => {
                    acc.iter_mut().zip(&g).for_each(|(a, b)| *a = *a + *b);
                    acc
                }
            });
        }
        (losses, grad)
    }

    /// The data term on the training rows (and `w_H · L_H` there, when it has no samples
    /// of its own): the data term, the total, and their gradient. `None` without rows.
    fn rows_term(&self, batch: &StepBatch<'_, E>) -> Option<(f64, f64, Vec<E>)> {
        let n = batch.x0.len() / 3;
        if n == 0 {
            return None;
        }
        let o = self.variant.outputs();
        let h_on_rows = self.rows_dual(batch);
        let net_spec = self.spec(h_on_rows);
        let net = Net::new(&self.params, net_spec);
        let input = with_time(batch.x0, self.time_scale * batch.time);
        let (out, acts) = net.forward(&input);
        let values = &out[..n * o];
        let mut y = vec![E::zero(); n * 3];
        head::warp(self.variant, values, batch.x0, &mut y);
        let (data, g_y) = data_term(&y, batch.target, batch.weights, self.loss.penalty);
        let mut g_out = vec![E::zero(); out.len()];
        head::warp_backward(self.variant, values, batch.x0, &g_y, &mut g_out[..n * o]);
        let mut total = data;
        if h_on_rows {
            total += smoothness(&out[n * o..], n, self.loss, &mut g_out[n * o..]);
        }
        let mut g = vec![E::zero(); self.params.len()];
        net.backward(&acts, &input, &g_out, false, &mut g);
        Some((data, total, g))
    }

    /// Whether the training rows carry tangents (`L_H` on them, without samples).
    fn rows_dual(&self, batch: &StepBatch<'_, E>) -> bool {
        self.loss.smoothness_weight > 0.0 && batch.samples.is_none()
    }

    /// `w_H · L_H` on the step's own samples, and its gradient. `None` without them.
    fn samples_term(&self, batch: &StepBatch<'_, E>) -> Option<(f64, Vec<E>)> {
        let samples = batch
            .samples
            .filter(|s| self.loss.smoothness_weight > 0.0 && !s.is_empty())?;
        let (p, o) = (samples.len() / 3, self.variant.outputs());
        let net_spec = self.spec(true);
        let net = Net::new(&self.params, net_spec);
        let input = with_time(samples, self.time_scale * batch.time);
        let (out, acts) = net.forward(&input);
        let mut g_out = vec![E::zero(); out.len()];
        let h = smoothness(&out[p * o..], p, self.loss, &mut g_out[p * o..]);
        let mut g = vec![E::zero(); self.params.len()];
        net.backward(&acts, &input, &g_out, false, &mut g);
        Some((h, g))
    }

    /// One step: the gradients of [`FusedStep::gradients`], then the optimiser's update
    /// at `lr`.
    pub fn step(&mut self, batch: &StepBatch<'_, E>, lr: f64) -> StepLosses {
        let (losses, grad) = self.gradients(batch);
        if let Some(g) = grad {
            self.optimizer.update(&mut self.params, &g, lr);
        }
        losses
    }
}

/// `f`, inside [`serial`] when `whole`.
fn serial_if<R>(whole: bool, f: impl FnOnce() -> R) -> R {
    if whole { serial(f) } else { f() }
}

/// `[x, y, z, t]` rows from `[x, y, z]` rows.
fn with_time<E: Float>(x: &[E], t: f64) -> Vec<E> {
    // Burn's `Tensor::full` casts the f64 time to the element type.
    let t = E::from_f64(t as f32 as f64);
    x.chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], t])
        .collect()
}

/// A step's inputs, owned ([`StepBatch`] borrows them).
#[derive(Clone, Debug, PartialEq)]
pub struct HostBatch {
    /// The frame's normalised time.
    pub time: f64,
    /// The training rows' canonical positions, `[n, 3]`.
    pub x0: Vec<f32>,
    /// Their positions in the frame, `[n, 3]`.
    pub target: Vec<f32>,
    /// Their weights, `[n]`.
    pub weights: Option<Vec<f32>>,
    /// `L_H`'s own sample points, `[p, 3]`.
    pub samples: Option<Vec<f32>>,
}

impl HostBatch {
    /// The batch, borrowed.
    pub fn batch(&self) -> StepBatch<'_, f32> {
        StepBatch {
            time: self.time,
            x0: &self.x0,
            target: &self.target,
            weights: self.weights.as_deref(),
            samples: self.samples.as_deref(),
        }
    }
}
