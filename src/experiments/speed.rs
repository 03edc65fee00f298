//! The speed comparison behind `doma bench`: the Jacobian step (outputs, J and the
//! backward of `L_H`) and one training step of the synthetic protocol, for each backend
//! and Jacobian method, in milliseconds (median after warm-up) and achieved GFLOP/s.
//!
//! FLOPs count the matmuls only (`2·m·k·n` each), the same for both methods: the useful
//! work of a SIREN with stacked tangents, not what a method happens to execute.

use std::time::Instant;

use burn::tensor::{Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::backend::BackendKind;
use crate::data::synthetic::{Motion, benchmark_sequence};
use crate::error::{DomaError, Result};
use crate::field::{DomaFieldConfig, MotionField, Variant};
use crate::jacobian::JacobianKind;
use crate::loss::{self, SmoothnessNorm};
use crate::readback::sync;
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
            // On a pool thread on the CPU, as `Trainer::step` runs (`backend::on_worker`).
            let step = || {
                let raw = field.raw_dual(x.clone(), 0.5, jac.as_ref());
                let tangent = raw.tangent.expect("a Jacobian method yields tangents");
                let l = loss::smoothness(tangent, SmoothnessNorm::Squared) + raw.value.mean();
                let grads = l.backward();
                drop(grads);
                sync(&device)
            };
            crate::backend::on_worker(&device, step)
        },
        warmup,
        steps,
    )?;
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

