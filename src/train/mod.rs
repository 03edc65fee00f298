//! Fitting a motion field (docs/reference.md §5): the recipe ([`FitConfig`]) and the one loop that
//! runs it ([`Trainer`]).
//!
//! One *iteration* is one pass over all `T` frames in a fresh random order; each frame is
//! one Adam step. What a step minimises is an [`Objective`]: the trajectory fit
//! ([`TrajectoryObjective`]: the trajectory L1, plus `w_H · L_H` (Eq. 13) and `w_E ·`
//! elasticity when their weights are positive) or the guided registration of Eq. 14
//! ([`crate::register`]). The learning rate follows the authors' LambdaLR schedule
//! ([`ScheduleConfig`]).

mod config;
pub(crate) mod fused;
mod hooks;
mod learned;
mod objective;
mod recipe;
mod record;
mod rows;
mod samples;
mod schedule;
pub mod select;
mod step;
mod trainer;
mod trajectory;

pub use config::{FitConfig, LossConfig, SmoothnessSampling, WithSchedule, check_weights};
pub use fused::{OptimizerKind, SoapConfig};
pub use hooks::{EachFn, Hooks, Progress};
pub use objective::Objective;
pub use recipe::{
    FAST_LR_FACTOR, FAST_POINTS_PER_STEP, FAST_SMOOTHNESS_POINTS, FAST_WARMUP, Recipe,
    RecipeChoice, SOAP_ITERATIONS, SOAP_LR_FACTOR,
};
pub use record::{Fitted, IterationRecord, Outcome, RngState, TrainerSnapshot, gaussian};
pub use schedule::{Convergence, Decay, ScheduleConfig, default_adam};
pub use step::StepKind;
pub use trainer::Trainer;
pub use trajectory::TrajectoryObjective;

use burn::module::Module;
use burn::tensor::Device;

use crate::Result;
use crate::data::Trajectories;
use crate::field::MotionField;
use crate::field::model::Model;

/// Fits the model of `config` to the training trajectories `data` on `device` (any
/// backend; autodiff is switched on here). No progress bar; see [`Trainer::progress`].
pub fn fit(config: &FitConfig, data: &Trajectories, device: &Device) -> Result<Fitted<Model>> {
    Trainer::from_config(config, data, device)?.run()
}

/// Fits `field` (parameters on `device.autodiff()`) by `config`'s objective, optimiser
/// and schedule; `config.model` is not read. The returned field is a validation snapshot
/// (no autodiff graph).
pub fn fit_model<M: MotionField + Module>(
    field: M,
    config: &FitConfig,
    data: &Trajectories,
    device: &Device,
) -> Result<Fitted<M>> {
    Trainer::new(field, config, data, device)?.run()
}
