//! The speed comparison behind `doma bench`: the Jacobian step (outputs, J and the
//! backward of `L_H`) and one training step of the synthetic protocol, for each backend
//! and Jacobian method, in milliseconds (median after warm-up) and achieved GFLOP/s.
//!
//! FLOPs count the matmuls only (`2·m·k·n` each), the same for both methods: the useful
//! work of a SIREN with stacked tangents, not what a method happens to execute. The steps
//! themselves are [`JacobianStep`], [`FitStep`] and [`WarpStep`], the PyTorch side is
//! [`compare_torch`]; docs/speed.md says how the figures are read.

mod fused;
mod steps;
mod torch;

pub use fused::{FusedRow, fused_rows, fused_table};
pub use steps::{FitStep, JacobianStep, WarpStep, synthetic_config};
pub use torch::{
    Comparison, TorchRow, TorchSize, compare_torch, comparison_table, parse_torch_rows, torch_rows,
    torch_script,
};

use std::time::Instant;

use burn::tensor::{Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::backend::BackendKind;
use crate::data::synthetic::{Motion, benchmark_sequence};
use crate::error::Result;
use crate::field::Variant;
use crate::jacobian::JacobianKind;
use crate::readback::sync;

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
    /// The same step without a regulariser: the trajectory L1 alone (the value path).
    FitStepL1,
    /// Evaluation: the warp `y = A x + u` of [`crate::warp::WARP_CHUNK`] points through
    /// the method's value path without autodiff (`autodiff`: Burn's plain ops;
    /// `analytic`: the fused SIREN op), what `doma eval` and `doma warp` run per chunk.
    Warp,
    /// The machine's matmul throughput through the backend's own GEMM: f32
    /// `[3000, 128] × [128, 128]`, the best of the timed runs. The other rows state their
    /// share of it.
    Gemm,
}

/// One row of the table (and one JSON record).
#[derive(Clone, Debug, Serialize)]
pub struct BenchRow {
    /// `jacobian` or `fit_step`.
    pub kind: BenchKind,
    /// The backend.
    pub backend: BackendKind,
    /// The Jacobian method (`null` for the GEMM row).
    pub method: Option<JacobianKind>,
    /// Points whose Jacobian is taken (for `fit_step`, the smoothness points; for
    /// `fit_step_l1`, the trajectory points; for `gemm`, the rows).
    pub points: usize,
    /// Milliseconds per step, the median after warm-up (for `gemm`, the best).
    pub ms: f64,
    /// Matmul FLOPs per step / time, in GFLOP/s.
    pub gflops: f64,
    /// `gflops` as a percentage of the GEMM peak measured on the same backend in the same
    /// run.
    pub peak_percent: f64,
    /// Training-step rows of a method other than Autodiff, timed in turn with it: the
    /// median over steps of Autodiff's step time over this method's, each pair timed back
    /// to back (over rounds, the median of the rounds'). A ratio that the machine's drift
    /// between steps cannot move, unlike the ratio of two medians.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub speedup: Option<f64>,
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
    /// Times every row is measured, the rows of a round in turn (so that the methods
    /// alternate); a row reports its median over the rounds.
    pub rounds: usize,
}

