//! The speed comparison behind `doma bench`: the Jacobian step (outputs, J and the
//! backward of `L_H`) and one training step of the synthetic protocol, for each backend
//! and Jacobian method, in milliseconds (median after warm-up) and achieved GFLOP/s.
//!
//! FLOPs count the matmuls only (`2·m·k·n` each), the same for both methods: the useful
//! work of a SIREN with stacked tangents, not what a method happens to execute.

use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::backend::BackendKind;
use crate::data::synthetic::{Motion, benchmark_sequence};
use crate::error::{DomaError, Result};
use crate::field::{DomaFieldConfig, MotionField, Variant};
use crate::jacobian::JacobianKind;
use crate::loss::{self, SmoothnessNorm};
use crate::train::{FitConfig, Trainer};

/// What a row measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BenchKind {
    /// Outputs + J (Eq. 6) + the backward of `L_H` (Eq. 13) through them, Affinity,
    /// d = 128, n = 2.
    Jacobian,
    /// One Adam step of the synthetic protocol (750 trajectory points; `L_H` on
    /// min(1,024, 750) = 750 jittered points; Affinity-H with weight 0.1).
    FitStep,
}

/// One row of the table (and one JSON record).
#[derive(Clone, Debug, Serialize)]
pub struct BenchRow {
    /// `jacobian` or `fit_step`.
    pub kind: BenchKind,
    /// The backend.
    pub backend: BackendKind,
    /// The Jacobian method.
    pub method: JacobianKind,
    /// Points whose Jacobian is taken (for `fit_step`, the smoothness points).
    pub points: usize,
    /// Milliseconds per step, the median after warm-up.
    pub ms: f64,
    /// Matmul FLOPs per step / time, in GFLOP/s.
    pub gflops: f64,
}

/// What to measure.
#[derive(Clone, Debug)]
pub struct BenchJob {
    /// Backends to run.
    pub backends: Vec<BackendKind>,
    /// Jacobian methods to compare.
    pub methods: Vec<JacobianKind>,
    /// Point counts of the `jacobian` rows.
    pub points: Vec<usize>,
    /// Untimed steps before measuring.
    pub warmup: usize,
    /// Timed steps (the median is reported).
    pub steps: usize,
}

impl Default for BenchJob {
    fn default() -> Self {
        BenchJob {
            backends: vec![BackendKind::Flex],
            methods: vec![JacobianKind::Autodiff, JacobianKind::Analytic],
            points: vec![1024, 16384],
            warmup: 5,
            steps: 30,
        }
    }
}

/// Matmul FLOPs of a SIREN pass over `rows` rows, forward and backward, with layer widths
/// `widths` (`[in, d, …, d, out]`). The backward costs two matmuls per layer (`g_W`, `g_S`)
/// except the first, whose input needs no gradient.
pub fn siren_flops(rows: usize, widths: &[usize]) -> f64 {
    let mut f = 0.0;
    for (l, w) in widths.windows(2).enumerate() {
        let mm = 2.0 * rows as f64 * w[0] as f64 * w[1] as f64;
        f += if l == 0 { 2.0 * mm } else { 3.0 * mm };
    }
    f
}

fn widths() -> Vec<usize> {
    // Affinity at d = 128, n = 2: (x, y, z, t) → 128 → 128 → 128 → 12.
    vec![4, 128, 128, 128, Variant::Affinity.outputs()]
}

