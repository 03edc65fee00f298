//! Choosing a regulariser's weight by validation (the paper's own limitation: "how to
//! balance their weights is still not transparent"). A seeded fraction of the *training*
//! trajectories is held out; short fits over a log grid of weights (0 included) are scored
//! on it; the weight with the lowest validation EPE wins. The test points never enter:
//! this module is handed the training trajectories alone.

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::{FitConfig, Trainer};
use crate::data::Trajectories;
use crate::data::sequence::split_indices;
use crate::metrics::{EPE_SCALE, evaluate_epe};
use crate::{DomaError, Result};

/// A regulariser's weight: given, or chosen by validation on the training points
/// ([`choose_weight`]).
///
/// In JSON (a batch manifest): a number, or the string `"auto"`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "WeightRepr", into = "WeightRepr")]
pub enum Weight {
    /// This weight.
    Fixed(f64),
    /// The grid's best on held-out training points.
    Auto,
}

/// How a [`Weight`] is written in JSON.
#[derive(Clone, Serialize, Deserialize)]
#[serde(untagged)]
enum WeightRepr {
    Number(f64),
    Word(String),
}

impl TryFrom<WeightRepr> for Weight {
    type Error = String;
    fn try_from(r: WeightRepr) -> std::result::Result<Self, String> {
        match r {
            WeightRepr::Number(w) if w.is_finite() && w >= 0.0 => Ok(Weight::Fixed(w)),
            WeightRepr::Word(w) if w == "auto" => Ok(Weight::Auto),
            WeightRepr::Number(w) => Err(format!("the weight {w} must be finite and non-negative")),
            WeightRepr::Word(w) => {
                Err(format!("the weight `{w}` is neither a number nor \"auto\""))
            }
        }
    }
}

impl From<Weight> for WeightRepr {
    fn from(w: Weight) -> Self {
        match w {
            Weight::Fixed(w) => WeightRepr::Number(w),
            Weight::Auto => WeightRepr::Word("auto".into()),
        }
    }
}

/// A finite non-negative number, or `auto`: the spelling of `--h-weight` and `--e-weight`.
impl std::str::FromStr for Weight {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        if s.trim() == "auto" {
            return Ok(Weight::Auto);
        }
        match s.parse::<f64>() {
            Ok(w) if w.is_finite() && w >= 0.0 => Ok(Weight::Fixed(w)),
            _ => Err(format!("`{s}` must be finite and non-negative, or `auto`")),
        }
    }
}

impl std::fmt::Display for Weight {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Weight::Fixed(w) => write!(f, "{w}"),
            Weight::Auto => f.write_str("auto"),
        }
    }
}

/// Which loss weight is searched.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Penalty {
    /// `w_H` of the smoothness loss `L_H` (Eq. 13).
    Smoothness,
    /// `w_E` of the elasticity loss.
    Elasticity,
}

impl Penalty {
    /// `config` with this penalty's weight set to `w` (the other one untouched).
    pub fn with_weight(self, config: &FitConfig, w: f64) -> FitConfig {
        let mut c = config.clone();
        match self {
            Penalty::Smoothness => c.loss.smoothness_weight = w,
            Penalty::Elasticity => c.loss.elasticity_weight = w,
        }
        c
    }
}

/// How the weight is searched. Its cost is `grid.len()` short fits of `iterations`
/// iterations each on `1 − validation_fraction` of the training points, before the real
/// fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WeightSearch {
    /// The candidate weights (0, the unregularised fit, should be one of them).
    pub grid: Vec<f64>,
    /// The fraction of the training points held out for validation.
    pub validation_fraction: f64,
    /// Iterations of each short fit.
    pub iterations: usize,
}

impl Default for WeightSearch {
    /// `{0, 10⁻⁴, 10⁻³, 10⁻², 10⁻¹, 1}`, a fifth of the training points, 200 iterations
    /// (6 fits × 200 iterations: a fifth of a 1000-iteration budget, once per model).
    fn default() -> Self {
        WeightSearch {
            grid: vec![0.0, 1e-4, 1e-3, 1e-2, 1e-1, 1.0],
            validation_fraction: 0.2,
            iterations: 200,
        }
    }
}

impl WeightSearch {
    /// Refuses an empty grid, negative or non-finite weights, a fraction outside (0, 1)
    /// and a zero budget, naming the flag that sets each.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(DomaError::Usage(m));
        if self.grid.is_empty() {
            return bad("--weight-grid: the grid is empty".into());
        }
        if let Some(w) = self.grid.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
            return bad(format!(
                "--weight-grid: {w} is not a finite non-negative weight"
            ));
        }
        if !(self.validation_fraction > 0.0 && self.validation_fraction < 1.0) {
            return bad(format!(
                "--validation-fraction: {} is not strictly between 0 and 1",
                self.validation_fraction
            ));
        }
        if self.iterations == 0 {
            return bad("--search-iters: at least 1".into());
        }
        Ok(())
    }
}

/// One weight of the grid and its validation EPE (×10⁴).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridPoint {
    /// The weight.
    pub weight: f64,
    /// EPE ×10⁴ on the held-out training points after the short fit.
    pub validation_epe_x1e4: f64,
}

/// The outcome of a search.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WeightChoice {
    /// Which weight was searched.
    pub penalty: Penalty,
    /// The chosen weight: the grid's lowest validation EPE (the smaller weight on a tie).
    pub weight: f64,
    /// Every weight tried.
    pub grid: Vec<GridPoint>,
}

/// The seeded split of `n` training points into the points fitted during the search and
/// the validation points: indices into the training set, disjoint, covering it.
pub fn validation_split(n: usize, fraction: f64, seed: u64) -> Result<(Vec<usize>, Vec<usize>)> {
    // Its own stream, so that it is not the train/test split's.
    split_indices(n, 1.0 - fraction, seed ^ 0x5E1E_C7ED)
        .map_err(|e| DomaError::Usage(format!("--validation-fraction {fraction}: {e}")))
}

/// Searches `penalty`'s weight for `base` (its other settings, seed included) on the
/// training trajectories `train`: short fits on the search part, EPE on the validation
/// part. `progress` is told each weight's result.
pub fn choose_weight(
    base: &FitConfig,
    penalty: Penalty,
    train: &Trajectories,
    search: &WeightSearch,
    device: &Device,
    mut progress: impl FnMut(&GridPoint),
) -> Result<WeightChoice> {
    search.validate()?;
    let (fit_idx, val_idx) =
        validation_split(train.points(), search.validation_fraction, base.seed)?;
    let (fit_part, val_part) = (
        train.select_points(&fit_idx)?,
        train.select_points(&val_idx)?,
    );
    let mut grid = Vec::with_capacity(search.grid.len());
    for &weight in &search.grid {
        let mut config = penalty.with_weight(base, weight);
        config.schedule.iterations = search.iterations;
        let fitted = Trainer::from_config(&config, &fit_part, device)?.run()?;
        let point = GridPoint {
            weight,
            validation_epe_x1e4: evaluate_epe(&fitted.field, &val_part, device)? * EPE_SCALE,
        };
        progress(&point);
        grid.push(point);
    }
    let best = grid
        .iter()
        .filter(|p| p.validation_epe_x1e4.is_finite())
        .min_by(|a, b| {
            a.validation_epe_x1e4
                .total_cmp(&b.validation_epe_x1e4)
                .then(a.weight.total_cmp(&b.weight))
        })
        .ok_or_else(|| {
            DomaError::InvalidData("no weight of the grid gave a finite validation EPE".into())
        })?;
    Ok(WeightChoice {
        penalty,
        weight: best.weight,
        grid,
    })
}
