//! `doma eval`: the metrics of a fitted run.

use std::borrow::Cow;
use std::path::Path;

use burn::tensor::Device;

use super::{Report, RunDir, gap_report};
use crate::data::Trajectories;
use crate::data::layout::TrackFile;
use crate::data::sequence::{LoadOptions, load_sequence_with};
use crate::field::MotionField;
use crate::io::load_json;
use crate::metrics::{EPE_SCALE, field_epe_per_frame, mean_over_frames};
use crate::train::IterationRecord;
use crate::{DomaError, Result};

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
        epe_x1e4: mean_over_frames(&per_frame),
        epe_per_frame_x1e4: per_frame,
        frames: truth.frames(),
        points: truth.points(),
        params: field.param_count(),
        checkpoint_bytes: 0,
        iterations: 0,
        seconds: 0.0,
        held_out_observations: None,
        epe: None,
        units: None,
    })
}

/// The metrics of the run in `run`: on its own held-out points, or on every point of
/// `data` (normalised like the run's data).
pub fn eval_run(run: &RunDir, data: Option<&Path>, device: &Device) -> Result<Report> {
    eval_run_as(run, data, None, device)
}

/// [`eval_run`] on `data` read as `file` says (a Python `Tracks` written as a masked
/// `.npz`), rather than as the run read its own data.
pub fn eval_run_as(
    run: &RunDir,
    data: Option<&Path>,
    file: Option<&TrackFile>,
    device: &Device,
) -> Result<Report> {
    let config = run.load_config()?;
    let field = run.load_field(&config, device)?;
    let own = run.load_data(&config)?;
    let (truth, what) = match data {
        None => {
            let (truth, what) = config.measured(&own.trajectories)?;
            (truth, what.to_string())
        }
        Some(path) => {
            // Read as the run read its own data (a tracker's layout and frame for a
            // tracker's .npz, dropped tracks).
            let npz = path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("npz"));
            let other = load_sequence_with(
                path,
                &LoadOptions {
                    stride: 1,
                    file: match file {
                        Some(file) => file.clone(),
                        None if npz => config.tracks.clone(),
                        None => Default::default(),
                    },
                    drop_unobserved: config.drop_unobserved,
                    model_outputs: config.model_outputs,
                    // The field takes points at the run's reference frame, whichever
                    // frame the other file sees most.
                    reference: Some(own.trajectories.reference()),
                    ..LoadOptions::default()
                },
            )?;
            // Undo the other file's own normalisation, apply the run's.
            let in_run_units = |e: DomaError| DomaError::Malformed {
                path: path.to_path_buf(),
                reason: format!("in the run's normalisation: {e}"),
            };
            let denorm = denormalize(&other.trajectories, other.center, other.scale)
                .map_err(in_run_units)?;
            let renorm = normalize_with(&denorm, own.center, own.scale).map_err(in_run_units)?;
            (
                Cow::Owned(renorm),
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
    let gaps = match data {
        None if own.held_out.is_some() => {
            gap_report(&field, &config, &config.load()?, &own, device)?
        }
        None => None,
        Some(_) => None,
    };
    Ok(Report {
        held_out_observations: gaps,
        checkpoint_bytes: bytes,
        iterations: history.len(),
        seconds: history.last().map_or(0.0, |r| r.seconds),
        ..report
    }
    .in_units(own.units.clone(), own.scale))
}

fn denormalize(t: &Trajectories, center: [f32; 3], scale: f32) -> Result<Trajectories> {
    t.map_coordinates(|v, c| v * scale + center[c])
}

fn normalize_with(t: &Trajectories, center: [f32; 3], scale: f32) -> Result<Trajectories> {
    t.map_coordinates(|v, c| (v - center[c]) / scale)
}
