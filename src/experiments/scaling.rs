//! How the cost of a fit grows (`doma bench --scaling`): time per training step and the
//! process's peak memory against the number of training points N and frames T, and the
//! checkpoint's size against T for DOMA (one network for all frames: constant) and DPF
//! (one network per frame: linear), the paper's size claim (Sec. 4: ≈ 200 KB against 8 MB
//! at T = 30).
//!
//! Each (N, T) cell runs in a fresh process, so that its peak resident memory (Linux's
//! `VmHWM`) is its own: the data, the model, Adam's state and the step's activations.

use std::time::Instant;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::checkpoint::Precision;
use crate::data::Trajectories;
use crate::field::dpf::DpfConfig;
use crate::field::model::ModelConfig;
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::siren::SirenShape;
use crate::train::{FitConfig, Trainer};
use crate::{DomaError, Result};

/// One (N, T) cell of the scaling table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScalingCell {
    /// Training points N.
    pub points: usize,
    /// Frames T.
    pub frames: usize,
    /// Points per step, when a subset (`--points-per-step`); `None`: all N.
    pub points_per_step: Option<usize>,
    /// Milliseconds per training step (one frame), the median of the timed steps.
    pub step_ms: f64,
    /// The process's peak resident memory in MiB (`None` where the OS does not say).
    pub peak_mib: Option<f64>,
}

/// The checkpoint sizes at `frames` frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointSize {
    /// Frames T.
    pub frames: usize,
    /// DOMA-Affinity's `model.bpk` bytes (f32; 128 wide, 3 hidden layers).
    pub doma_bytes: usize,
    /// DPF's (one such SIREN per frame).
    pub dpf_bytes: usize,
}

/// The fit of a cell: `doma fit`'s default recipe (DOMA-Affinity, the analytic Jacobian,
/// the trajectory L1 alone), with `points_per_step`.
pub fn cell_config(points_per_step: Option<usize>) -> FitConfig {
    FitConfig::doma(DomaFieldConfig::new(Variant::Affinity))
        .with_jacobian(JacobianKind::Analytic)
        .with_points_per_step(points_per_step)
}

/// `points` tracks over `frames` frames of a smooth non-rigid motion (a twist about z that
/// grows with height, and a bend), seeded and reproducible.
pub fn synthetic_tracks(points: usize, frames: usize) -> Result<Trajectories> {
    let mut positions = Vec::with_capacity(points * frames * 3);
    let golden = 0.618_033_988_75_f64;
    for k in 0..frames {
        let t = crate::data::normalized_time(k, frames);
        for i in 0..points {
            // A low-discrepancy fill of the cube [-0.5, 0.5]³.
            let x = (i as f64 * golden).fract() - 0.5;
            let y = (i as f64 * golden * golden).fract() - 0.5;
            let z = (i as f64 * 0.754_877_666).fract() - 0.5;
            let angle = 0.6 * t * (1.0 + z);
            let (s, c) = angle.sin_cos();
            positions.extend([
                (c * x - s * y) as f32,
                (s * x + c * y + 0.1 * t * x * x) as f32,
                (z + 0.05 * t * (3.0 * x).sin()) as f32,
            ]);
        }
    }
    Trajectories::new(frames, points, positions)
}

/// Times `steps` training steps (after `warmup`) of the cell `(points, frames)` on `device`
/// and reads the process's peak memory; the caller runs it in a fresh process.
pub fn measure_cell(
    points: usize,
    frames: usize,
    points_per_step: Option<usize>,
    warmup: usize,
    steps: usize,
    device: &Device,
) -> Result<ScalingCell> {
    let data = synthetic_tracks(points, frames)?;
    let config = cell_config(points_per_step);
    let mut trainer = Trainer::from_config(&config, &data, device)?;
    let lr = config.schedule.learning_rate;
    let mut times = Vec::with_capacity(steps);
    for s in 0..warmup + steps.max(1) {
        let start = Instant::now();
        let losses = trainer.step(s % frames, lr)?;
        // Reading the loss waits for the step on an asynchronous device.
        crate::readback::to_vec::<f32, 1, _>(losses)?;
        if s >= warmup {
            times.push(start.elapsed().as_secs_f64() * 1e3);
        }
    }
    times.sort_by(f64::total_cmp);
    Ok(ScalingCell {
        points,
        frames,
        points_per_step,
        step_ms: times[times.len() / 2],
        peak_mib: peak_resident_bytes().map(|b| b as f64 / (1 << 20) as f64),
    })
}

