//! What each recipe sets in a [`FitConfig`].

use super::{
    FAST_LR_FACTOR, FAST_POINTS_PER_STEP, FAST_SMOOTHNESS_POINTS, FAST_WARMUP, Recipe,
    RecipeChoice, SOAP_ITERATIONS, SOAP_LR_FACTOR, decimal,
};
use crate::train::config::FitConfig;
use crate::train::schedule::{Convergence, Decay};
use crate::train::{SoapConfig, StepKind};

impl Recipe {
    /// `config` with this recipe's settings: [`Recipe::Paper`] leaves it as it is;
    /// [`Recipe::Fast`] keeps the budget, multiplies the learning rate by
    /// [`FAST_LR_FACTOR`], warms up for [`FAST_WARMUP`] iterations then decays on a
    /// cosine, fits at most [`FAST_POINTS_PER_STEP`] training points per step, and caps a
    /// capped `L_H` sampling (the authors' Affinity one) at [`FAST_SMOOTHNESS_POINTS`], and
    /// takes the whole step as one CPU op where it applies ([`StepKind::Auto`],
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
            config.step = Some(config.step.unwrap_or(StepKind::Auto));
        }
        if self == Recipe::Soap {
            config.schedule.iterations = SOAP_ITERATIONS;
            config.schedule.learning_rate = decimal(base_rate * SOAP_LR_FACTOR);
            config.soap = Some(SoapConfig::default());
        }
        config.recipe = Some(self);
        config
    }
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
