//! doma against PyTorch, alternating in one run: `benches/torch_step.py` (the same step in
//! plain PyTorch, the Jacobian four ways) run with a user's Python, side by side with
//! doma's training-step rows (`doma bench --compare-torch`).

use serde::Serialize;

use super::{FitStep, median, steps_in_turn, synthetic_config};
use crate::backend::BackendKind;
use crate::data::synthetic::{Motion, benchmark_sequence};
use crate::error::{DomaError, Result};
use crate::jacobian::JacobianKind;
use crate::train::{FAST_POINTS_PER_STEP, FAST_SMOOTHNESS_POINTS, FitConfig, Recipe, StepKind};

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

/// The size of a PyTorch step: training points and `L_H` samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct TorchSize {
    /// Training points per step.
    pub points: usize,
    /// `L_H` samples per step.
    pub h_points: usize,
}

/// Runs the PyTorch step script with `python` for `modes` (comma-separated) on `threads`
/// threads, at `size`.
pub fn torch_rows(
    python: &std::path::Path,
    modes: &str,
    size: TorchSize,
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
        .args(["--points", &size.points.to_string()])
        .args(["--h-points", &size.h_points.to_string()])
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
    /// The step: `affinity-h`, `no-reg` (the protocol's, 750 points and 750 `L_H`
    /// samples) or `fast` (`--recipe fast`'s Affinity-H step, 256 points and 64 samples).
    pub step: &'static str,
    /// doma's way of taking it: `analytic` or `autodiff` (the composed step by that
    /// Jacobian method) or `fused` (the whole step as one op).
    pub doma: &'static str,
    /// doma's median ms per step, one per round.
    pub doma_ms: Vec<f64>,
    /// PyTorch's mode (for `fastest`, the fastest of `dual`, `jvp` and `jacrev` in each
    /// round).
    pub torch: &'static str,
    /// The size of both sides' step.
    pub size: TorchSize,
    /// PyTorch's median ms per step, one per round.
    pub torch_ms: Vec<f64>,
    /// The speed-up this step is expected to reach: `torch / doma` of the medians over
    /// rounds (`None`: no target set).
    pub target: Option<f64>,
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

/// doma against PyTorch on flex, `rounds` times alternating: the protocol's Affinity-H
/// step (composed with Analytic, and fused) against PyTorch's fastest mode, with Autodiff
/// against `jvp`, the no-regulariser step (composed and fused) against `none`, and `--recipe
/// fast`'s step (fused) against PyTorch's fastest mode at the same size. In a round, doma's
/// steps are timed in turn, then PyTorch's.
pub fn compare_torch(
    python: &std::path::Path,
    rounds: usize,
    warmup: usize,
    steps: usize,
    mut progress: impl FnMut(&str),
) -> Result<Vec<Comparison>> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let device = BackendKind::Flex.device()?;
    let seq = benchmark_sequence(Motion::Rotation, 0)?;
    let n = seq.train.points();
    let (protocol, fast, cases) = comparison_cases(n);
    let mut trainers = Vec::new();
    let mut rows = Vec::new();
    for (step, doma, config, torch, size, target) in cases {
        trainers.push(FitStep::new(&config, &seq.train, &device)?);
        rows.push(Comparison {
            step,
            doma,
            doma_ms: Vec::new(),
            torch,
            size,
            torch_ms: Vec::new(),
            target,
        });
    }
    for round in 0..rounds.max(1) {
        let times = steps_in_turn(&mut trainers, warmup, steps)?;
        for (c, t) in rows.iter_mut().zip(times) {
            let ms = median(t);
            progress(&format!(
                "round {round}: doma {} {}: {ms:.2} ms",
                c.step, c.doma
            ));
            c.doma_ms.push(ms);
        }
        for size in [protocol, fast] {
            let modes = if size == protocol {
                "none,jvp,dual,jacrev"
            } else {
                "jvp,dual,jacrev"
            };
            let torch = torch_rows(python, modes, size, warmup, steps, threads)?;
            let ms = |mode: &str| torch.iter().find(|t| t.mode == mode).map(|t| t.ms_median);
            for c in rows.iter_mut().filter(|c| c.size == size) {
                let v = match c.torch {
                    "fastest" => ["dual", "jvp", "jacrev"]
                        .iter()
                        .filter_map(|m| ms(m))
                        .fold(f64::INFINITY, f64::min),
                    mode => ms(mode).unwrap_or(f64::NAN),
                };
                progress(&format!(
                    "round {round}: pytorch {} at {} points: {v:.2} ms",
                    c.torch, size.points
                ));
                c.torch_ms.push(v);
            }
        }
    }
    Ok(rows)
}

