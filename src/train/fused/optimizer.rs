//! The update a fused step applies to its gradient, Adam's or SOAP's, and which
//! checkpoints can resume it.

use serde::{Deserialize, Serialize};

use super::{AdamState, Float, FusedStep, SoapConfig, SoapState};
use crate::{DomaError, Result};

/// The optimiser of a fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum OptimizerKind {
    /// Adam, the paper's optimiser (every step kind).
    Adam,
    /// SOAP: Adam in the eigenbasis of Shampoo's factors of each weight matrix
    /// ([`SoapConfig`]), refreshed every 100 steps; the fused step only.
    Soap,
}

crate::names::value_names!(OptimizerKind);

impl OptimizerKind {
    /// The config's SOAP settings for this choice (`None`: Adam).
    pub fn soap(self) -> Option<SoapConfig> {
        match self {
            OptimizerKind::Adam => None,
            OptimizerKind::Soap => Some(SoapConfig::default()),
        }
    }
}

/// The update a fused step applies to its gradient.
#[derive(Clone, Debug)]
pub enum Optimizer<E> {
    /// Adam, as Burn computes it (the composed step's optimiser).
    Adam(AdamState<E>),
    /// SOAP ([`SoapState`]).
    Soap(SoapState<E>),
}

impl<E: Float + Send + Sync> Optimizer<E> {
    /// One update of `params` by their gradient `grad` at learning rate `lr`.
    pub fn update(&mut self, params: &mut [E], grad: &[E], lr: f64) {
        match self {
            Optimizer::Adam(a) => a.update(params, grad, lr),
            Optimizer::Soap(s) => s.update(params, grad, lr),
        }
    }
}

impl Optimizer<f32> {
    /// The state as a checkpoint stores it (each kind under its own magic).
    pub fn to_bytes(&self) -> Vec<u8> {
        match self {
            Optimizer::Adam(a) => a.to_bytes(),
            Optimizer::Soap(s) => s.to_bytes(),
        }
    }
}

/// Whether a checkpoint's optimiser state was written by the fused step.
pub fn is_fused_state(bytes: &[u8]) -> bool {
    AdamState::is_fused(bytes) || SoapState::is_fused(bytes)
}

impl<E: Float + Send + Sync> FusedStep<E> {
    /// The same step with SOAP's update instead of Adam's, from a fresh state.
    pub fn with_soap(mut self, config: SoapConfig) -> Self {
        self.optimizer = Optimizer::Soap(SoapState::new(config, &self.specs[0].shapes));
        self
    }

    /// The optimiser's state.
    pub fn optimizer(&self) -> &Optimizer<E> {
        &self.optimizer
    }

    /// Puts an Adam state back (a resumed fit's).
    pub fn set_adam(&mut self, adam: AdamState<E>) -> Result<()> {
        if adam.moment_1.len() != self.params.len() || adam.moment_2.len() != self.params.len() {
            return Err(DomaError::InvalidData(format!(
                "the saved Adam state holds {} moments for {} parameters",
                adam.moment_1.len(),
                self.params.len()
            )));
        }
        self.optimizer = Optimizer::Adam(adam);
        Ok(())
    }
}

impl FusedStep<f32> {
    /// Whether a checkpoint's optimiser state can resume this step: a SOAP state only a
    /// SOAP step, and a SOAP step only a SOAP state (Adam's, fused or Burn's, cannot).
    pub fn check_optimizer(&self, bytes: &[u8]) -> std::result::Result<(), String> {
        let soap_bytes = SoapState::is_fused(bytes);
        match (&self.optimizer, soap_bytes) {
            (Optimizer::Adam(_), true) => Err("the checkpoint holds a SOAP state and this fit \
                                               steps with Adam: resume it with the same optimiser"
                .into()),
            (Optimizer::Soap(_), false) => Err("the checkpoint holds an Adam state and this fit \
                                                steps with SOAP: resume it with the same \
                                                optimiser"
                .into()),
            _ => Ok(()),
        }
    }

    /// Puts a checkpoint's optimiser state back (a resumed fit's); it must be of this
    /// step's kind ([`FusedStep::check_optimizer`]), for these layers.
    pub fn restore_optimizer(&mut self, bytes: &[u8]) -> std::result::Result<(), String> {
        self.check_optimizer(bytes)?;
        match &mut self.optimizer {
            Optimizer::Adam(a) => {
                let adam = AdamState::from_bytes(bytes, a.settings())?;
                self.set_adam(adam).map_err(|e| e.to_string())
            }
            Optimizer::Soap(s) => s.read_bytes(bytes),
        }
    }
}
