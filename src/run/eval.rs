//! `doma eval`: the metrics of a fitted run.

use std::path::Path;

use burn::tensor::Device;

use super::{Report, RunDir};
use crate::Result;
use crate::checkpoint::load_json;
use crate::data::Trajectories;
use crate::data::sequence::load_sequence;
use crate::field::MotionField;
use crate::metrics::{EPE_SCALE, field_epe_per_frame};
use crate::train::IterationRecord;

/// The EPE report of `field` on `truth` (normalised coordinates).
pub fn evaluate(
    field: &dyn MotionField,
    truth: &Trajectories,
    what: &str,
    device: &Device,
) -> Result<Report> {
    let per_frame: Vec<f64> = field_epe_per_frame(field, truth, device)?
        .into_iter()
        .map(|e| e * EPE_SCALE)
        .collect();
    Ok(Report {
        evaluated_on: what.into(),
        epe_x1e4: per_frame.iter().sum::<f64>() / per_frame.len() as f64,
        epe_per_frame_x1e4: per_frame,
        frames: truth.frames(),
        points: truth.points(),
        params: field.param_count(),
        checkpoint_bytes: 0,
        iterations: 0,
        seconds: 0.0,
    })
}

/// The metrics of the run in `run`: on its own held-out points, or on every point of
/// `data` (normalised like the run's data).
pub fn eval_run(run: &RunDir, data: Option<&Path>, device: &Device) -> Result<Report> {
    let config = run.load_config()?;
    let field = run.load_field(&config, device)?;
    let own = config.load()?;
    let (truth, what) = match data {
        None => (
            config.split(&own.trajectories)?.1,
            "the held-out points of the fitted data".to_string(),
        ),
        Some(path) => {
            let other = load_sequence(path, None, None, 1)?;
            // Undo the other file's own normalisation, apply the run's.
            let denorm = denormalize(&other.trajectories, other.center, other.scale);
            (
                normalize_with(&denorm, own.center, own.scale),
                format!("every point of {}", path.display()),
            )
        }
    };
    let bytes = std::fs::metadata(run.model()).map(|m| m.len()).unwrap_or(0);
    // No history yet is an empty one; a corrupt one is an error, as for `info` and `plot`.
    let history: Vec<IterationRecord> = if run.history().is_file() {
        load_json(&run.history())?
    } else {
        Vec::new()
    };
    let report = evaluate(&field, &truth, &what, device)?;
    Ok(Report {
        checkpoint_bytes: bytes,
        iterations: history.len(),
        seconds: history.last().map_or(0.0, |r| r.seconds),
        ..report
    })
}

fn map_points(t: &Trajectories, f: impl Fn(f32, usize) -> f32) -> Trajectories {
    let positions = t
        .positions()
        .iter()
        .enumerate()
        .map(|(i, &v)| f(v, i % 3))
        .collect();
    Trajectories::new(t.frames(), t.points(), positions).expect("an affine map keeps the shape")
}

fn denormalize(t: &Trajectories, center: [f32; 3], scale: f32) -> Trajectories {
    map_points(t, |v, c| v * scale + center[c])
}

fn normalize_with(t: &Trajectories, center: [f32; 3], scale: f32) -> Trajectories {
    map_points(t, |v, c| (v - center[c]) / scale)
}
