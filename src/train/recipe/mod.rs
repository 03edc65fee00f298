//! Named recipes: the paper's protocol, and cheaper steps on a steeper schedule that reach
//! its error sooner (docs/speed.md, "Time to accuracy"). A recipe rewrites the fields of a
//! [`FitConfig`]; the result is saved in `config.json` like any other setting, so a run's
//! folder says exactly what ran.

use serde::{Deserialize, Serialize};

use super::config::FitConfig;
use super::schedule::{Convergence, Decay};

/// A named set of fit settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Recipe {
    /// The paper's protocol: 1000 iterations of one frame per Adam step at `1e-4`, the
    /// authors' linear decay, every training point and every `L_H` sample. The default.
    Paper,
    /// The same budget at 1.5 times the learning rate, with a warm-up and a cosine decay,
    /// on 256 training points and 64 `L_H` samples per step: a lower held-out error than
    /// the paper's protocol on the synthetic benchmark and the shipped sequences, in a
    /// third to a quarter of the time (docs/speed.md, "Time to accuracy").
    Fast,
    /// `Fast`'s sampling and schedule shape over 400 iterations at 3 times the paper's
    /// learning rate, stepped by SOAP (Adam in the eigenbasis of Shampoo's factors,
    /// [`super::SoapConfig`]) in the fused step: the authors' error on the synthetic
    /// benchmark over fifteen times sooner than the paper's protocol, and a held-out error
    /// a quarter to a half lower on the shipped sequences with thousands of tracks; on
    /// clips of a hundred tracks it lands within about 2 % of the protocol either way, as
    /// `Fast` does, and below it on average over seeds (docs/speed.md, "Fourth round").
    /// Refused where the fused step does not apply.
    Soap,
}

/// The SOAP recipe's iterations.
pub const SOAP_ITERATIONS: usize = 400;

/// The SOAP recipe's learning rate, as a multiple of the config's.
pub const SOAP_LR_FACTOR: f64 = 3.0;

/// The fast recipe's learning rate, as a multiple of the config's.
pub const FAST_LR_FACTOR: f64 = 1.5;
/// The fast recipe's warm-up, in iterations.
pub const FAST_WARMUP: usize = 5;
/// The fast recipe's `L_H` samples per step, where the sampling is capped.
pub const FAST_SMOOTHNESS_POINTS: usize = 64;
/// The fast recipe's training points per step (at most).
pub const FAST_POINTS_PER_STEP: usize = 256;

impl Recipe {
    /// `config` with this recipe's settings: [`Recipe::Paper`] leaves it as it is;
    /// [`Recipe::Fast`] keeps the budget, multiplies the learning rate by
    /// [`FAST_LR_FACTOR`], warms up for [`FAST_WARMUP`] iterations then decays on a
    /// cosine, fits at most [`FAST_POINTS_PER_STEP`] training points per step, and caps a
    /// capped `L_H` sampling (the authors' Affinity one) at [`FAST_SMOOTHNESS_POINTS`], and
    /// takes the whole step as one CPU op where it applies ([`super::StepKind::Auto`],
    /// unless the config names a step). [`Recipe::Soap`] does the same over
    /// [`SOAP_ITERATIONS`] iterations at [`SOAP_LR_FACTOR`] times the config's learning
    /// rate with SOAP's update. The model, the loss weights and
    /// the seed are kept.
    pub fn apply(self, mut config: FitConfig) -> FitConfig {
        let base_rate = config.schedule.learning_rate;
        if self != Recipe::Paper {
            let s = &mut config.schedule;
            s.learning_rate = decimal(s.learning_rate * FAST_LR_FACTOR);
            s.decay = Some(Decay::Cosine);
            s.warmup_iterations = Some(FAST_WARMUP);
            let m = &mut config.smoothness_sampling.max_points;
            *m = m.map(|m| m.min(FAST_SMOOTHNESS_POINTS));
            let k = config.points_per_step.unwrap_or(FAST_POINTS_PER_STEP);
            config.points_per_step = Some(k.min(FAST_POINTS_PER_STEP));
            // Its steps are mostly fixed cost: the whole step as one op, where it applies.
            config.step = Some(config.step.unwrap_or(super::StepKind::Auto));
        }
        if self == Recipe::Soap {
            config.schedule.iterations = SOAP_ITERATIONS;
            config.schedule.learning_rate = decimal(base_rate * SOAP_LR_FACTOR);
            config.soap = Some(super::SoapConfig::default());
        }
        config.recipe = Some(self);
        config
    }
}

/// What a fit's flags ask of its recipe: a named recipe (`None`: the config as it is) and
/// a stop on convergence after `until_converged` iterations of patience.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecipeChoice {
    /// The named recipe.
    pub recipe: Option<Recipe>,
    /// The patience of a stop on convergence ([`Convergence`], its other settings at their
    /// defaults).
    pub until_converged: Option<usize>,
}

impl RecipeChoice {
    /// `config` with the recipe's settings ([`Recipe::apply`]) and the stop on convergence.
    /// Flags that set a field themselves are applied after, and win.
    pub fn apply(&self, config: FitConfig) -> FitConfig {
        let mut config = match self.recipe {
            Some(r) => r.apply(config),
            None => config,
        };
        if let Some(p) = self.until_converged {
            config.until_converged = Some(Convergence::new(p));
        }
        config
    }
}

/// `x` rounded to 12 significant digits. `1.5 × 1e-4` is one ulp off the double nearest
/// `1.5e-4`; written into `config.json` in full and read back by serde_json's parser, it
/// would come back as that nearest double, and a resumed fit would not repeat its steps.
/// A short decimal reads back exactly.
fn decimal(x: f64) -> f64 {
    format!("{x:.11e}").parse().unwrap_or(x)
}

crate::names::value_names!(Recipe);
