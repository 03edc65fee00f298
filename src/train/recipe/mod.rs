//! Named recipes: the paper's protocol, and cheaper steps on a steeper schedule that reach
//! its error sooner (docs/speed.md, "Time to accuracy"). A recipe rewrites the fields of a
//! [`FitConfig`](super::FitConfig); the result is saved in `config.json` like any other setting, so a run's
//! folder says exactly what ran. How a recipe rewrites a config is `apply.rs`, so that
//! the config can name a recipe without this file naming the config.

mod apply;

use serde::{Deserialize, Serialize};

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
    /// `Fast` does, and below it on average over seeds (docs/speed.md, "Time to accuracy").
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

/// What a fit's flags ask of its recipe: a named recipe (`None`: the config as it is) and
/// a stop on convergence after `until_converged` iterations of patience.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecipeChoice {
    /// The named recipe.
    pub recipe: Option<Recipe>,
    /// The patience of a stop on convergence ([`Convergence`](super::schedule::Convergence), its other settings at their
    /// defaults).
    pub until_converged: Option<usize>,
}

/// `x` rounded to 12 significant digits. `1.5 × 1e-4` is one ulp off the double nearest
/// `1.5e-4`; written into `config.json` in full and read back by serde_json's parser, it
/// would come back as that nearest double, and a resumed fit would not repeat its steps.
/// A short decimal reads back exactly.
pub(super) fn decimal(x: f64) -> f64 {
    format!("{x:.11e}").parse().unwrap_or(x)
}

crate::names::value_names!(Recipe);
