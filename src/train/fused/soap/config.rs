//! SOAP's settings, apart from its arithmetic: a [`crate::train::FitConfig`] names them
//! without depending on the fused step.

use serde::{Deserialize, Serialize};

/// SOAP's hyper-parameters: the paper's defaults `β = (0.95, 0.95)` and `ε = 10⁻⁸`, and
/// a refresh every 100 steps where the paper refreshes every 10 (on these small networks
/// a refresh costs several steps, and the rarer one fitted as well or better:
/// docs/speed.md, "What was tried").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SoapConfig {
    /// `β₁`, the first moment's decay.
    #[serde(default = "default_beta")]
    pub beta_1: f64,
    /// `β₂`, the second moment's and the factors' decay.
    #[serde(default = "default_beta")]
    pub beta_2: f64,
    /// `ε`.
    #[serde(default = "default_epsilon")]
    pub epsilon: f64,
    /// Steps between refreshes of the eigenbases (the paper's default: 10).
    #[serde(default = "default_every")]
    pub every: usize,
}

fn default_beta() -> f64 {
    0.95
}
fn default_epsilon() -> f64 {
    1e-8
}
fn default_every() -> usize {
    100
}

impl Default for SoapConfig {
    fn default() -> Self {
        SoapConfig {
            beta_1: default_beta(),
            beta_2: default_beta(),
            epsilon: default_epsilon(),
            every: default_every(),
        }
    }
}

impl SoapConfig {
    /// Why these settings cannot run, if they cannot.
    pub fn check(&self) -> Result<(), String> {
        let beta = |b: f64| b.is_finite() && (0.0..1.0).contains(&b);
        if !beta(self.beta_1) || !beta(self.beta_2) {
            return Err(format!(
                "SOAP's betas must lie in [0, 1), got {} and {}",
                self.beta_1, self.beta_2
            ));
        }
        if !(self.epsilon.is_finite() && self.epsilon > 0.0) {
            return Err(format!(
                "SOAP's epsilon must be positive, got {}",
                self.epsilon
            ));
        }
        if self.every == 0 {
            return Err("SOAP's refresh interval must be at least 1 step".into());
        }
        Ok(())
    }
}
