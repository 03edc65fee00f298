//! The composed training step against the fused one (`doma bench --fused`): the same
//! fits, one trainer per step kind, their steps timed in turn.

use serde::Serialize;

use super::{FitStep, median, steps_in_turn, synthetic_config};
use crate::Result;
use crate::backend::BackendKind;
use crate::data::synthetic::{Motion, benchmark_sequence};
use crate::jacobian::JacobianKind;
use crate::train::{FitConfig, Recipe, SoapConfig, StepKind};

/// One fit's step, composed and fused.
#[derive(Clone, Debug, Serialize)]
pub struct FusedRow {
    /// `protocol Affinity-H`, `protocol L1` or `fast Affinity-H`.
    pub step: String,
    /// Training points per step.
    pub points: usize,
    /// `L_H` samples per step (0 without `L_H`).
    pub samples: usize,
    /// The composed step's median, ms.
    pub composed_ms: f64,
    /// The fused step's median, ms.
    pub fused_ms: f64,
    /// The median over steps of composed / fused, each pair timed back to back.
    pub speedup: f64,
    /// The fused step with SOAP's update instead of Adam's, timed in turn with the two
    /// others (the `fast` row only), ms.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub soap_ms: Option<f64>,
}

/// The three steps (the synthetic protocol's Affinity-H and L1 steps, and `--recipe
/// fast`'s Affinity-H step) on `backend`, each composed and fused in turn (`fast`'s also
/// fused with SOAP's update): `warmup` untimed rounds, then `steps` timed.
pub fn fused_rows(backend: BackendKind, warmup: usize, steps: usize) -> Result<Vec<FusedRow>> {
    let device = backend.device()?;
    let seq = benchmark_sequence(Motion::Rotation, 0)?;
    let n = seq.train.points();
    let cases = [
        (
            "protocol Affinity-H",
            synthetic_config(JacobianKind::Analytic, true),
        ),
        (
            "protocol L1",
            synthetic_config(JacobianKind::Analytic, false),
        ),
        (
            "fast Affinity-H",
            Recipe::Fast.apply(synthetic_config(JacobianKind::Analytic, true)),
        ),
    ];
    let mut rows = Vec::new();
    for (name, config) in cases {
        let mut configs = vec![
            config.clone().with_step(Some(StepKind::Composed)),
            config.clone().with_step(Some(StepKind::Fused)),
        ];
        if name.starts_with("fast") {
            configs.push(configs[1].clone().with_soap(Some(SoapConfig::default())));
        }
        let mut trainers = configs
            .iter()
            .map(|c| FitStep::new(c, &seq.train, &device))
            .collect::<Result<Vec<_>>>()?;
        let times = steps_in_turn(&mut trainers, warmup, steps)?;
        let ratios = times[0].iter().zip(&times[1]).map(|(c, f)| c / f).collect();
        rows.push(FusedRow {
            step: name.into(),
            points: config.points_per_step.map_or(n, |k| k.min(n)),
            samples: samples(&config, n),
            composed_ms: median(times[0].clone()),
            fused_ms: median(times[1].clone()),
            speedup: median(ratios),
            soap_ms: times.get(2).map(|t| median(t.clone())),
        });
    }
    Ok(rows)
}

/// `L_H`'s samples per step of `config` on `n` training points.
fn samples(config: &FitConfig, n: usize) -> usize {
    if config.loss.smoothness_weight > 0.0 {
        config
            .smoothness_sampling
            .max_points
            .map_or(n, |m| m.min(n))
    } else {
        0
    }
}

/// The rows as a fixed-width table.
pub fn fused_table(rows: &[FusedRow]) -> String {
    let mut s = format!(
        "{:<20} {:>6} {:>7} {:>12} {:>9} {:>9} {:>14}\n",
        "step", "points", "samples", "composed ms", "fused ms", "speed-up", "fused SOAP ms"
    );
    s += &"-".repeat(83);
    s += "\n";
    for r in rows {
        s += &format!(
            "{:<20} {:>6} {:>7} {:>12.3} {:>9.3} {:>8.2}× {:>14}\n",
            r.step,
            r.points,
            r.samples,
            r.composed_ms,
            r.fused_ms,
            r.speedup,
            r.soap_ms.map_or("-".into(), |m| format!("{m:.3}"))
        );
    }
    s
}
