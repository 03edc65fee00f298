//! Evaluation metrics (REFERENCE §7).

use burn::tensor::Device;

use crate::data::Trajectories;
use crate::field::MotionField;
use crate::{DomaError, Result};

/// The factor by which tables report the EPE (the paper's "×10⁻⁴").
pub const EPE_SCALE: f64 = 1e4;

/// The end-point error per frame: for every point and frame `k`,
/// `‖(ŷ_k − x_0) − (y_k − x_0)‖₁ = ‖ŷ_k − y_k‖₁` (summed over x, y, z), averaged over
/// the points. Frame 0 is included, as in the authors' code (REFERENCE §7).
pub fn epe_per_frame(predicted: &Trajectories, truth: &Trajectories) -> Result<Vec<f64>> {
    if predicted.frames() != truth.frames() || predicted.points() != truth.points() {
        return Err(DomaError::InvalidData(format!(
            "EPE of {}×{} predicted against {}×{} true positions",
            predicted.frames(),
            predicted.points(),
            truth.frames(),
            truth.points()
        )));
    }
    Ok((0..truth.frames())
        .map(|k| {
            let total: f64 = predicted
                .frame(k)
                .iter()
                .zip(truth.frame(k))
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum();
            total / truth.points() as f64
        })
        .collect())
}

/// The EPE (REFERENCE §7): [`epe_per_frame`] averaged over all frames, raw (multiply by
/// [`EPE_SCALE`] for the paper's tables).
pub fn epe(predicted: &Trajectories, truth: &Trajectories) -> Result<f64> {
    let per_frame = epe_per_frame(predicted, truth)?;
    Ok(per_frame.iter().sum::<f64>() / per_frame.len() as f64)
}

/// Warps the canonical points of `truth` (its frame 0) to every frame with `field`.
pub fn predict(
    field: &dyn MotionField,
    truth: &Trajectories,
    device: &Device,
) -> Result<Trajectories> {
    let x0 = truth.frame_tensor(0, device);
    let mut positions = Vec::with_capacity(truth.positions().len());
    for k in 0..truth.frames() {
        let y = field.warp(x0.clone(), truth.time(k));
        let values = y
            .try_into_vec_as::<f32>()
            .map_err(|e| DomaError::Device(format!("{e:?}")))?;
        positions.extend(values);
    }
    Trajectories::new(truth.frames(), truth.points(), positions)
}

/// The EPE of `field` on the held-out trajectories `truth`.
pub fn evaluate_epe(field: &dyn MotionField, truth: &Trajectories, device: &Device) -> Result<f64> {
    epe(&predict(field, truth, device)?, truth)
}
