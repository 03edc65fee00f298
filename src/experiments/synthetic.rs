//! The synthetic benchmark (paper Tab. 2): fit each variant to each synthetic motion
//! and report the EPE on the held-out points.

use serde::{Deserialize, Serialize};

use crate::Result;
use crate::backend::BackendKind;
use crate::data::synthetic::{Motion, benchmark_sequence};
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::metrics::{EPE_SCALE, evaluate_epe};
use crate::prelude::*;
use crate::train::select::{Penalty, WeightChoice, WeightSearch, choose_weight};
use crate::train::{FitConfig, RecipeChoice, Trainer};

/// The regulariser of a run: the rows "", "-E" and "-H" of Tab. 2.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Regularizer {
    /// The trajectory loss alone.
    None,
    /// The smoothness loss `L_H` (Eq. 13, squared form).
    H,
    /// The elasticity loss (Nerfies).
    E,
}

impl Regularizer {
    /// The suffix of the paper's row names ("", "-H", "-E").
    pub fn suffix(self) -> &'static str {
        match self {
            Regularizer::None => "",
            Regularizer::H => "-H",
            Regularizer::E => "-E",
        }
    }

    /// The weights `(w_H, w_E)` of a fit with this regulariser, given each one's weight.
    pub fn weights(self, h_weight: f64, e_weight: f64) -> (f64, f64) {
        match self {
            Regularizer::None => (0.0, 0.0),
            Regularizer::H => (h_weight, 0.0),
            Regularizer::E => (0.0, e_weight),
        }
    }
}

/// What to run.
#[derive(Clone, Debug)]
pub struct SyntheticJob {
    /// The motions (columns).
    pub motions: Vec<Motion>,
    /// The variants (rows).
    pub variants: Vec<Variant>,
    /// The regulariser of every run.
    pub reg: Regularizer,
    /// `w_H` when `reg` is `H`.
    pub h_weight: f64,
    /// `w_E` when `reg` is `E`.
    pub e_weight: f64,
    /// Iterations per fit (the budget: a fit that stops on convergence runs fewer).
    pub iterations: usize,
    /// The recipe and the stop on convergence (its iterations give way to `iterations`).
    pub recipe: RecipeChoice,
    /// Hidden width.
    pub hidden: usize,
    /// The backend.
    pub backend: BackendKind,
    /// The Jacobian method.
    pub jacobian: JacobianKind,
    /// The seed of the weights and of the frame order (the points are always the
    /// reference draw, numpy seed 0).
    pub seed: u64,
    /// No progress bars.
    pub quiet: bool,
    /// When set, the regulariser's weight is chosen by validation on held-out training
    /// points (`--h-weight auto`) instead of `h_weight` / `e_weight`.
    pub weight_search: Option<WeightSearch>,
}

impl SyntheticJob {
    /// `config` with its regulariser's weight searched on `train` when the job asks
    /// for it (the test points are not passed).
    pub fn searched(
        &self,
        config: FitConfig,
        train: &crate::data::Trajectories,
        device: &burn::tensor::Device,
    ) -> Result<(FitConfig, Option<WeightChoice>)> {
        let penalty = match (self.reg, &self.weight_search) {
            (Regularizer::H, Some(_)) => Penalty::Smoothness,
            (Regularizer::E, Some(_)) => Penalty::Elasticity,
            _ => return Ok((config, None)),
        };
        let search = self.weight_search.as_ref().expect("matched above");
        let choice = choose_weight(&config, penalty, train, search, device, |p| {
            if !self.quiet {
                eprintln!(
                    "  weight {:e}: validation EPE {:.2}e-4",
                    p.weight, p.validation_epe_x1e4
                );
            }
        })?;
        Ok((penalty.with_weight(&config, choice.weight), Some(choice)))
    }

    /// The fit configuration of one run.
    pub fn fit_config(&self, variant: Variant) -> FitConfig {
        let (w_h, w_e) = self.reg.weights(self.h_weight, self.e_weight);
        let base = FitConfig::doma(DomaFieldConfig::new(variant).with_hidden(self.hidden));
        self.recipe
            .apply(base)
            .with_iterations(self.iterations)
            .with_smoothness_weight(w_h)
            .with_elasticity_weight(w_e)
            .with_jacobian(self.jacobian)
            .with_seed(self.seed)
    }
}

/// One run's record (one JSON object per run).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SyntheticRun {
    /// The motion.
    pub motion: Motion,
    /// The variant.
    pub variant: Variant,
    /// The regulariser.
    pub reg: Regularizer,
    /// Iterations.
    pub iters: usize,
    /// The backend.
    pub backend: BackendKind,
    /// The Jacobian method.
    pub jacobian: JacobianKind,
    /// EPE × 10⁴ on the 2250 test points.
    pub epe_x1e4: f64,
    /// Wall time of the fit loop, seconds.
    pub seconds: f64,
    /// Optimiser steps.
    pub steps: usize,
    /// How the regulariser's weight was chosen, when it was searched.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub weight_search: Option<WeightChoice>,
}

/// Runs every (variant, motion) pair of `job`, calling `on_run` after each fit.
pub fn run(job: &SyntheticJob, mut on_run: impl FnMut(&SyntheticRun)) -> Result<Vec<SyntheticRun>> {
    let device = job.backend.device()?;
    let mut runs = Vec::new();
    for &motion in &job.motions {
        let seq = benchmark_sequence(motion, 0)?;
        for &variant in &job.variants {
            let (config, choice) = job.searched(job.fit_config(variant), &seq.train, &device)?;
            let fitted = Trainer::from_config(&config, &seq.train, &device)?
                .progress(!job.quiet)
                .run()?;
            let epe = evaluate_epe(&fitted.field, &seq.test, &device)?;
            let run = SyntheticRun {
                motion,
                variant,
                reg: job.reg,
                iters: job.iterations,
                backend: job.backend,
                jacobian: job.jacobian,
                epe_x1e4: epe * EPE_SCALE,
                seconds: fitted.seconds,
                steps: fitted.steps,
                weight_search: choice,
            };
            on_run(&run);
            runs.push(run);
        }
    }
    Ok(runs)
}

/// A table like the paper's Tab. 2: one row per (variant, regulariser), one column per
/// motion, EPE × 10⁴.
pub fn table(runs: &[SyntheticRun]) -> String {
    let mut motions: Vec<Motion> = Vec::new();
    let mut rows: Vec<(Variant, Regularizer)> = Vec::new();
    for r in runs {
        if !motions.contains(&r.motion) {
            motions.push(r.motion);
        }
        if !rows.contains(&(r.variant, r.reg)) {
            rows.push((r.variant, r.reg));
        }
    }
    motions.sort_by_key(|m| Motion::ALL.iter().position(|x| x == m));
    let mut out = format!("{:<20}", "EPE (x1e-4)");
    for m in &motions {
        out += &format!(" | {m:>11}");
    }
    out += "\n";
    out += &"-".repeat(20 + 14 * motions.len());
    out += "\n";
    for (variant, reg) in rows {
        out += &format!(
            "{:<20}",
            format!("{}{}", variant.paper_name(), reg.suffix())
        );
        for m in &motions {
            let cell = runs
                .iter()
                .find(|r| r.variant == variant && r.reg == reg && r.motion == *m)
                .map_or("-".to_string(), |r| format!("{:.2}", r.epe_x1e4));
            out += &format!(" | {cell:>11}");
        }
        out += "\n";
    }
    out
}

crate::names::value_names!(Regularizer);