/// One line of the comparison: doma's step and method, its config, PyTorch's mode, the
/// size both run at, and the ratio aimed at.
type Case = (
    &'static str,
    &'static str,
    FitConfig,
    &'static str,
    TorchSize,
    Option<f64>,
);

/// The sizes of the protocol's step and `fast`'s on `n` training points, and the lines of
/// [`compare_torch`].
fn comparison_cases(n: usize) -> (TorchSize, TorchSize, [Case; 6]) {
    let protocol = TorchSize {
        points: n,
        h_points: n,
    };
    let fast = TorchSize {
        points: FAST_POINTS_PER_STEP.min(n),
        h_points: FAST_SMOOTHNESS_POINTS.min(n),
    };
    let config =
        |method, smoothness, step| synthetic_config(method, smoothness).with_step(Some(step));
    let fast_config = Recipe::Fast
        .apply(synthetic_config(JacobianKind::Analytic, true))
        .with_step(Some(StepKind::Fused));
    let (analytic, autodiff) = (JacobianKind::Analytic, JacobianKind::Autodiff);
    let (composed, fused) = (StepKind::Composed, StepKind::Fused);
    let cases = [
        (
            "affinity-h",
            "analytic",
            config(analytic, true, composed),
            "fastest",
            protocol,
            Some(2.5),
        ),
        (
            "affinity-h",
            "fused",
            config(analytic, true, fused),
            "fastest",
            protocol,
            None,
        ),
        (
            "affinity-h",
            "autodiff",
            config(autodiff, true, composed),
            "jvp",
            protocol,
            Some(1.0),
        ),
        (
            "no-reg",
            "analytic",
            config(analytic, false, composed),
            "none",
            protocol,
            Some(2.0),
        ),
        (
            "no-reg",
            "fused",
            config(analytic, false, fused),
            "none",
            protocol,
            None,
        ),
        ("fast", "fused", fast_config, "fastest", fast, None),
    ];
    (protocol, fast, cases)
}

/// The side-by-side table: each line's medians over rounds (min–max), the ratio and its
/// target.
pub fn comparison_table(rows: &[Comparison]) -> String {
    let range = |v: &[f64]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, 0f64), |(a, b), &x| (a.min(x), b.max(x)));
        format!("{:.2} ({lo:.2}-{hi:.2})", Comparison::median(v))
    };
    let mut s = format!(
        "{:<11} {:>7} {:<9} {:>22} {:<8} {:>22} {:>8} {:>7}\n",
        "step", "points", "doma", "ms (min-max)", "pytorch", "ms (min-max)", "speed-up", "target"
    );
    s += &"-".repeat(102);
    s += "\n";
    for c in rows {
        s += &format!(
            "{:<11} {:>7} {:<9} {:>22} {:<8} {:>22} {:>7.2}x {:>7}\n",
            c.step,
            // PyTorch's `none` step samples no `L_H` points.
            format!(
                "{}/{}",
                c.size.points,
                if c.torch == "none" {
                    0
                } else {
                    c.size.h_points
                }
            ),
            c.doma,
            range(&c.doma_ms),
            c.torch,
            range(&c.torch_ms),
            c.ratio(),
            c.target.map_or("-".into(), |t| format!("{t:.1}x"))
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pytorch_lines_are_parsed_and_the_ratio_is_of_medians() {
        let out = "loading torch\n{\"impl\": \"pytorch\", \"torch\": \"2.5\", \"mode\": \"dual\", \"threads\": 2, \"points\": 750, \"ms_median\": 13.5, \"ms_min\": 13, \"ms_max\": 14}\n";
        let rows = parse_torch_rows(out).unwrap();
        assert_eq!((rows[0].mode.as_str(), rows[0].ms_median), ("dual", 13.5));
        assert!(parse_torch_rows("{ not json").is_err());
        let c = Comparison {
            step: "affinity-h",
            doma: "analytic",
            doma_ms: vec![5.0, 4.0, 6.0],
            torch: "fastest",
            size: TorchSize {
                points: 750,
                h_points: 750,
            },
            torch_ms: vec![12.0, 15.0, 13.0],
            target: Some(2.5),
        };
        // Medians 5 and 13: 2.6x.
        assert!((c.ratio() - 2.6).abs() < 1e-12);
        assert!(comparison_table(&[c]).contains("2.60x"));
    }
}
