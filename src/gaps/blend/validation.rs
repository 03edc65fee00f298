//! The choices of a blend's validation in one place ([`Validation`]): how many spans are
//! hidden, in how many draws, how the draws are split for cross-fitting, and how clear a
//! gain must be. A fit's config carries it (`FitConfig::validation`, `--config`), so a run
//! folder says which validation chose its weights.

use serde::{Deserialize, Serialize};

/// How doma's fill validates its weights (docs/design.md §7, "Tuning constants of the
/// fill", for what chose each default). Every field has today's value as its default;
/// a config file may set any of them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Validation {
    /// The share of the observations of the tracks with gaps hidden in each validation
    /// draw, and in the blind spans hidden from a fit. A tenth: enough spans per draw on a
    /// minute of capture, little taken from a short clip's fit.
    pub fraction: f64,
    /// The validation draws of stage 1 at least. Three draws gave weights that moved by
    /// ±10 % with the draw alone; six halve that variance at twice the fillers' cost.
    pub min_draws: usize,
    /// The validation draws at most: past `min_draws`, draws are added until every class
    /// of gap length with a gap to fill holds `spans_per_class` spans (a tenth of a
    /// 2-second clip is a couple of one-second gaps).
    pub max_draws: usize,
    /// The validation spans wanted in each class of gap length with a gap to fill.
    pub spans_per_class: usize,
    /// Draws that find no span to hide before stage 1 stops drawing.
    pub max_failed_draws: usize,
    /// The groups of draws that cross-fitting holds out in turn (each judged by the
    /// weights the others learn): one per draw at the least number of draws.
    pub cross_fit_groups: usize,
    /// The folds the blind spans are split into, span by span, for stage 2.
    pub blind_folds: usize,
    /// The blind folds with entries of a class that stage 2 needs to weigh the field's
    /// fills there (fewer give no measure of the gain's spread).
    pub field_folds: usize,
    /// The draws that must hold a track's validation spans of a class for it to lean
    /// there (fewer give no measure of the gain's spread).
    pub lean_draws: usize,
    /// The shares of a track's classic weight that its lean may move to one filler.
    pub lean_shares: Vec<f64>,
    /// How many standard errors of its per-fold gain a choice must gain by to be kept
    /// (the field's share in stage 2, a track's lean): a share won by noise cost up to
    /// 1.45× the best filler on a short recording.
    pub standard_errors: f64,
    /// Whether a class of gap length whose stage-1 choice does not clearly beat the filler
    /// best across the recording takes that filler alone. Off: on the native-rate table it
    /// met 43 of 48 cases where the per-class choice met 48 (docs/gap-filling.md, "What
    /// was tried").
    pub fall_back: bool,
}

impl Default for Validation {
    fn default() -> Self {
        Validation {
            fraction: 0.1,
            min_draws: 6,
            max_draws: 30,
            spans_per_class: 24,
            max_failed_draws: 6,
            cross_fit_groups: 6,
            blind_folds: 6,
            field_folds: 3,
            lean_draws: 3,
            lean_shares: vec![0.25, 0.5, 0.75, 1.0],
            standard_errors: 2.0,
            fall_back: false,
        }
    }
}

impl Validation {
    /// Why these settings cannot run, if they cannot.
    pub fn check(&self) -> Result<(), String> {
        if !(self.fraction > 0.0 && self.fraction < 1.0) {
            return Err(format!(
                "validation.fraction must lie in (0, 1), got {}",
                self.fraction
            ));
        }
        let counts = [
            ("min_draws", self.min_draws),
            ("max_draws", self.max_draws),
            ("max_failed_draws", self.max_failed_draws),
            ("cross_fit_groups", self.cross_fit_groups),
            ("blind_folds", self.blind_folds),
        ];
        if let Some((name, _)) = counts.iter().find(|(_, v)| *v == 0) {
            return Err(format!("validation.{name} must be at least 1"));
        }
        if self.max_draws < self.min_draws {
            return Err(format!(
                "validation.max_draws ({}) is below validation.min_draws ({})",
                self.max_draws, self.min_draws
            ));
        }
        if self.lean_draws < 2 || self.field_folds < 2 {
            return Err(
                "validation.lean_draws and validation.field_folds must be at least 2 \
                        (one fold gives no spread)"
                    .into(),
            );
        }
        if self
            .lean_shares
            .iter()
            .any(|s| !(s.is_finite() && *s > 0.0 && *s <= 1.0))
        {
            return Err(format!(
                "validation.lean_shares must lie in (0, 1], got {:?}",
                self.lean_shares
            ));
        }
        if !(self.standard_errors.is_finite() && self.standard_errors >= 0.0) {
            return Err(format!(
                "validation.standard_errors must be a number ≥ 0, got {}",
                self.standard_errors
            ));
        }
        Ok(())
    }

    /// Whether the mean of `gains` (one per fold or draw) exceeds `standard_errors` of its
    /// standard errors, and so is positive: the one rule that keeps a choice made on a few
    /// spans (the field's share in stage 2, a track's lean). Fewer than two gains give no
    /// spread and never clear.
    pub fn clearly_positive(&self, gains: &[f64]) -> bool {
        let n = gains.len() as f64;
        if gains.len() < 2 {
            return false;
        }
        let mean = gains.iter().sum::<f64>() / n;
        let variance = gains.iter().map(|g| (g - mean).powi(2)).sum::<f64>() / (n - 1.0);
        mean > 0.0 && mean > self.standard_errors * (variance / n).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gain_is_clear_past_two_standard_errors() {
        let v = Validation::default();
        // Every fold gains the same: no spread, clear.
        assert!(v.clearly_positive(&[1.0, 1.0, 1.0]));
        // Mean 1/3, standard deviation √(4/3), standard error 2/3: 1/3 < 4/3.
        assert!(!v.clearly_positive(&[1.0, -1.0, 1.0]));
        // Mean 3, standard deviation 0.1, standard error 0.1/√3: clear.
        assert!(v.clearly_positive(&[2.9, 3.0, 3.1]));
        // A loss is never clear, however steady; one fold gives no spread.
        assert!(!v.clearly_positive(&[-1.0, -1.0, -1.0]));
        assert!(!v.clearly_positive(&[5.0]));
        assert!(!v.clearly_positive(&[]));
        // At one standard error, mean 1/3 against 2/3 is still not clear; at 0.4 it is.
        let lax = |k: f64| Validation {
            standard_errors: k,
            ..Validation::default()
        };
        assert!(!lax(1.0).clearly_positive(&[1.0, -1.0, 1.0]));
        assert!(lax(0.4).clearly_positive(&[1.0, -1.0, 1.0]));
    }

    #[test]
    fn a_config_file_sets_one_field_and_keeps_the_others() {
        let v: Validation = serde_json::from_str(r#"{"max_draws": 12}"#).unwrap();
        assert_eq!(v.max_draws, 12);
        assert_eq!(v.min_draws, Validation::default().min_draws);
        assert!(serde_json::from_str::<Validation>(r#"{"folds": 3}"#).is_err());
        assert!(v.check().is_ok());
        let bad = Validation {
            fraction: 1.5,
            ..Validation::default()
        };
        assert!(bad.check().unwrap_err().contains("validation.fraction"));
    }
}
