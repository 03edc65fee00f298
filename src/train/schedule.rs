//! The learning-rate schedule of a fit (the authors' LambdaLR, or a warm-up and a cosine
//! decay), Adam as the authors run it, and the stop on convergence.

use burn::config::Config;
use burn::optim::AdamConfig;

use crate::{DomaError, Result};

/// Adam as the authors run it: PyTorch's defaults, `ε = 1e-8`.
pub fn default_adam() -> AdamConfig {
    AdamConfig::new().with_epsilon(1e-8)
}

/// The shape of the learning rate after its flat (or warm-up) start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Decay {
    /// The authors' LambdaLR: a linear decay towards 0 at the end of the budget.
    Linear,
    /// A half cosine from the base rate towards 0 at the end of the budget.
    Cosine,
}

/// The learning-rate schedule: `iterations` passes over the frames, Adam's base rate, and
/// the authors' LambdaLR (flat, then a linear decay), or a linear warm-up followed by a
/// cosine decay for shorter budgets.
#[derive(Config, Debug, PartialEq)]
pub struct ScheduleConfig {
    /// Iterations (passes over all frames); the paper's budget is 1000.
    #[config(default = 1000)]
    pub iterations: usize,
    /// Adam's base learning rate (1e-4 for the DOMA variants).
    #[config(default = 1e-4)]
    pub learning_rate: f64,
    /// Iterations at the full learning rate before the linear decay (the authors' 10 for
    /// a fit, 0 for a registration).
    #[config(default = 10)]
    pub lr_flat_iterations: usize,
    /// The decay after the start (`None`: the authors' linear one; a config without the
    /// field reads as `None`).
    pub decay: Option<Decay>,
    /// With [`Decay::Cosine`]: iterations of linear warm-up from `lr / warmup` to `lr`
    /// (`None` or 0: none).
    pub warmup_iterations: Option<usize>,
}

impl ScheduleConfig {
    /// The learning-rate factor during iteration `e` (0-based): 1 for the first
    /// `lr_flat_iterations + 1` iterations, then a linear decay,
    /// `1 − (e − flat) / (iterations − flat + 1)` (the authors' LambdaLR).
    ///
    /// With [`Decay::Cosine`]: `(e + 1) / w` during the `w` warm-up iterations, then
    /// `½ (1 + cos(π (e − w) / (iterations − w)))`.
    pub fn lr_factor(&self, e: usize) -> f64 {
        if self.decay == Some(Decay::Cosine) {
            let warmup = self.warmup_iterations.unwrap_or(0);
            if e < warmup {
                return (e + 1) as f64 / warmup as f64;
            }
            let span = self.iterations.saturating_sub(warmup).max(1) as f64;
            let p = ((e - warmup) as f64 / span).min(1.0);
            return 0.5 * (1.0 + (std::f64::consts::PI * p).cos());
        }
        let flat = self.lr_flat_iterations;
        if e <= flat {
            1.0
        } else {
            1.0 - (e - flat) as f64 / (self.iterations + 1 - flat) as f64
        }
    }

    /// The learning rate during iteration `e`.
    pub fn learning_rate_at(&self, e: usize) -> f64 {
        self.learning_rate * self.lr_factor(e)
    }

    /// Refuses values that cannot run.
    pub fn validate(&self) -> Result<()> {
        if self.iterations == 0 {
            return Err(DomaError::InvalidConfig(
                "iterations must be at least 1".into(),
            ));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return Err(DomaError::InvalidConfig(format!(
                "learning rate {} must be positive",
                self.learning_rate
            )));
        }
        if self.decay == Some(Decay::Cosine)
            && self.warmup_iterations.unwrap_or(0) >= self.iterations
        {
            return Err(DomaError::InvalidConfig(format!(
                "{} warm-up iterations leave none of the {} to decay over",
                self.warmup_iterations.unwrap_or(0),
                self.iterations
            )));
        }
        Ok(())
    }
}