impl Default for BenchJob {
    fn default() -> Self {
        BenchJob {
            backends: vec![BackendKind::Flex],
            methods: vec![JacobianKind::Autodiff, JacobianKind::Analytic],
            points: vec![1024, 16384],
            warmup: 5,
            steps: 30,
            rounds: 1,
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

/// The `jacobian` row: outputs, J and the backward of `L_H + mean(o)` at `points` random
/// points ([`JacobianStep`]).
pub fn jacobian_row(
    backend: BackendKind,
    method: JacobianKind,
    points: usize,
    warmup: usize,
    steps: usize,
) -> Result<BenchRow> {
    let step = JacobianStep::new(backend, method, points)?;
    let ms = median_ms(|| step.run(), warmup, steps)?;
    Ok(BenchRow {
        kind: BenchKind::Jacobian,
        backend,
        method: Some(method),
        points,
        ms,
        gflops: siren_flops(4 * points, &widths()) / (ms * 1e6),
        peak_percent: f64::NAN,
        speedup: None,
    })
}

/// The `fit_step` (or `fit_step_l1`) rows of several methods, timed **step by step in
/// turn**: one trainer per method, and each round of the loop times one step of each. On
/// a machine whose speed drifts (lavapipe on a shared host: ±20 % within a minute), rows
/// timed one after the other compare different machines; steps in turn see the same one.
pub fn fit_step_rows(
    backend: BackendKind,
    methods: &[JacobianKind],
    smoothness: bool,
    warmup: usize,
    steps: usize,
) -> Result<Vec<BenchRow>> {
    let device = backend.device()?;
    let seq = benchmark_sequence(Motion::Rotation, 0)?;
    let mut fit_steps = methods
        .iter()
        .map(|&m| FitStep::synthetic(&seq.train, m, smoothness, &device))
        .collect::<Result<Vec<_>>>()?;
    let n = seq.train.points();
    // The sampling does not depend on the method.
    let common = synthetic_config(JacobianKind::Autodiff, smoothness);
    // docs/reference.md §4.2: min(1024, N) jittered training points, so 750 here.
    let h_points = common
        .smoothness_sampling
        .max_points
        .map_or(n, |m| m.min(n));
    let times = steps_in_turn(&mut fit_steps, warmup, steps)?;
    let (kind, points, flops) = if smoothness {
        let flops = siren_flops(n, &widths()) + siren_flops(4 * h_points, &widths());
        (BenchKind::FitStep, h_points, flops)
    } else {
        (BenchKind::FitStepL1, n, siren_flops(n, &widths()))
    };
    let autodiff = methods.iter().position(|&m| m == JacobianKind::Autodiff);
    let speedups: Vec<Option<f64>> = (0..methods.len())
        .map(|i| {
            let a = autodiff.filter(|&a| a != i)?;
            let ratios = times[a].iter().zip(&times[i]).map(|(a, m)| a / m).collect();
            Some(median(ratios))
        })
        .collect();
    Ok(methods
        .iter()
        .zip(times)
        .zip(speedups)
        .map(|((&method, times), speedup)| {
            let ms = median(times);
            BenchRow {
                kind,
                backend,
                method: Some(method),
                points,
                ms,
                gflops: flops / (ms * 1e6),
                peak_percent: f64::NAN,
                speedup,
            }
        })
        .collect())
}

/// The steps of several trainers timed in turn (one step of each per round), `warmup`
/// rounds untimed then `steps` timed: each trainer's step times in ms, in order.
pub(crate) fn steps_in_turn(
    trainers: &mut [FitStep<'_>],
    warmup: usize,
    steps: usize,
) -> Result<Vec<Vec<f64>>> {
    let mut times = vec![Vec::with_capacity(steps); trainers.len()];
    for k in 0..warmup + steps.max(1) {
        for (step, times) in trainers.iter_mut().zip(&mut times) {
            let start = Instant::now();
            step.run()?;
            if k >= warmup {
                times.push(start.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
    Ok(times)
}

/// The median of `values` (the upper one of an even count).
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

/// The `warp` row: one chunk of evaluation (Affinity, d = 128, n = 2) through `method`'s
/// value path, on the backend's plain (non-autodiff) device ([`WarpStep`]).
pub fn warp_row(
    backend: BackendKind,
    method: JacobianKind,
    warmup: usize,
    steps: usize,
) -> Result<BenchRow> {
    let points = crate::warp::WARP_CHUNK;
    let step = WarpStep::new(backend, method)?;
    let ms = median_ms(|| step.run(), warmup, steps)?;
    // The forward alone: one multiply per weight and row.
    let forward: f64 = widths()
        .windows(2)
        .map(|w| 2.0 * points as f64 * w[0] as f64 * w[1] as f64)
        .sum();
    Ok(BenchRow {
        kind: BenchKind::Warp,
        backend,
        method: Some(method),
        points,
        ms,
        gflops: forward / (ms * 1e6),
        peak_percent: f64::NAN,
        speedup: None,
    })
}

/// The `gemm` row: the best of `steps` f32 `[3000, 128] × [128, 128]` matmuls on
/// `backend` (after `warmup`), through the GEMM that the backend's training steps use.
pub fn gemm_row(backend: BackendKind, warmup: usize, steps: usize) -> Result<BenchRow> {
    let (m, k, n) = (3000, 128, 128);
    let device = backend.device()?;
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut random =
        |len: usize| -> Vec<f32> { (0..len).map(|_| rng.random_range(-1.0..1.0)).collect() };
    let a = Tensor::<2>::from_data(TensorData::new(random(m * k), [m, k]), &device);
    let b = Tensor::<2>::from_data(TensorData::new(random(k * n), [k, n]), &device);
    let mut best = f64::INFINITY;
    for i in 0..warmup + steps.max(1) {
        let start = Instant::now();
        let c = a.clone().matmul(b.clone());
        sync(&device)?;
        drop(c);
        if i >= warmup {
            best = best.min(start.elapsed().as_secs_f64() * 1e3);
        }
    }
    Ok(BenchRow {
        kind: BenchKind::Gemm,
        backend,
        method: None,
        points: m,
        ms: best,
        gflops: 2.0 * (m * k * n) as f64 / (best * 1e6),
        peak_percent: 100.0,
        speedup: None,
    })
}

/// Runs every row of `job`, calling `on_row` as each finishes: per backend, its GEMM peak
/// first (every other row states its share of it), then the training steps (Affinity-H,
/// then without a regulariser) and the Jacobian steps.
pub fn run(job: &BenchJob, mut on_row: impl FnMut(&BenchRow)) -> Result<Vec<BenchRow>> {
    let mut rows = Vec::new();
    let rounds = job.rounds.max(1);
    for &backend in &job.backends {
        // More runs than a step row: the best of them is the peak.
        let peak = gemm_row(backend, job.warmup, 4 * job.steps)?;
        on_row(&peak);
        let peak_gflops = peak.gflops;
        rows.push(peak);
        let mut measured: Vec<Vec<BenchRow>> = Vec::new();
        for round in 0..rounds {
            let mut this_round = Vec::new();
            for smoothness in [true, false] {
                this_round.extend(fit_step_rows(
                    backend,
                    &job.methods,
                    smoothness,
                    job.warmup,
                    job.steps,
                )?);
            }
            for &points in &job.points {
                for &method in &job.methods {
                    this_round.push(jacobian_row(
                        backend, method, points, job.warmup, job.steps,
                    )?);
                }
            }
            for &method in &job.methods {
                this_round.push(warp_row(backend, method, job.warmup, job.steps)?);
            }
            if rounds > 1 {
                for r in &this_round {
                    let method = r.method.map_or("-".into(), |m| m.to_string());
                    let speedup = r
                        .speedup
                        .map_or(String::new(), |x| format!(" ({x:.2}× Autodiff, paired)"));
                    eprintln!(
                        "round {round}: {:?} {} {method} {} points: {:.2} ms{speedup}",
                        r.kind, r.backend, r.points, r.ms
                    );
                }
            }
            measured.push(this_round);
        }
        for i in 0..measured[0].len() {
            let mut times: Vec<f64> = measured.iter().map(|r| r[i].ms).collect();
            times.sort_by(f64::total_cmp);
            let mut row = measured[0][i].clone();
            let median_ms = times[times.len() / 2];
            row.gflops *= row.ms / median_ms;
            row.ms = median_ms;
            let speedups: Vec<f64> = measured.iter().filter_map(|r| r[i].speedup).collect();
            row.speedup = (!speedups.is_empty()).then(|| median(speedups));
            row.peak_percent = 100.0 * row.gflops / peak_gflops;
            on_row(&row);
            rows.push(row);
        }
    }
    Ok(rows)
}

/// The rows as a fixed-width table.
pub fn table(rows: &[BenchRow]) -> String {
    let mut s = format!(
        "{:<11} {:<8} {:<9} {:>7} {:>10} {:>8} {:>7} {:>9}\n",
        "kind", "backend", "method", "points", "ms/step", "GFLOP/s", "% peak", "speed-up"
    );
    s += &"-".repeat(76);
    s += "\n";
    for r in rows {
        let kind = match r.kind {
            BenchKind::Jacobian => "jacobian",
            BenchKind::FitStep => "fit_step",
            BenchKind::FitStepL1 => "fit_step_l1",
            BenchKind::Warp => "warp",
            BenchKind::Gemm => "gemm",
        };
        let method = r.method.map_or("-".to_string(), |m| m.to_string());
        let speedup = r.speedup.map_or(String::new(), |x| format!("{x:.2}×"));
        let line = format!(
            "{:<11} {:<8} {:<9} {:>7} {:>10.2} {:>8.1} {:>7.1} {:>9}",
            kind, r.backend, method, r.points, r.ms, r.gflops, r.peak_percent, speedup
        );
        s += line.trim_end();
        s += "\n";
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

    #[test]
    fn the_table_states_a_paired_speed_up_and_pads_nothing_after_the_last_column() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        let row = |method, speedup| BenchRow {
            kind: BenchKind::FitStep,
            backend: BackendKind::Flex,
            method: Some(method),
            points: 750,
            ms: 10.0,
            gflops: 1.0,
            peak_percent: 50.0,
            speedup,
        };
        let t = table(&[
            row(JacobianKind::Autodiff, None),
            row(JacobianKind::Analytic, Some(1.256)),
        ]);
        let lines: Vec<&str> = t.lines().collect();
        assert!(lines[2].ends_with("50.0"), "{:?}", lines[2]);
        assert!(lines[3].ends_with("1.26×"), "{:?}", lines[3]);
    }
}
