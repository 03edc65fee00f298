//! doma against PyTorch, alternating in one run: `benches/torch_step.py` (the same step in
//! plain PyTorch, the Jacobian four ways) run with a user's Python, side by side with
//! doma's training-step rows (`doma bench --compare-torch`).

use serde::Serialize;

use super::fit_step_row;
use crate::backend::BackendKind;
use crate::error::{DomaError, Result};
use crate::jacobian::JacobianKind;

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
    /// The speed-up this step is expected to reach: `torch / doma` of the medians over rounds.
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
}