/// The checkpoint sizes of DOMA-Affinity and DPF at each of `frames`, with the SIREN of
/// the paper's size table (Tab. A-size, the Resynth alignment: 128 wide, 3 hidden layers).
pub fn checkpoint_sizes(frames: &[usize]) -> Result<Vec<CheckpointSize>> {
    let device = Device::flex();
    let shape = SirenShape::new().with_n_hidden(3);
    frames
        .iter()
        .map(|&t| {
            let doma = ModelConfig::Doma(
                DomaFieldConfig::new(Variant::Affinity).with_shape(shape.clone()),
            )
            .init(0, &[], &device);
            let dpf =
                ModelConfig::Dpf(DpfConfig::new(t).with_shape(shape.clone())).init(0, &[], &device);
            Ok(CheckpointSize {
                frames: t,
                doma_bytes: doma.encode(Precision::F32)?.len(),
                dpf_bytes: dpf.encode(Precision::F32)?.len(),
            })
        })
        .collect()
}

/// The process's peak resident memory (`VmHWM` of `/proc/self/status`), where Linux
/// reports it.
pub fn peak_resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The scaling table as text.
pub fn scaling_table(cells: &[ScalingCell], sizes: &[CheckpointSize]) -> String {
    let mut s = format!(
        "{:>8} {:>6} {:>10} {:>10} {:>10}\n",
        "N", "T", "per step", "ms/step", "peak MiB"
    );
    for c in cells {
        let k = c
            .points_per_step
            .map_or("all".to_string(), |k| k.to_string());
        let peak = c.peak_mib.map_or("-".to_string(), |m| format!("{m:.0}"));
        s += &format!(
            "{:>8} {:>6} {:>10} {:>10.2} {:>10}\n",
            c.points, c.frames, k, c.step_ms, peak
        );
    }
    s += &format!("\n{:>6} {:>12} {:>12}\n", "T", "DOMA bytes", "DPF bytes");
    for r in sizes {
        s += &format!("{:>6} {:>12} {:>12}\n", r.frames, r.doma_bytes, r.dpf_bytes);
    }
    s
}

/// The cells of `--scaling`: every (N, T), and N = 10⁵ again with 10⁴ points per step.
pub const SCALING_CELLS: [(usize, usize, Option<usize>); 8] = [
    (1_000, 20, None),
    (10_000, 20, None),
    (100_000, 20, None),
    (100_000, 20, Some(10_000)),
    (1_000, 100, None),
    (10_000, 100, None),
    (100_000, 100, None),
    (100_000, 100, Some(10_000)),
];

/// Frames at which the checkpoint sizes are reported.
pub const CHECKPOINT_FRAMES: [usize; 5] = [1, 10, 30, 100, 300];

/// Parses a cell's `N,T` or `N,T,K` (`doma bench --scaling-cell`).
pub fn parse_cell(spec: &str) -> Result<(usize, usize, Option<usize>)> {
    let bad = || DomaError::Usage(format!("--scaling-cell `{spec}`: expected N,T or N,T,K"));
    let parts: Vec<usize> = spec
        .split(',')
        .map(|p| p.trim().parse().map_err(|_| bad()))
        .collect::<Result<_>>()?;
    match parts[..] {
        [n, t] => Ok((n, t, None)),
        [n, t, k] => Ok((n, t, Some(k))),
        _ => Err(bad()),
    }
}