/// Stopping a fit once the EPE on held-back training tracks stops improving: usable on a
/// user's data, where no ground truth exists. The held-back tracks are not fitted.
///
/// In JSON, every field but `patience` may be left out (its default is used).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Convergence {
    /// Stop when the validation EPE has not improved for this many iterations.
    pub patience: usize,
    /// The fraction of the training tracks held back (drawn among those seen in the
    /// reference frame); default 0.1.
    #[serde(default = "Convergence::default_fraction")]
    pub validation_fraction: f64,
    /// Iterations between two validation EPEs; default 10.
    #[serde(default = "Convergence::default_every")]
    pub every: usize,
    /// The relative drop below the best EPE so far that counts as an improvement; default
    /// 0.01.
    #[serde(default = "Convergence::default_min_improvement")]
    pub min_improvement: f64,
    /// Iterations of cool-down after the plateau: the learning rate falls linearly from its
    /// value there towards 0, then the fit stops (`None`: as many as `patience`; 0: stop at
    /// the plateau). Most of a fit's error goes during a decay, so stopping on a plateau
    /// at a high rate would keep a rough field.
    #[serde(default)]
    pub cooldown: Option<usize>,
}

impl Convergence {
    fn default_fraction() -> f64 {
        0.1
    }
    fn default_every() -> usize {
        10
    }
    fn default_min_improvement() -> f64 {
        0.01
    }

    /// Stop after `patience` iterations without improvement; the other fields at their
    /// defaults.
    pub fn new(patience: usize) -> Self {
        Convergence {
            patience,
            validation_fraction: Self::default_fraction(),
            every: Self::default_every(),
            min_improvement: Self::default_min_improvement(),
            cooldown: None,
        }
    }

    /// Sets the cool-down after the plateau.
    pub fn with_cooldown(mut self, cooldown: Option<usize>) -> Self {
        self.cooldown = cooldown;
        self
    }

    /// The cool-down in iterations (`patience` unless set).
    pub fn cooldown_iterations(&self) -> usize {
        self.cooldown.unwrap_or(self.patience)
    }

    /// Sets the held-back fraction.
    pub fn with_validation_fraction(mut self, fraction: f64) -> Self {
        self.validation_fraction = fraction;
        self
    }

    /// Sets the iterations between two validation EPEs.
    pub fn with_every(mut self, every: usize) -> Self {
        self.every = every;
        self
    }

    /// Sets the relative improvement that counts.
    pub fn with_min_improvement(mut self, min_improvement: f64) -> Self {
        self.min_improvement = min_improvement;
        self
    }

    /// Refuses a zero patience or period, and a fraction outside (0, 1).
    pub fn validate(&self) -> Result<()> {
        if self.patience == 0 || self.every == 0 {
            return Err(DomaError::InvalidConfig(
                "the patience and the validation period must be at least 1 iteration".into(),
            ));
        }
        if !(self.validation_fraction > 0.0 && self.validation_fraction < 1.0) {
            return Err(DomaError::InvalidConfig(format!(
                "the validation fraction {} is not strictly between 0 and 1",
                self.validation_fraction
            )));
        }
        if !(self.min_improvement.is_finite() && (0.0..1.0).contains(&self.min_improvement)) {
            return Err(DomaError::InvalidConfig(format!(
                "the minimum improvement {} is not in [0, 1)",
                self.min_improvement
            )));
        }
        Ok(())
    }

    /// The iteration count at which the validation curve `epes` (iteration count after
    /// which each EPE was measured, EPE) first reached its plateau: its best EPE so far
    /// (each improvement at least `min_improvement` below the previous best) `patience`
    /// iterations or more behind the measurement. One pass over the curve.
    pub fn plateau(&self, epes: impl IntoIterator<Item = (usize, f64)>) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for (done, epe) in epes {
            let improved = match best {
                None => epe.is_finite(),
                Some((_, b)) => epe < b * (1.0 - self.min_improvement),
            };
            if improved {
                best = Some((done, epe));
            }
            if let Some((at, _)) = best
                && done - at >= self.patience
            {
                return Some(done);
            }
        }
        None
    }

    /// Whether the curve `epes` has reached a plateau ([`Convergence::plateau`]).
    pub fn converged(&self, epes: impl IntoIterator<Item = (usize, f64)>) -> bool {
        self.plateau(epes).is_some()
    }
}