fn median_ms(mut step: impl FnMut() -> Result<()>, warmup: usize, steps: usize) -> Result<f64> {
    for _ in 0..warmup {
        step()?;
    }
    let mut times = Vec::with_capacity(steps);
    for _ in 0..steps.max(1) {
        let start = Instant::now();
        step()?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok(times[times.len() / 2])
}

fn sync(device: &Device) -> Result<()> {
    device
        .sync()
        .map_err(|e| DomaError::Device(format!("{e:?}")))
}

/// The `jacobian` row: outputs, J and the backward of `L_H + mean(o)` at `points` random
/// points.
pub fn jacobian_row(
    backend: BackendKind,
    method: JacobianKind,
    points: usize,
    warmup: usize,
    steps: usize,
) -> Result<BenchRow> {
    let device = backend.device()?;
    let ad = device.clone().autodiff();
    let field = DomaFieldConfig::new(Variant::Affinity).init(0, &ad);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let x: Vec<f32> = (0..3 * points)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let x = Tensor::<2>::from_data(TensorData::new(x, [points, 3]), &ad);
    let jac = method.method();
    let ms = median_ms(
        || {
            let raw = field.raw_dual(x.clone(), 0.5, jac.as_ref());
            let tangent = raw.tangent.expect("a Jacobian method yields tangents");
            let l = loss::smoothness(tangent, SmoothnessNorm::Squared) + raw.value.mean();
            let grads = l.backward();
            drop(grads);
            sync(&device)
        },
        warmup,
        steps,
    )?;
    Ok(BenchRow {
        kind: BenchKind::Jacobian,
        backend,
        method,
        points,
        ms,
        gflops: siren_flops(4 * points, &widths()) / (ms * 1e6),
    })
}

/// The `fit_step` row: one training step of the synthetic protocol, Affinity-H.
pub fn fit_step_row(
    backend: BackendKind,
    method: JacobianKind,
    warmup: usize,
    steps: usize,
) -> Result<BenchRow> {
    let device = backend.device()?;
    let seq = benchmark_sequence(Motion::Rotation, 0)?;
    let config = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity))
        .with_smoothness_weight(0.1)
        .with_jacobian(method);
    let mut trainer = Trainer::from_config(&config, &seq.train, &device)?;
    // REFERENCE §4.2: min(1024, N) jittered training points, so 750 here.
    let n = seq.train.points();
    let h_points = config
        .smoothness_sampling
        .max_points
        .map_or(n, |m| m.min(n));
    let frames = seq.train.frames();
    let mut k = 0;
    let ms = median_ms(
        || {
            let _ = trainer.step(k % frames, config.schedule.learning_rate);
            k += 1;
            sync(&device)
        },
        warmup,
        steps,
    )?;
    let flops = siren_flops(seq.train.points(), &widths()) + siren_flops(4 * h_points, &widths());
    Ok(BenchRow {
        kind: BenchKind::FitStep,
        backend,
        method,
        points: h_points,
        ms,
        gflops: flops / (ms * 1e6),
    })
}

/// Runs every row of `job`, calling `on_row` as each finishes.
pub fn run(job: &BenchJob, mut on_row: impl FnMut(&BenchRow)) -> Result<Vec<BenchRow>> {
    let mut rows = Vec::new();
    for &backend in &job.backends {
        for &method in &job.methods {
            let row = fit_step_row(backend, method, job.warmup, job.steps)?;
            on_row(&row);
            rows.push(row);
        }
        for &points in &job.points {
            for &method in &job.methods {
                let row = jacobian_row(backend, method, points, job.warmup, job.steps)?;
                on_row(&row);
                rows.push(row);
            }
        }
    }
    Ok(rows)
}

/// The rows as a fixed-width table.
pub fn table(rows: &[BenchRow]) -> String {
    let mut s = format!(
        "{:<9} {:<8} {:<9} {:>7} {:>10} {:>8}\n",
        "kind", "backend", "method", "points", "ms/step", "GFLOP/s"
    );
    s += &"-".repeat(56);
    s += "\n";
    for r in rows {
        let kind = match r.kind {
            BenchKind::Jacobian => "jacobian",
            BenchKind::FitStep => "fit_step",
        };
        s += &format!(
            "{:<9} {:<8} {:<9} {:>7} {:>10.2} {:>8.1}\n",
            kind, r.backend, r.method, r.points, r.ms, r.gflops
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flops_of_a_small_siren_by_hand() {
        // rows 10, widths 2 → 3 → 1: layer 1: 2·10·2·3 = 120, ×2 (forward, g_W) = 240;
        // layer 2: 2·10·3·1 = 60, ×3 = 180.
        assert_eq!(siren_flops(10, &[2, 3, 1]), 420.0);
    }
}
