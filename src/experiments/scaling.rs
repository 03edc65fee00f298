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

use crate::Result;
use crate::checkpoint::Precision;
use crate::data::Trajectories;
use crate::field::dpf::DpfConfig;
use crate::field::model::ModelConfig;
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::siren::SirenShape;
use crate::train::{FitConfig, Trainer};

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
