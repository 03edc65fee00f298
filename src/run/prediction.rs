//! The fitted field's prediction of a set of tracks at their frames: what the metrics, the
//! gap reports and a completion read the field through.

use burn::tensor::Device;

use crate::Result;
use crate::data::Trajectories;
use crate::data::mesh::as_points;
use crate::field::MotionField;

/// The field's prediction `[T, N, 3]` of every track of `data` (from its canonical
/// position) at every frame.
pub fn field_everywhere(
    field: &dyn MotionField,
    data: &Trajectories,
    device: &Device,
) -> Result<Vec<f32>> {
    let t = data.frames();
    field_at_frames(field, &as_points(data.canonical()), 0..t, t, device)
}

/// The field's prediction `[F, N, 3]` of the tracks at `canonical` (`[N]`) at `frames` of
/// a `total`-frame sequence: a window of [`field_everywhere`], the same to the bit.
pub fn field_at_frames(
    field: &dyn MotionField,
    canonical: &[[f32; 3]],
    frames: std::ops::Range<usize>,
    total: usize,
    device: &Device,
) -> Result<Vec<f32>> {
    let mut predicted = Vec::with_capacity(3 * frames.len() * canonical.len());
    crate::warp::warp_frames(field, canonical, frames, total, device, |_, y| {
        predicted.extend(y.iter().flatten());
        Ok(())
    })?;
    Ok(predicted)
}