/// Measures every cell of [`SCALING_CELLS`], each in a fresh process of `exe` (the `doma`
/// binary, `bench --scaling-cell`), so that each peak resident memory is the cell's own;
/// `progress` sees each cell as it finishes.
pub fn run_cells(
    exe: &std::path::Path,
    warmup: usize,
    steps: usize,
    mut progress: impl FnMut(&ScalingCell),
) -> Result<Vec<ScalingCell>> {
    let mut cells = Vec::new();
    for (n, t, k) in SCALING_CELLS {
        let spec = match k {
            Some(k) => format!("{n},{t},{k}"),
            None => format!("{n},{t}"),
        };
        let out = std::process::Command::new(exe)
            .args(["bench", "--scaling-cell", &spec])
            .args(["--warmup", &warmup.to_string()])
            .args(["--steps", &steps.to_string()])
            .output()
            .map_err(|e| DomaError::io(exe, e))?;
        if !out.status.success() {
            return Err(DomaError::Device(format!(
                "the scaling cell {spec} failed: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            )));
        }
        let cell: ScalingCell = serde_json::from_slice(&out.stdout).map_err(|e| {
            DomaError::InvalidData(format!("the scaling cell {spec} printed no record: {e}"))
        })?;
        progress(&cell);
        cells.push(cell);
    }
    Ok(cells)
}

/// The scaling plots: time per step and peak memory against N (a curve per T), and
/// checkpoint bytes against T for DOMA and DPF.
pub fn scaling_plots(
    cells: &[ScalingCell],
    sizes: &[CheckpointSize],
) -> Vec<(&'static str, crate::plot::Figure)> {
    use crate::plot::{Series, line_plot};
    // One picture per measured quantity: a curve per T against N (all points per step).
    let against_n = |title: &str, y_label: &str, value: fn(&ScalingCell) -> Option<f64>| {
        let curve = |t: usize| -> Vec<(f64, f64)> {
            cells
                .iter()
                .filter(|c| c.frames == t && c.points_per_step.is_none())
                .filter_map(|c| Some((c.points as f64, value(c)?)))
                .collect()
        };
        line_plot(
            title,
            "training points N",
            y_label,
            &[
                Series {
                    name: "T = 20",
                    color: [31, 119, 180],
                    points: curve(20),
                },
                Series {
                    name: "T = 100",
                    color: [214, 39, 40],
                    points: curve(100),
                },
            ],
            true,
        )
        .log_x()
    };
    let step = against_n(
        "Time per training step (flex, Affinity, analytic)",
        "ms per step",
        |c| Some(c.step_ms),
    );
    let peak = against_n(
        "Peak memory of a fit (flex, Affinity, analytic)",
        "peak MiB",
        |c| c.peak_mib,
    );
    let bytes = |f: fn(&CheckpointSize) -> usize| -> Vec<(f64, f64)> {
        sizes
            .iter()
            .map(|s| (s.frames as f64, f(s) as f64 / 1e6))
            .collect()
    };
    let ckpt = line_plot(
        "Checkpoint size against frames",
        "frames T",
        "MB",
        &[
            Series {
                name: "DOMA",
                color: [31, 119, 180],
                points: bytes(|s| s.doma_bytes),
            },
            Series {
                name: "DPF",
                color: [214, 39, 40],
                points: bytes(|s| s.dpf_bytes),
            },
        ],
        true,
    )
    .log_x();
    vec![
        ("scaling_step.png", step),
        ("scaling_memory.png", peak),
        ("scaling_checkpoint.png", ckpt),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn doma_checkpoints_stay_constant_and_dpf_grows_linearly() {
        let sizes = checkpoint_sizes(&[2, 4]).unwrap();
        assert_eq!(sizes[0].doma_bytes, sizes[1].doma_bytes);
        // DPF: one SIREN per frame, so twice the frames is twice the bytes (to the few
        // bytes of the names' lengths).
        let (two, four) = (sizes[0].dpf_bytes as f64, sizes[1].dpf_bytes as f64);
        assert!(two > 2.0 * 100_000.0, "{two}");
        assert!((four / two - 2.0).abs() < 1e-3, "{two} {four}");
    }

    #[test]
    fn the_synthetic_tracks_start_where_they_should_and_move() {
        let t = synthetic_tracks(100, 3).unwrap();
        assert_eq!((t.frames(), t.points()), (3, 100));
        assert!(t.positions().iter().all(|v| v.is_finite() && v.abs() < 1.0));
        assert_ne!(t.frame(0), t.frame(2));
        assert!(peak_resident_bytes().is_none_or(|b| b > 0));
    }
}
