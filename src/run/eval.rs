//! `doma eval`: the metrics of a fitted run.

use std::path::Path;

use burn::tensor::Device;

use super::{GapReport, Report, RunConfig, RunDir};
use crate::data::Trajectories;
use crate::data::mesh::as_points;
use crate::data::sequence::{LoadOptions, Sequence, load_sequence_with};
use crate::data::tracks::neighbour_motion;
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
    })
}

/// The gap-filling report of `field` fitted under `config`: on the held-out observations
/// of the training tracks, the field's EPE beside linear interpolation's and the k-NN
/// baseline's ([`GapReport`]); `None` when nothing was held out. `placed` is the run's data
/// as loaded (the baselines use its canonical positions, nothing the fit learned), `data`
/// the same with the canonical positions the fit learned ([`RunDir::load_data`]).
pub fn gap_report(
    field: &dyn MotionField,
    config: &RunConfig,
    placed: &Sequence,
    data: &Sequence,
    device: &Device,
) -> Result<Option<GapReport>> {
    let Some(held) = &data.held_out else {
        return Ok(None);
    };
    let (train_idx, _) = config.split_indices(data.trajectories.points())?;
    let train = data.trajectories.select_points(&train_idx)?;
    let baseline = placed.trajectories.select_points(&train_idx)?;
    let mut row = vec![usize::MAX; data.trajectories.points()];
    for (r, &i) in train_idx.iter().enumerate() {
        row[i] = r;
    }
    // The entries of training tracks, as (frame, training row), with their truth.
    let (entries, truth): (Vec<(usize, usize)>, Vec<[f32; 3]>) = held
        .entries
        .iter()
        .zip(&held.truth)
        .filter(|((_, i), _)| row[*i] != usize::MAX)
        .map(|(&(k, i), &p)| ((k, row[i]), p))
        .unzip();
    if entries.is_empty() {
        return Ok(None);
    }
    let l1 = |a: &[f32; 3], b: &[f32; 3]| (0..3).map(|c| (a[c] - b[c]).abs() as f64).sum::<f64>();
    let mean = |pred: &[[f32; 3]]| {
        EPE_SCALE * pred.iter().zip(&truth).map(|(a, b)| l1(a, b)).sum::<f64>()
            / entries.len() as f64
    };
    let linear: Vec<[f32; 3]> = entries
        .iter()
        .map(|&(k, r)| {
            let p = &baseline.frame(k)[3 * r..3 * r + 3];
            [p[0], p[1], p[2]]
        })
        .collect();
    let neighbours = neighbour_motion(&baseline, &entries)?;
    // The field's prediction, frame by frame over the frames that have entries.
    let canonical = as_points(train.canonical());
    let mut predicted = vec![[0f32; 3]; entries.len()];
    let mut start = 0;
    while start < entries.len() {
        let k = entries[start].0;
        let end = start + entries[start..].partition_point(|e| e.0 == k);
        let x: Vec<[f32; 3]> = entries[start..end].iter().map(|e| canonical[e.1]).collect();
        crate::warp::warp_frames(field, &x, k..k + 1, train.frames(), device, |_, y| {
            predicted[start..end].copy_from_slice(&y);
            Ok(())
        })?;
        start = end;
    }
    Ok(Some(GapReport {
        entries: entries.len(),
        epe_x1e4: mean(&predicted),
        linear_x1e4: mean(&linear),
        neighbours_x1e4: mean(&neighbours),
    }))
}

/// The metrics of the run in `run`: on its own held-out points, or on every point of
/// `data` (normalised like the run's data).
pub fn eval_run(run: &RunDir, data: Option<&Path>, device: &Device) -> Result<Report> {
    let config = run.load_config()?;
    let field = run.load_field(&config, device)?;
    let own = run.load_data(&config)?;
    let (truth, what) = match data {
        None => (
            config.split(&own.trajectories)?.1,
            "the held-out points of the fitted data".to_string(),
        ),
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
                    file: if npz {
                        config.tracks.clone()
                    } else {
                        Default::default()
                    },
                    drop_unobserved: config.drop_unobserved,
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
            (renorm, format!("every point of {}", path.display()))
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
    })
}

fn denormalize(t: &Trajectories, center: [f32; 3], scale: f32) -> Result<Trajectories> {
    t.map_coordinates(|v, c| v * scale + center[c])
}

fn normalize_with(t: &Trajectories, center: [f32; 3], scale: f32) -> Result<Trajectories> {
    t.map_coordinates(|v, c| (v - center[c]) / scale)
}