/// The `fit_step` row (one training step of the synthetic protocol, Affinity-H), or with
/// `smoothness = false` the `fit_step_l1` row (the same step without `L_H`).
pub fn fit_step_row(
    backend: BackendKind,
    method: JacobianKind,
    smoothness: bool,
    warmup: usize,
    steps: usize,
) -> Result<BenchRow> {
    let mut rows = fit_step_rows(backend, &[method], smoothness, warmup, steps)?;
    Ok(rows.remove(0))
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
    let config = |method| {
        FitConfig::doma(DomaFieldConfig::new(Variant::Affinity))
            .with_smoothness_weight(if smoothness { 0.1 } else { 0.0 })
            .with_jacobian(method)
    };
    let mut trainers = methods
        .iter()
        .map(|&m| Trainer::from_config(&config(m), &seq.train, &device))
        .collect::<Result<Vec<_>>>()?;
    let n = seq.train.points();
    // The sampling and schedule do not depend on the method.
    let common = config(JacobianKind::Autodiff);
    // REFERENCE §4.2: min(1024, N) jittered training points, so 750 here.
    let h_points = common
        .smoothness_sampling
        .max_points
        .map_or(n, |m| m.min(n));
    let frames = seq.train.frames();
    let lr = common.schedule.learning_rate;
    let mut times = vec![Vec::with_capacity(steps); methods.len()];
    for k in 0..warmup + steps.max(1) {
        for (trainer, times) in trainers.iter_mut().zip(&mut times) {
            let start = Instant::now();
            trainer.step(k % frames, lr)?;
            sync(&device)?;
            if k >= warmup {
                times.push(start.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
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

/// The median of `values` (the upper one of an even count).
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

/// The `warp` row: one chunk of evaluation (Affinity, d = 128, n = 2) through `method`'s
/// value path, on the backend's plain (non-autodiff) device.
pub fn warp_row(
    backend: BackendKind,
    method: JacobianKind,
    warmup: usize,
    steps: usize,
) -> Result<BenchRow> {
    let points = crate::warp::WARP_CHUNK;
    let device = backend.device()?;
    let field = DomaFieldConfig::new(Variant::Affinity).init(0, &device);
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let x: Vec<f32> = (0..3 * points)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let x = Tensor::<2>::from_data(TensorData::new(x, [points, 3]), &device);
    let jac = method.method();
    let ms = median_ms(
        || {
            let y = field.warp_values(x.clone(), 0.5, jac.as_ref()).warped.value;
            sync(&device)?;
            drop(y);
            Ok(())
        },
        warmup,
        steps,
    )?;
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

/// The PyTorch side of a comparison: `benches/torch_step.py` in the crate.
pub fn torch_script() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/torch_step.py")
}

/// One line of `benches/torch_step.py`'s output.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct TorchRow {
    /// `none`, `jacrev`, `jvp` or `dual`.
    pub mode: String,
    /// The torch version.
    pub torch: String,
    /// Its intra-op threads.
    pub threads: usize,
    /// Median milliseconds per step after warm-up.
    pub ms_median: f64,
}

/// Parses the script's output: one JSON object per line; other lines are ignored.
pub fn parse_torch_rows(stdout: &str) -> Result<Vec<TorchRow>> {
    stdout
        .lines()
        .filter(|l| l.trim_start().starts_with('{'))
        .map(|l| {
            serde_json::from_str(l).map_err(|e| {
                DomaError::InvalidData(format!("the PyTorch script printed {l:?}: {e}"))
            })
        })
        .collect()
}

/// Runs the PyTorch step script with `python` for `modes` (comma-separated) on `threads`
/// threads.
pub fn torch_rows(
    python: &std::path::Path,
    modes: &str,
    warmup: usize,
    steps: usize,
    threads: usize,
) -> Result<Vec<TorchRow>> {
    let out = std::process::Command::new(python)
        .arg(torch_script())
        .args(["--modes", modes])
        .args([
            "--warmup",
            &warmup.to_string(),
            "--steps",
            &steps.to_string(),
        ])
        .args(["--threads", &threads.to_string()])
        .output()
        .map_err(|e| DomaError::io(python, e))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let last = err
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("no message");
        return Err(DomaError::Usage(format!(
            "--compare-torch {}: the PyTorch script failed: {last}",
            python.display()
        )));
    }
    parse_torch_rows(&String::from_utf8_lossy(&out.stdout))
}

/// One line of the side-by-side table: a doma step and its PyTorch counterpart, each
/// measured once per round, rounds alternating between the two.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// The step: `affinity-h` or `no-reg`.
    pub step: &'static str,
    /// doma's method.
    pub doma: JacobianKind,
    /// doma's median ms per step, one per round.
    pub doma_ms: Vec<f64>,
    /// PyTorch's mode (for `fastest`, the fastest of `dual`, `jvp` and `jacrev` in each
    /// round).
    pub torch: &'static str,
    /// PyTorch's median ms per step, one per round.
    pub torch_ms: Vec<f64>,
    /// The speed-up the issue asks for: `torch / doma` of the medians over rounds.
    pub target: f64,
}

impl Comparison {
    /// The median over rounds.
    fn median(v: &[f64]) -> f64 {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    }

    /// `torch / doma`: how many times faster doma is.
    pub fn ratio(&self) -> f64 {
        Self::median(&self.torch_ms) / Self::median(&self.doma_ms)
    }
}

/// doma against PyTorch on flex, `rounds` times alternating: Affinity-H with Analytic
/// against PyTorch's fastest mode, with Autodiff against `jvp`, and the no-regulariser step
/// against `none`.
pub fn compare_torch(
    python: &std::path::Path,
    rounds: usize,
    warmup: usize,
    steps: usize,
    mut progress: impl FnMut(&str),
) -> Result<Vec<Comparison>> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut rows = vec![
        (("affinity-h", JacobianKind::Analytic, true), "fastest", 2.5),
        (("affinity-h", JacobianKind::Autodiff, true), "jvp", 1.0),
        (("no-reg", JacobianKind::Analytic, false), "none", 2.0),
    ]
    .into_iter()
    .map(|((step, doma, smoothness), torch, target)| {
        let c = Comparison {
            step,
            doma,
            doma_ms: Vec::new(),
            torch,
            torch_ms: Vec::new(),
            target,
        };
        (c, smoothness)
    })
    .collect::<Vec<_>>();
    for round in 0..rounds.max(1) {
        for (c, smoothness) in rows.iter_mut() {
            let r = fit_step_row(BackendKind::Flex, c.doma, *smoothness, warmup, steps)?;
            progress(&format!(
                "round {round}: doma {} {}: {:.2} ms",
                c.step, c.doma, r.ms
            ));
            c.doma_ms.push(r.ms);
        }
        let torch = torch_rows(python, "none,jvp,dual,jacrev", warmup, steps, threads)?;
        let ms = |mode: &str| torch.iter().find(|t| t.mode == mode).map(|t| t.ms_median);
        for (c, _) in rows.iter_mut() {
            let v = match c.torch {
                "fastest" => ["dual", "jvp", "jacrev"]
                    .iter()
                    .filter_map(|m| ms(m))
                    .fold(f64::INFINITY, f64::min),
                mode => ms(mode).unwrap_or(f64::NAN),
            };
            progress(&format!("round {round}: pytorch {}: {v:.2} ms", c.torch));
            c.torch_ms.push(v);
        }
    }
    Ok(rows.into_iter().map(|(c, _)| c).collect())
}

/// The side-by-side table: each line's medians over rounds (min–max), the ratio and the
/// issue's target.
pub fn comparison_table(rows: &[Comparison]) -> String {
    let range = |v: &[f64]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, 0f64), |(a, b), &x| (a.min(x), b.max(x)));
        format!("{:.2} ({lo:.2}-{hi:.2})", Comparison::median(v))
    };
    let mut s = format!(
        "{:<11} {:<9} {:>22} {:<8} {:>22} {:>8} {:>7}\n",
        "step", "doma", "ms (min-max)", "pytorch", "ms (min-max)", "speed-up", "target"
    );
    s += &"-".repeat(94);
    s += "\n";
    for c in rows {
        s += &format!(
            "{:<11} {:<9} {:>22} {:<8} {:>22} {:>7.2}x {:>6.1}x\n",
            c.step,
            c.doma,
            range(&c.doma_ms),
            c.torch,
            range(&c.torch_ms),
            c.ratio(),
            c.target
        );
    }
    s
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
    fn the_pytorch_lines_are_parsed_and_the_ratio_is_of_medians() {
        let out = "loading torch\n{\"impl\": \"pytorch\", \"torch\": \"2.5\", \"mode\": \"dual\", \"threads\": 2, \"points\": 750, \"ms_median\": 13.5, \"ms_min\": 13, \"ms_max\": 14}\n";
        let rows = parse_torch_rows(out).unwrap();
        assert_eq!((rows[0].mode.as_str(), rows[0].ms_median), ("dual", 13.5));
        assert!(parse_torch_rows("{ not json").is_err());
        let c = Comparison {
            step: "affinity-h",
            doma: JacobianKind::Analytic,
            doma_ms: vec![5.0, 4.0, 6.0],
            torch: "fastest",
            torch_ms: vec![12.0, 15.0, 13.0],
            target: 2.5,
        };
        // Medians 5 and 13: 2.6x.
        assert!((c.ratio() - 2.6).abs() < 1e-12);
        assert!(comparison_table(&[c]).contains("2.60x"));
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
